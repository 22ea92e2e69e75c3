"""The offline builder: from an exploration bag to a landmark database (Chapters 3, 5, 6).

``build(bag, config)`` composes one module per step, in the data's order:

==================== ============================================ ==========================
step                 what                                         module
==================== ============================================ ==========================
read                 images, camera info, image poses             :mod:`.exploration`
sample               sampled poses, pose graph G (6.2.1)          :mod:`.sampled_poses`
features             SIFT per image, in parallel (8.3.2)          :mod:`.features`
classes              correspondence classes, Algorithm 6.3        :mod:`.classes`
verify               one scene point per class (rays meet)        :mod:`.verification`
filter               retain good features (6.2.2, 8.3.2)          :mod:`.filters`
points               scene points of the verified classes         :mod:`.scene_points`
decompose            rho-MORDP regions (Chapter 5)                :mod:`landmark_db.decomposition`
model views          two or three views, extra features (7.2)     :mod:`.model_views`
compact              descriptor codes, JPEG patches (schema 5)    :mod:`landmark_db...compact`
database             one SQLite file, atomic                      :mod:`landmark_db.database`
==================== ============================================ ==========================

Each step's time and counts go into :class:`BuildReport`; ``vbn build --report`` draws
them. Configuration is one frozen :class:`BuildConfig` (the defaults live in the step
configs' dataclasses; ``config/builder.yaml`` repeats them for the ROS node, and a test
keeps the two equal).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
import logging
import os
from pathlib import Path
import time
from typing import Any

import numpy as np
import scipy.sparse as sp

from landmark_db.database import (
    BuildInfo,
    CameraIntrinsics,
    FeatureClasses,
    LandmarkDatabase,
    RegionRecord,
    SampledPoses,
    write_database,
)
from landmark_db.database.build_info import utc_now_iso
from landmark_db.database.compact import compact_database
from landmark_db.decomposition import Decomposition, decompose, service
from landmark_db.world import WorldInstance
from vbn_common.atomic import check_output_folder
from vbn_common.errors import NoPoseSourceError
from vbn_common.exploration import Exploration, read_exploration
from vbn_common.features import ImageFeatures, extract_many
from vbn_common.geometry.camera import camera_from_info
from vbn_common.geometry.frames import compose_poses, invert_pose
from visibility_builder.build_config import (
    BuildConfig,
    DecompositionConfig,
    config_from_flat,
    flat_config,
    setting_descriptions,
)
from visibility_builder.classes import correspondence_classes
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.filters import retain_good_features
from visibility_builder.model_views import (
    ImageTable,
    class_descriptors,
    extra_features,
    select_model_views,
)
from visibility_builder.point_patches import patch_sources
from visibility_builder.sampled_poses import PoseSampling, sample_poses
from visibility_builder.scene_points import labels_by_image, scene_points
from visibility_builder.verification import verify_classes

__all__ = ['BuildConfig', 'BuildReport', 'BuildResult', 'DecompositionConfig', 'build',
           'build_from_exploration', 'config_from_flat', 'flat_config',
           'setting_descriptions']

_LOG = logging.getLogger(__name__)


@dataclass
class BuildReport:
    """Counts and timings of one build (the closing figures of ``vbn build``).

    Attributes:
        seconds: Per step, wall seconds.
        counts: Per step, named counts.
        visibility_sizes_before: (n_classes_before,) poses per class after Algorithm 6.3.
        visibility_sizes_after: (n_classes,) poses per class after the filters.
    """

    seconds: dict[str, float] = field(default_factory=dict)
    counts: dict[str, dict[str, Any]] = field(default_factory=dict)
    visibility_sizes_before: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    visibility_sizes_after: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    def summary(self) -> dict[str, Any]:
        """JSON-able summary: counts and seconds per step."""
        return {'seconds': {k: round(v, 3) for k, v in self.seconds.items()},
                'counts': self.counts}


@dataclass
class BuildResult:
    """What ``build`` made.

    Attributes:
        database: The landmark database (written to disk when a path was given).
        world: The world instance the decomposition ran on.
        decomposition: The decomposition.
        sampling: The sampled poses and graph.
        report: Counts and timings.
    """

    database: LandmarkDatabase
    world: WorldInstance
    decomposition: Decomposition
    sampling: PoseSampling
    report: BuildReport


class _Stages:
    """Times the steps and reports progress (``on_stage(name, fraction)``)."""

    def __init__(self, report: BuildReport,
                 on_stage: Callable[[str, str], None] | None) -> None:
        self.report = report
        self.on_stage = on_stage
        self.check_stop: Callable[[], None] | None = None
        self.name = ''
        self.start = 0.0

    def begin(self, name: str, detail: str = '') -> None:
        if self.check_stop is not None:
            self.check_stop()
        self.name, self.start = name, time.perf_counter()
        if self.on_stage:
            self.on_stage(name, detail)     # the caller says it (vbn build: one line)
        else:
            _LOG.info('%s %s', name, detail)

    def end(self, **counts: Any) -> None:
        self.report.seconds[self.name] = time.perf_counter() - self.start
        self.report.counts[self.name] = counts


def _level_keypoints(frames: Sequence[Any], features: list[ImageFeatures],
                     exploration: Exploration) -> int:
    """Move the keypoints of frames tilted beyond the mount to where the mount puts them.

    A frame whose pose source tilts it (a shaking robot: the ground truth carries the
    pitch and roll) sees the scene a fraction of a degree off; its keypoints are
    re-projected, ray by ray, into the camera as mounted, so that the classes, their
    geometric check and the model views all see one camera. Descriptors are kept (the
    patch barely changes). Returns how many frames were moved.
    """
    mounted = exploration.camera_model()
    lens = getattr(mounted, 'camera', mounted)
    moved = 0
    for i, frame in enumerate(frames):
        tilt = getattr(frame, 'camera_tilt', None)
        if tilt is None or len(features[i]) == 0:
            continue
        rays = lens.unproject(features[i].keypoints.astype(float)) @ np.asarray(tilt).T
        uv, _ = mounted.project(rays)
        features[i] = replace(features[i], keypoints=uv.astype(np.float32))
        moved += 1
    return moved


def _camera_intrinsics(exploration: Exploration) -> CameraIntrinsics:
    info = exploration.camera_info
    kind = camera_from_info(info).kind
    return CameraIntrinsics(kind=kind, width=info.width, height=info.height,
                            K=np.asarray(info.k, float).reshape(3, 3),
                            D=np.asarray(info.d, float), distortion_model=info.distortion_model,
                            frame_id=info.frame_id)


def build(bag: str | os.PathLike[str], config: BuildConfig = BuildConfig(),
          db_path: str | os.PathLike[str] | None = None,
          on_stage: Callable[[str, str], None] | None = None,
          on_image: Callable[[int], None] | None = None,
          source: str | None = None,
          check_stop: Callable[[], None] | None = None) -> BuildResult:
    """Build the landmark database of an exploration bag.

    Args:
        bag: The rosbag2 directory (or ``.mcap``).
        config: Every setting.
        db_path: Write the database here (atomically); None: only return it.
        on_stage: Called with ``(step name, detail)`` when a step starts.
        on_image: Called with a count each time SIFT finished images (progress).
        source: What the database records as its source (default: the bag's path; the
            builder node's live mode names what it recorded, its bag being temporary).
        check_stop: Called between units of the long steps (each SIFT image, each chunk
            of pose pairs matched in the process pool) and at each step: what it raises
            stops the build there (the workers are terminated, nothing is written).

    Raises:
        VisibilityBuilderError: Nothing can be built (no images, no poses, too few
            features for k, ...); the message names the problem. No file is written.
    """
    report = BuildReport()
    stages = _Stages(report, on_stage)
    stages.begin('read', str(bag))
    try:
        exploration = read_exploration(bag, config.read)
    except NoPoseSourceError as error:
        if config.read.pose_source != 'auto':
            raise
        from visibility_builder.estimation.pipeline import estimate_from_odometry

        exploration = estimate_from_odometry(bag, config.read, config.workers, error)
    stages.end(frames=len(exploration.frames), pose_source=exploration.pose_source,
               skipped=dict(exploration.skipped))
    return build_from_exploration(exploration, config, db_path, stages=stages,
                                  on_image=on_image, source=source, check_stop=check_stop)


def build_from_exploration(exploration: Exploration, config: BuildConfig = BuildConfig(),
                           db_path: str | os.PathLike[str] | None = None,
                           stages: _Stages | None = None,
                           on_stage: Callable[[str, str], None] | None = None,
                           on_image: Callable[[int], None] | None = None,
                           source: str | None = None,
                           check_stop: Callable[[], None] | None = None) -> BuildResult:
    """Build from frames already read (the builder node's live mode collects them).

    See :func:`build`.
    """
    stages = stages or _Stages(BuildReport(), on_stage)
    stages.check_stop = check_stop
    report = stages.report

    if db_path is not None:
        _check_output(Path(db_path))
    frames = exploration.frames
    if not frames:
        raise VisibilityBuilderError(f'no usable image in {exploration.path}')

    stages.begin('sample')
    sampling = sample_poses(exploration, config.sampling, config.decomposition.rho)
    stages.end(poses=sampling.n_poses, edges=int(len(sampling.edges)),
               spacing=sampling.spacing, graph=sampling.graph, headings=sampling.headings)

    stages.begin('features', f'{len(frames)} images on {config.n_workers} process(es)')
    results = extract_many([f.image for f in frames], config.sift, config.n_workers,
                           progress=on_image, check_stop=check_stop)
    features: list[ImageFeatures] = []
    undecodable = 0
    for frame, result in zip(frames, results, strict=True):
        if isinstance(result, str):
            _LOG.warning('image at %.3f s skipped: %s', frame.stamp_ns / 1e9, result)
            undecodable += 1
            features.append(ImageFeatures.empty())
        else:
            features.append(result)
    levelled = _level_keypoints(frames, features, exploration)
    n_feats = np.array([len(f) for f in features])
    stages.end(images=len(frames), undecodable=undecodable, features=int(n_feats.sum()),
               per_image_mean=float(n_feats.mean()), per_image_median=float(np.median(n_feats)),
               **({'levelled_images': levelled} if levelled else {}))

    stages.begin('classes')
    pose_descriptors = [
        np.concatenate([features[i].descriptors for i in members])  # uint8
        for members in sampling.frames_of_pose]
    classes = correspondence_classes(
        pose_descriptors, sampling.edges,
        replace(config.classes, workers=max(config.classes.workers, config.n_workers)),
        check_stop=check_stop)
    # One scene point per class: the rays of its members must meet (verification.py).
    classes = verify_classes(
        classes,
        [np.concatenate([features[i].keypoints for i in members])
         for members in sampling.frames_of_pose],
        [np.concatenate([features[i].sizes for i in members])
         for members in sampling.frames_of_pose],
        [np.concatenate([np.repeat(np.asarray([frames[i].camera_pose], float), len(features[i]),
                                   axis=0) for i in members])
         for members in sampling.frames_of_pose],
        exploration.camera_model(), config.verify)
    sizes_before = np.asarray(classes.visibility.sum(axis=0)).ravel().astype(int)
    report.visibility_sizes_before = sizes_before
    stages.end(**{k: (int(v) if float(v).is_integer() else float(v))
                  for k, v in classes.stats.items()})

    stages.begin('filter')
    filtered = retain_good_features(classes.visibility, sampling.sector_grid(), sampling.edges,
                                    config.filters)
    visibility = filtered.visibility.tocsr().astype(bool)
    kept = np.asarray(filtered.kept_classes, np.int64)
    report.visibility_sizes_after = np.asarray(visibility.sum(axis=0)).ravel().astype(int)
    stages.end(**filtered.counts_dict())
    if visibility.shape[1] == 0:
        raise VisibilityBuilderError(
            'no feature class survived the filters (try a lower filters.min_poses or '
            'filters.min_block)')

    stages.begin('points')
    image_labels = labels_by_image(sampling.frames_of_pose, classes.labels,
                                   [len(f) for f in features])
    points = scene_points(image_labels, features, np.array([f.camera_pose for f in frames]),
                          exploration.camera_model(), kept, config.points, *patch_sources(frames))
    stages.end(points=points.n_points, of_kept_classes=int((points.class_ids >= 0).sum()),
               with_patch=int(points.patch_mask.sum()))

    stages.begin('decompose', f'{config.decomposition.algorithm}, k={config.decomposition.k}')
    spacing = sampling.spacing
    world = WorldInstance.from_visibility(sampling.world_poses(), sampling.edges, visibility,
                                          spacing=spacing, name=str(exploration.path.name))
    per_pose = np.asarray(visibility.sum(axis=1)).ravel()
    dc = config.decomposition
    if per_pose.max(initial=0) < dc.k:
        raise VisibilityBuilderError(
            f"k={dc.k} is larger than any pose's visibility (at most "
            f'{int(per_pose.max(initial=0))} filtered features per pose): lower --k')
    decomposition = decompose(world, dc.algorithm, dc.k, dc.rho, dc.sigma, rng=dc.seed,
                              check_stop=check_stop)
    served = service(world, [region.poses for region in decomposition.regions], dc.k, dc.rho)
    bound = {} if decomposition.lower_bound is None else {
        'lower_bound': decomposition.lower_bound,
        'ratio_to_bound': round(len(decomposition.regions) / decomposition.lower_bound, 4)
        if decomposition.lower_bound else None}
    stages.end(regions=len(decomposition.regions), **served.to_dict(), **bound,
               mean_region_poses=float(np.mean([r.poses.size for r in decomposition.regions]))
               if decomposition.regions else 0.0)
    if served.k_coverable == 0:
        raise VisibilityBuilderError(
            f'no pose is k-coverable: none sees k={dc.k} features throughout its '
            f'rho={dc.rho} neighbourhood (lower --k or --rho)')

    stages.begin('model_views')
    database = replace(_assemble(exploration, sampling, features, image_labels, kept,
                                 visibility, decomposition, world, config,
                                 source or str(exploration.path)), points=points)
    final = database.service(world)
    stages.end(regions=database.n_regions,
               regions_without_view=len(decomposition.regions) - database.n_regions,
               model_views=sum(len(r.model_views) for r in database.regions),
               extra_features=int(sum(r.extra.size for r in database.regions)),
               descriptors=int(database.classes.descriptors.shape[0]),
               served=final.served, served_share=round(final.share, 6))

    stages.begin('compact')
    database, compaction = compact_database(
        database, config.descriptor_bytes, config.points.patch_quality,
        np.random.default_rng(dc.seed))
    stages.end(**compaction.to_dict())

    if db_path is not None:
        stages.begin('write', str(db_path))
        write_database(db_path, database)
        stages.end(bytes=Path(db_path).stat().st_size)
    return BuildResult(database, world, decomposition, sampling, report)


def _check_output(path: Path) -> None:
    """Fail before any work when the database could not be written."""
    if path.is_dir():
        raise VisibilityBuilderError(f'--db {path} is a folder, not a file')
    check_output_folder(path)


def _assemble(exploration: Exploration, sampling: PoseSampling,
              features: Sequence[ImageFeatures], verified_labels: Sequence[np.ndarray],
              kept: np.ndarray, visibility: sp.csr_matrix, decomposition: Decomposition,
              world: WorldInstance, config: BuildConfig, source: str) -> LandmarkDatabase:
    # verified_labels: per image, the verified class of each feature (-1: none), before
    # the filters' renumbering (scene_points.labels_by_image).
    frames = exploration.frames
    n_images = len(frames)
    # Database class numbering: position in ``kept``; a removed class becomes -1.
    remap = np.full(int(max(kept.max(initial=-1) + 1, 1 + max(
        (int(lab.max(initial=-1)) for lab in verified_labels), default=-1))), -1, np.int64)
    remap[kept] = np.arange(kept.size)
    image_pose = np.empty(n_images, np.int64)
    for pose, members in enumerate(sampling.frames_of_pose):
        image_pose[list(members)] = pose
    image_labels = [np.where(part >= 0, remap[np.maximum(part, 0)], -1)
                    for part in verified_labels]
    camera = np.array([f.camera_pose for f in frames], float)
    table = ImageTable(pose=image_pose, stamp_ns=np.array([f.stamp_ns for f in frames]),
                       camera_xy=camera[:, :2], camera_yaw=camera[:, 2], features=features,
                       labels=image_labels)

    # Representative descriptors: features whose (pose, class) survived the filters.
    vis = visibility.tocsr()
    cls_list, desc_list, pos_list = [], [], []
    for i in range(n_images):
        labels = image_labels[i]
        valid = np.flatnonzero(labels >= 0)
        if valid.size == 0:
            continue
        keep = valid[np.asarray(vis[image_pose[i], labels[valid]].todense()).ravel()]
        cls_list.append(labels[keep])
        desc_list.append(features[i].descriptors[keep])
        pos_list.append(np.repeat(camera[i:i + 1, :2], keep.size, axis=0))
    descriptors, offsets = class_descriptors(
        np.concatenate(cls_list), np.concatenate(desc_list), np.concatenate(pos_list),
        vis.shape[1], config.descriptors_per_class)

    regions = []
    dropped = []
    for region in decomposition.regions:
        landmark = np.asarray(region.features, np.int64)
        extra = extra_features(vis, region.poses, landmark, config.model_views)
        try:
            views = select_model_views(table, region.poses, landmark, extra,
                                       config.model_views)
        except VisibilityBuilderError as error:
            # Several images per pose (pinhole headings): the pose sees the k landmark
            # features, but no single image does, so the region has no model view.
            dropped.append(region)
            _LOG.warning('region dropped: %s', error)
            continue
        regions.append(RegionRecord(poses=region.poses, landmark=landmark, extra=extra,
                                    model_views=views))
    if not regions:
        raise VisibilityBuilderError(
            'no region has an image that shows its whole landmark (several images per '
            'pose each see only part of it): try a smaller --k')
    if dropped:
        _LOG.warning('%d of %d regions dropped: no image shows the whole landmark',
                     len(dropped), len(decomposition.regions))
    # The poses the kept regions do not serve (more than the decomposition's when a
    # region was dropped).
    uncovered = service(world, [region.poses for region in regions], config.decomposition.k,
                        config.decomposition.rho).unserved

    dc = config.decomposition
    info = BuildInfo(
        k=dc.k, rho=dc.rho, sigma=dc.sigma, algorithm=dc.algorithm,
        pose_source=exploration.pose_source, source_bag=source,
        created_utc=utc_now_iso(), camera=_camera_intrinsics(exploration),
        frames=dict(exploration.frame_ids), sift=config.sift.as_dict(),
        parameters={**{k: v for k, v in flat_config(config).items()
                       if not k.startswith(('sift.', 'decomposition.'))},
                    # Heading sectors of the pose space (1: positions only): the
                    # localizer's pose lookups then weigh headings as well.
                    'pose_headings': int(sampling.headings),
                    # The camera's pitch and roll on base_link (ray_level = tilt @ ray),
                    # from /tf_static; the localizer levels its rays with it.
                    **({} if exploration.camera_tilt is None else {'camera_tilt': [
                        round(float(v), 12) for v in np.ravel(exploration.camera_tilt)]}),
                    # The camera's planar pose on base_link (x, y, yaw): the localizer
                    # turns the camera pose it computes into base_link's with it.
                    'camera_mount': [round(float(v), 9) for v in compose_poses(
                        invert_pose(frames[0].base_pose), frames[0].camera_pose)]},
        decomposition_seconds=float(decomposition.seconds))
    poses = SampledPoses(xy=sampling.positions, yaw=sampling.yaw, grid=sampling.grid,
                         edges=sampling.edges, spacing=sampling.spacing)
    return LandmarkDatabase(info=info, poses=poses,
                            classes=FeatureClasses(descriptors, offsets, vis),
                            regions=tuple(regions), uncovered=uncovered)
