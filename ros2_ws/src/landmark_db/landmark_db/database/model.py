"""The landmark database in memory: what the builder fills and the localizer reads.

A landmark database (thesis Sections 1.1, 3.1.4, 7.1 and 7.2) records, for a world
decomposed into regions, which landmark (k features) to use at each pose, the
appearance of every feature, and for every region two or three *model views*: images
taken inside the region in which all k landmark features are visible, with the pose at
which each was taken. The localizer votes for regions with the features it sees (the
feature-to-region membership, Section 7.1), tracks a region's k features, switches
between overlapping regions (the region graph, Section 7.1) and computes its pose from
the features' locations in the model views (Section 7.2).

Identifiers: pose ``i`` is row ``i`` of :class:`SampledPoses`; class ``c`` (a scene
feature, the correspondence class of Algorithm 6.3) is entry ``c`` of
:class:`FeatureClasses`, and is also the feature id of column ``c`` of the exported
world instance; region ``r`` is ``LandmarkDatabase.regions[r]``.

The camera and the build's settings are :mod:`.build_info`'s; the field checks are
:mod:`.fields`'. Every dataclass here is frozen and validates its input in
``__post_init__``: arrays are
copied into the documented dtype and made read-only, so a database cannot change after
it was checked. The checks are *structural* (shapes, dtypes, finite numbers, indices in
range, no duplicates, each model view holds every landmark feature of its region);
whether the regions form a valid decomposition is the validator's job
(``vbn db-export`` then ``vbn validate``), so that a database built with a faulty
decomposition can still be opened and inspected.

Two departures from a literal reading of the task, both documented where they apply:
a model view may hold features of its image that belong to no class (class id ``-1``),
kept for the matching symmetry check of Section 6.2.1; and :class:`BuildInfo` carries
``decomposition_seconds`` so that the exported decomposition reports the real time.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
import hashlib
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from landmark_db.database.build_info import (
    BuildInfo,
)
from landmark_db.database.codebook import DescriptorCodebook
from landmark_db.database.fields import (
    ArrayEquality,
    bool_csr,
    check_range,
    descriptor_array,
    float_array,
    incidence,
    int_array,
    int_at_least,
    read_only,
    set_field,
)
from landmark_db.database.points import ScenePoints
from landmark_db.decomposition import Decomposition, Region, Service, service
from landmark_db.errors import LandmarkDbError
from landmark_db.world import WorldInstance, adjacency_matrix

__all__ = [
    'FeatureClasses',
    'LandmarkDatabase',
    'ModelView',
    'RegionAdjacency',
    'RegionRecord',
    'SampledPoses',
]

@dataclass(frozen=True, eq=False)
class SampledPoses(ArrayEquality):
    """The sampled poses V and the pose graph G (Definition 3.1).

    Attributes:
        xy: ``(n, 2)`` float64 positions of ``base_link`` in ``map``, metres.
        yaw: ``(n,)`` float64 headings, radians.
        grid: ``(n, 2)`` int64 grid cell ``(ix, iy)`` of each pose, ``(-1, -1)`` when
            the pose is not on the sampling grid.
        edges: ``(m, 2)`` int64 pose index pairs, the undirected graph G.
        spacing: grid spacing, metres, or None when the poses are not on a grid.
    """

    xy: np.ndarray
    yaw: np.ndarray
    grid: np.ndarray
    edges: np.ndarray
    spacing: float | None = None

    def __post_init__(self) -> None:
        xy = float_array(self.xy, 'poses xy', (None, 2))
        n = xy.shape[0]
        set_field(self, 'xy', xy)
        set_field(self, 'yaw', float_array(self.yaw, 'poses yaw', (n,)))
        grid = int_array(self.grid, 'poses grid', (n, 2))
        off = grid < 0
        if np.any(grid < -1) or np.any(off[:, 0] != off[:, 1]):
            bad = int(np.flatnonzero((grid < -1).any(axis=1) | (off[:, 0] != off[:, 1]))[0])
            raise LandmarkDbError(f'pose {bad} has grid index {grid[bad].tolist()}; '
                                  f'expected two indices >= 0, or (-1, -1) off the grid')
        set_field(self, 'grid', grid)
        edges = int_array(self.edges, 'pose edges', (None, 2))
        check_range(edges, n, 'pose edges', 'pose')
        set_field(self, 'edges', edges)
        if self.spacing is not None:
            spacing = self.spacing
            if (isinstance(spacing, bool) or not isinstance(spacing, (int, float, np.number))
                    or not math.isfinite(spacing) or spacing <= 0):
                raise LandmarkDbError(f'pose spacing must be a positive number or None, '
                                      f'got {spacing!r}')
            set_field(self, 'spacing', float(spacing))

    @property
    def n_poses(self) -> int:
        """Number of poses."""
        return int(self.xy.shape[0])


@dataclass(frozen=True, eq=False)
class FeatureClasses(ArrayEquality):
    """Scene features (correspondence classes, Section 6.2.1) and who sees them.

    A feature's appearance changes across the region that sees it, so each class keeps
    a few representative descriptors rather than one.

    Attributes:
        descriptors: ``(total, 128)`` uint8 SIFT descriptors of all classes, class by
            class. Integer-valued float input (OpenCV's float32 SIFT) is converted.
        offsets: ``(n_classes + 1,)`` int64; class ``c`` owns rows
            ``descriptors[offsets[c]:offsets[c + 1]]`` (at least one each).
        visibility: ``(n_poses, n_classes)`` bool ``scipy.sparse`` CSR matrix: the
            classes each pose sees after the filters of Section 6.2.2.
    """

    descriptors: np.ndarray
    offsets: np.ndarray
    visibility: sp.csr_matrix

    def __post_init__(self) -> None:
        descriptors = descriptor_array(self.descriptors, 'class descriptors')
        offsets = int_array(self.offsets, 'class offsets', (None,))
        if offsets.size == 0 or offsets[0] != 0 or offsets[-1] != descriptors.shape[0]:
            raise LandmarkDbError(
                f'class offsets must run from 0 to the number of descriptors '
                f'({descriptors.shape[0]}), got '
                f'{offsets[:1].tolist()}..{offsets[-1:].tolist()}')
        empty = np.flatnonzero(np.diff(offsets) <= 0)
        if empty.size:
            raise LandmarkDbError(f'class {int(empty[0])} has no descriptor (offsets must '
                                  f'increase strictly)')
        set_field(self, 'descriptors', descriptors)
        set_field(self, 'offsets', offsets)
        n_classes = offsets.size - 1
        visibility = bool_csr(self.visibility, 'class visibility')
        if visibility.shape[1] != n_classes:
            raise LandmarkDbError(f'class visibility has {visibility.shape[1]} columns but '
                                  f'there are {n_classes} classes')
        set_field(self, 'visibility', visibility)

    @property
    def n_classes(self) -> int:
        """Number of classes."""
        return int(self.offsets.size - 1)

    def descriptors_of(self, class_id: int) -> np.ndarray:
        """Return the ``(d, 128)`` uint8 representative descriptors of one class."""
        return self.descriptors[self.offsets[class_id]:self.offsets[class_id + 1]]

    @property
    def descriptor_classes(self) -> np.ndarray:
        """``(total,)`` int64 class id of every descriptor row (for a matcher index)."""
        return np.repeat(np.arange(self.n_classes, dtype=np.int64), np.diff(self.offsets))


@dataclass(frozen=True, eq=False)
class ModelView(ArrayEquality):
    """One model view of a region: an exploration image and its features (Section 7.2).

    Attributes:
        pose: index of the sampled pose the image belongs to.
        image_stamp_ns: the image's header stamp, nanoseconds.
        image_index: index of the image in the source bag's image topic.
        x: camera position in ``map``, metres.
        y: camera position in ``map``, metres.
        yaw: camera heading in ``map``, radians.
        class_ids: ``(m,)`` int64 class of each feature; every landmark and extra
            feature of the region that the image shows, and possibly more features of
            the image for the symmetry check of Section 6.2.1, which may belong to no
            class (id ``-1``). Ids >= 0 are distinct (local uniqueness, eq. 6.3).
        keypoints: ``(m, 2)`` float32 pixel coordinates (x right, y down).
        descriptors: ``(m, 128)`` uint8 SIFT descriptors in this image.
    """

    pose: int
    image_stamp_ns: int
    image_index: int
    x: float
    y: float
    yaw: float
    class_ids: np.ndarray
    keypoints: np.ndarray
    descriptors: np.ndarray

    def __post_init__(self) -> None:
        set_field(self, 'pose', int_at_least(self.pose, 'model view pose', 0))
        set_field(self, 'image_stamp_ns', int_at_least(self.image_stamp_ns,
                                                   'model view image_stamp_ns', 0))
        set_field(self, 'image_index', int_at_least(self.image_index,
                                                'model view image_index', 0))
        for name in ('x', 'y', 'yaw'):
            value = getattr(self, name)
            if (isinstance(value, bool) or not isinstance(value, (int, float, np.number))
                    or not math.isfinite(value)):
                raise LandmarkDbError(f'model view {name} must be a finite number, '
                                      f'got {value!r}')
            set_field(self, name, float(value))
        class_ids = int_array(self.class_ids, 'model view class_ids', (None,))
        m = class_ids.size
        if np.any(class_ids < -1):
            raise LandmarkDbError(f'model view class id {int(class_ids.min())} is invalid '
                                  f'(ids are >= 0, or -1 for a feature of no class)')
        known = class_ids[class_ids >= 0]
        if np.unique(known).size != known.size:
            raise LandmarkDbError('model view lists a class twice (eq. 6.3: one image '
                                  'feature per class)')
        set_field(self, 'class_ids', class_ids)
        keypoints = float_array(self.keypoints, 'model view keypoints', (m, 2))
        set_field(self, 'keypoints', read_only(keypoints.astype(np.float32)))
        descriptors = descriptor_array(self.descriptors, 'model view descriptors')
        if descriptors.shape[0] != m:
            raise LandmarkDbError(f'model view has {m} class ids but '
                                  f'{descriptors.shape[0]} descriptors')
        set_field(self, 'descriptors', descriptors)

    def __len__(self) -> int:
        return int(self.class_ids.size)


@dataclass(frozen=True, eq=False)
class RegionRecord(ArrayEquality):
    """One region: its poses, its landmark, extra features and model views.

    Attributes:
        poses: ``(p,)`` int64 pose indices, sorted and distinct (input is sorted).
        landmark: ``(k,)`` int64 class ids of the region's landmark, distinct, in the
            builder's order (the decomposition's ``features``).
        extra: ``(e,)`` int64 more class ids the region's poses see, distinct and not
            in ``landmark``; they vote for the region too (Section 7.1).
        model_views: the region's model views (the builder picks two at the extremes
            with the largest baseline and, where possible, a third off their line); at
            least one, each holding every landmark feature.
    """

    poses: np.ndarray
    landmark: np.ndarray
    extra: np.ndarray
    model_views: tuple[ModelView, ...]

    def __post_init__(self) -> None:
        raw = int_array(self.poses, 'region poses', (None,))
        poses = np.unique(raw)
        if poses.size != raw.size:
            raise LandmarkDbError('region lists a pose twice')
        if poses.size == 0:
            raise LandmarkDbError('region has no poses')
        set_field(self, 'poses', read_only(poses))
        landmark = int_array(self.landmark, 'region landmark', (None,))
        extra = int_array(self.extra, 'region extra', (None,))
        for name, ids in (('landmark', landmark), ('extra', extra)):
            if np.unique(ids).size != ids.size:
                raise LandmarkDbError(f'region {name} lists a class twice')
            if np.any(ids < 0):
                raise LandmarkDbError(f'region {name} has a negative class id')
        if landmark.size == 0:
            raise LandmarkDbError('region has an empty landmark')
        both = np.intersect1d(landmark, extra)
        if both.size:
            raise LandmarkDbError(f'class {int(both[0])} is both a landmark and an extra '
                                  f'feature of the region')
        set_field(self, 'landmark', landmark)
        set_field(self, 'extra', extra)
        views = tuple(self.model_views)
        if not views:
            raise LandmarkDbError('region has no model view')
        for i, view in enumerate(views):
            if not isinstance(view, ModelView):
                raise LandmarkDbError(f'model view {i} is a {type(view).__name__}, '
                                      f'not a ModelView')
            absent = np.setdiff1d(landmark, view.class_ids)
            if absent.size:
                raise LandmarkDbError(f'model view {i} (image {view.image_index}) lacks '
                                      f'landmark class {int(absent[0])}')
        set_field(self, 'model_views', views)

    @property
    def features(self) -> np.ndarray:
        """``(k + e,)`` int64 landmark then extra class ids: the classes voting for it."""
        return np.concatenate([self.landmark, self.extra])


@dataclass(frozen=True, eq=False)
class RegionAdjacency(ArrayEquality):
    """The region graph used for switching regions (Section 7.1).

    Two regions are neighbours when they share poses (they overlap) or when an edge of
    the pose graph G joins a pose of one to a pose of the other.

    Attributes:
        pairs: ``(q, 2)`` int64 region pairs ``(a, b)``, ``a < b``, sorted.
        shared_poses: ``(q,)`` int64 number of poses in both regions.
        joining_edges: ``(q,)`` int64 number of ordered pose pairs ``(u, v)``, ``u``
            in ``a`` and ``v`` in ``b``, that are edges of G (edges inside the overlap
            count too).
    """

    pairs: np.ndarray
    shared_poses: np.ndarray
    joining_edges: np.ndarray

    def __post_init__(self) -> None:
        pairs = int_array(self.pairs, 'adjacency pairs', (None, 2))
        q = pairs.shape[0]
        set_field(self, 'pairs', pairs)
        set_field(self, 'shared_poses', int_array(self.shared_poses, 'shared_poses', (q,)))
        set_field(self, 'joining_edges', int_array(self.joining_edges, 'joining_edges', (q,)))

    def neighbours(self, region: int) -> np.ndarray:
        """Return the sorted region ids adjacent to ``region``."""
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        return np.sort(np.concatenate([b[a == region], a[b == region]]))


@dataclass(frozen=True, eq=False)
class LandmarkDatabase(ArrayEquality):
    """A whole landmark database.

    Attributes:
        info: build parameters.
        poses: the sampled poses and pose graph.
        classes: feature classes, their descriptors and visibility.
        regions: the regions, region ``r`` is ``regions[r]``.
        uncovered: ``(u,)`` int64 sorted k-coverable poses no region covers (the
            decomposition's ``uncovered``).
        points: the scene points (:mod:`.points`; empty in a database built without).
        codebook: the product quantizer the file stores the descriptors with
            (:mod:`.codebook`; schema 5), or None: whole 128-byte descriptors. With a
            codebook every descriptor must be one its codes decode to
            (:meth:`quantized` makes them so); the writer refuses others.

    Derived (computed from the above, never stored twice): :attr:`membership`,
    :attr:`adjacency`, :meth:`to_world_instance`, :meth:`to_decomposition`.

    Raises:
        LandmarkDbError: when an index is out of range (a region pose, a class id, a
            model view pose) or the parts disagree on the number of poses.
    """

    info: BuildInfo
    poses: SampledPoses
    classes: FeatureClasses
    regions: tuple[RegionRecord, ...]
    uncovered: np.ndarray
    points: ScenePoints = field(default_factory=ScenePoints.empty)
    codebook: DescriptorCodebook | None = None

    def __post_init__(self) -> None:
        if self.codebook is not None and not isinstance(self.codebook, DescriptorCodebook):
            raise LandmarkDbError(f'codebook must be a DescriptorCodebook or None, got '
                                  f'{type(self.codebook).__name__}')
        for name, kind in (('info', BuildInfo), ('poses', SampledPoses),
                           ('classes', FeatureClasses)):
            if not isinstance(getattr(self, name), kind):
                raise LandmarkDbError(f'{name} must be a {kind.__name__}, '
                                      f'got {type(getattr(self, name)).__name__}')
        n, c = self.poses.n_poses, self.classes.n_classes
        if self.classes.visibility.shape[0] != n:
            raise LandmarkDbError(f'class visibility has {self.classes.visibility.shape[0]} '
                                  f'rows but there are {n} poses')
        regions = tuple(self.regions)
        for r, region in enumerate(regions):
            if not isinstance(region, RegionRecord):
                raise LandmarkDbError(f'region {r} is a {type(region).__name__}, '
                                      f'not a RegionRecord')
            if region.poses[-1] >= n:
                raise LandmarkDbError(f'region {r} has pose {int(region.poses[-1])} out of '
                                      f'range (there are {n} poses)')
            ids = region.features
            if ids.size and ids.max() >= c:
                raise LandmarkDbError(f'region {r} has class {int(ids.max())} out of range '
                                      f'(there are {c} classes)')
            for i, view in enumerate(region.model_views):
                if view.pose >= n:
                    raise LandmarkDbError(f'region {r} model view {i} has pose {view.pose} '
                                          f'out of range (there are {n} poses)')
                if view.class_ids.size and view.class_ids.max() >= c:
                    raise LandmarkDbError(
                        f'region {r} model view {i} has class {int(view.class_ids.max())} '
                        f'out of range (there are {c} classes)')
        set_field(self, 'regions', regions)
        raw = int_array(self.uncovered, 'uncovered', (None,))
        uncovered = np.unique(raw)
        if uncovered.size != raw.size:
            raise LandmarkDbError('uncovered lists a pose twice')
        check_range(uncovered, n, 'uncovered', 'pose')
        set_field(self, 'uncovered', read_only(uncovered))
        if not isinstance(self.points, ScenePoints):
            raise LandmarkDbError(f'points must be ScenePoints, got '
                                  f'{type(self.points).__name__}')
        self.points.class_points(c)  # every named class in range

    @property
    def n_poses(self) -> int:
        """Number of sampled poses."""
        return self.poses.n_poses

    @property
    def n_classes(self) -> int:
        """Number of feature classes."""
        return self.classes.n_classes

    @property
    def n_regions(self) -> int:
        """Number of regions."""
        return len(self.regions)

    @cached_property
    def region_poses(self) -> sp.csr_matrix:
        """``(n_regions, n_poses)`` bool CSR: which poses each region holds."""
        return incidence([r.poses for r in self.regions], self.n_poses)

    @cached_property
    def membership(self) -> sp.csr_matrix:
        """``(n_classes, n_regions)`` bool CSR: the regions each class votes for.

        A class is a member of a region when it is one of the region's landmark or
        extra features (Sections 3.1.4, 7.1); row ``c`` lists the regions for class c.
        """
        return incidence([r.features for r in self.regions], self.n_classes).T.tocsr()

    @cached_property
    def adjacency(self) -> RegionAdjacency:
        """The region graph: regions sharing poses or joined by an edge of G."""
        members = self.region_poses.astype(np.int64)
        shared = (members @ members.T).tocoo()
        pose_graph = adjacency_matrix(self.poses.edges, self.n_poses).astype(np.int64)
        joining = (members @ pose_graph @ members.T).tocoo()
        n = self.n_regions
        rows = np.concatenate([shared.row, joining.row]).astype(np.int64)
        cols = np.concatenate([shared.col, joining.col]).astype(np.int64)
        keep = rows < cols
        keys = np.unique(rows[keep] * max(n, 1) + cols[keep])
        pairs = np.column_stack([keys // max(n, 1), keys % max(n, 1)]).astype(np.int64)
        shared_csr = shared.tocsr()
        joining_csr = joining.tocsr()
        if keys.size:
            shared_count = np.asarray(shared_csr[pairs[:, 0], pairs[:, 1]]).reshape(-1)
            joining_count = np.asarray(joining_csr[pairs[:, 0], pairs[:, 1]]).reshape(-1)
        else:
            shared_count = joining_count = np.zeros(0, dtype=np.int64)
        return RegionAdjacency(pairs.reshape(-1, 2), shared_count.astype(np.int64),
                               joining_count.astype(np.int64))

    def content_digest(self) -> str:
        """Return a BLAKE2b digest (64 hex digits) of everything the database holds.

        Equal databases have equal digests; the file stores it so that reading detects
        damage SQLite's own checks cannot see (a changed descriptor byte or coordinate).
        """
        digest = hashlib.blake2b(digest_size=32)

        def add(data: bytes | np.ndarray | Any) -> None:
            if isinstance(data, np.ndarray):
                chunk = np.ascontiguousarray(data).tobytes()
                digest.update(f'{data.dtype.str}{data.shape}'.encode())
            elif isinstance(data, bytes):
                chunk = data
            else:
                chunk = json.dumps(data, sort_keys=True, allow_nan=False).encode()
            digest.update(len(chunk).to_bytes(8, 'little'))
            digest.update(chunk)

        add(self.info.to_dict())
        poses = self.poses
        for array in (poses.xy, poses.yaw, poses.grid, poses.edges):
            add(array)
        add(poses.spacing)
        classes = self.classes
        add(classes.descriptors)
        add(classes.offsets)
        add(classes.visibility.indptr.astype(np.int64))
        add(classes.visibility.indices.astype(np.int64))
        for region in self.regions:
            for array in (region.poses, region.landmark, region.extra):
                add(array)
            for view in region.model_views:
                add([view.pose, view.image_stamp_ns, view.image_index, view.x, view.y,
                     view.yaw])
                for array in (view.class_ids, view.keypoints, view.descriptors):
                    add(array)
        add(self.uncovered)
        if self.points.n_points:  # (schema 1 files have none: their digests hold)
            for array in (self.points.xyz, self.points.class_ids, self.points.descriptors,
                          self.points.views):
                add(array)
            if self.points.has_seen_from:  # (schema 2 files have none: their digests hold)
                add(self.points.seen_from)
            if self.points.has_patches:  # (schema 3 files have none: their digests hold)
                add(self.points.patches)
                add(self.points.patch_axes)
        if self.codebook is not None:  # (files before schema 5 have none: their digests hold)
            add(self.codebook.centroids)
            add([self.codebook.rms_error])
        return digest.hexdigest()

    def descriptor_arrays(self) -> list[np.ndarray]:
        """Every descriptor array: the classes', each model view's, the scene points'."""
        return [self.classes.descriptors,
                *(view.descriptors for region in self.regions for view in region.model_views),
                self.points.descriptors]

    def quantized(self, codebook: DescriptorCodebook | None) -> LandmarkDatabase:
        """Return this database with ``codebook``, every descriptor replaced by its code's.

        None returns the database with whole descriptors as they are (no codebook).
        """
        if codebook is None:
            return replace(self, codebook=None)
        regions = tuple(replace(region, model_views=tuple(
            replace(view, descriptors=codebook.quantize(view.descriptors))
            for view in region.model_views)) for region in self.regions)
        return replace(
            self, classes=replace(self.classes,
                                  descriptors=codebook.quantize(self.classes.descriptors)),
            regions=regions, codebook=codebook,
            points=replace(self.points, descriptors=codebook.quantize(self.points.descriptors))
            if self.points.n_points else self.points)

    def to_world_instance(self) -> WorldInstance:
        """Return the world instance: poses, G, and feature id ``c`` = class ``c``."""
        name = Path(self.info.source_bag).name if self.info.source_bag else ''
        headings = int(self.info.parameters.get('pose_headings', 1) or 1)
        poses = self.poses.xy if headings == 1 else np.column_stack([self.poses.xy,
                                                                     self.poses.yaw])
        return WorldInstance.from_visibility(
            poses, self.poses.edges, self.classes.visibility,
            feature_ids=np.arange(self.n_classes, dtype=np.int64),
            spacing=self.poses.spacing, name=name)

    def service(self, world: WorldInstance | None = None) -> Service:
        """Return the service of the stored regions (:mod:`landmark_db.decomposition.service`).

        Args:
            world: this database's world instance if the caller has it already.
        """
        return service(world if world is not None else self.to_world_instance(),
                       [region.poses for region in self.regions], self.info.k, self.info.rho)

    def to_decomposition(self) -> Decomposition:
        """Return the decomposition record (region landmarks as feature ids = class ids)."""
        regions = [Region(region.poses.copy(), np.sort(region.landmark))
                   for region in self.regions]
        info = self.info
        return Decomposition(info.algorithm, info.k, info.rho, info.sigma,
                             info.decomposition_seconds, regions, self.uncovered.copy())
