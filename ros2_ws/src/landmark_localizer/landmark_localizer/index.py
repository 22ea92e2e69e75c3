"""The database as the localizer uses it, prepared once at start-up (thesis 3.1.4, 7.1).

:class:`DatabaseIndex` holds, from a :class:`~landmark_db.database.LandmarkDatabase`:

- the descriptor index for voting: every class's representative descriptors (a few per
  class, thousands in all: 1,956 in the room, 28,148 on the floor) in a FLANN
  randomised KD-tree forest built once (:meth:`DatabaseIndex.nearest_classes`; an
  exact BLAS product on request), so that voting does not scan the whole database;
- the feature-to-region membership (voting) and the region graph (switching);
- per region, its features (landmark then extra) and its model views as arrays;
- per class, a 3-D point triangulated from the model views that show it: the
  localizer predicts where a feature should appear in the current image from the
  current pose, to re-detect a lost track or pick up a new region's features after a
  switch, and checks and polishes its two-view poses on them;
- the database's scene points, those of classes the filters dropped included, with
  their descriptors in a second FLANN forest: the 2D-3D matches of a pose where no
  region serves (:mod:`.absolute_pose`);
- the sampled poses in a KD-tree, for "which region contains this position".

Nothing here depends on the size of the database at run time except voting in LOST.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any

import cv2
from numba import njit
import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from landmark_db.database import LandmarkDatabase
from landmark_localizer.errors import LocalizerError
from landmark_localizer.matching import grouped_nearest, squared_distances
from vbn_common.errors import VbnCommonError
from vbn_common.geometry.camera import CameraModel, camera_from_info, pixels_per_radian
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION
from vbn_common.geometry.mount import tilted

__all__ = ['DatabaseIndex', 'RegionData', 'ViewData', 'tilt_rotation']

#: FLANN's randomised KD-trees (``FLANN_INDEX_KDTREE``), trees in the forest, and the
#: neighbours fetched per query (enough to find the nearest descriptor of another class:
#: a class has about four).
_FLANN_KDTREE = 1
FLANN_SEED = 0
FLANN_TREES = 4
FLANN_NEIGHBOURS = 8


@dataclass(frozen=True)
class ViewData:
    """One model view as arrays.

    Attributes:
        pose: (3,) camera pose (x, y, yaw) in ``map``.
        class_ids: (m,) classes of its features (>= 0 only).
        keypoints: (m, 2) float64 pixels.
        descriptors: (m, 128) float32.
        position: ``{class id: row}``.
    """

    pose: np.ndarray
    class_ids: np.ndarray
    keypoints: np.ndarray
    descriptors: np.ndarray
    position: dict[int, int]


@dataclass(frozen=True)
class RegionData:
    """One region as the localizer uses it.

    Attributes:
        index: Region index in the database.
        poses: (p,) sorted pose indices.
        features: (k + e,) landmark then extra class ids.
        landmark: (k,) landmark class ids.
        views: Its model views.
        view_classes: Sorted classes at least one of its model views shows.
    """

    index: int
    poses: np.ndarray
    features: np.ndarray
    landmark: np.ndarray
    views: tuple[ViewData, ...]
    view_classes: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        seen = [v.class_ids for v in self.views] or [np.zeros(0, np.int64)]
        object.__setattr__(self, 'view_classes', np.unique(np.concatenate(seen)))


class _CameraInfo:
    """CameraInfo-like view of the database's intrinsics (for ``camera_from_info``)."""

    def __init__(self, camera: Any) -> None:
        self.width, self.height = camera.width, camera.height
        self.distortion_model = camera.distortion_model
        self.k = np.asarray(camera.K, float).reshape(-1)
        self.d = np.asarray(camera.D, float).reshape(-1)


class DatabaseIndex:
    """Everything the localizer looks up, built once from the database.

    Args:
        database: The landmark database (``landmark_db.database.open_database``).

    Raises:
        LocalizerError: A database the localizer cannot use (no region, a camera
            model it does not know).
    """

    def __init__(self, database: LandmarkDatabase) -> None:
        if database.n_regions == 0:
            raise LocalizerError('the database has no region: nothing to localize against')
        self.database = database
        self.k = int(database.info.k)
        try:
            self.camera: CameraModel = tilted(
                camera_from_info(_CameraInfo(database.info.camera)),
                database.info.parameters.get('camera_tilt'))
        except VbnCommonError as error:
            raise LocalizerError(f'database camera: {error}') from error
        # The camera of the frames being localized: the database's, or the run's own
        # (another resolution or calibration; camera_check.frame_camera).
        self.frame_camera: CameraModel = self.camera
        self._view_rays: dict[int, np.ndarray] = {}  # id(ViewData) -> its keypoints' rays
        mount = database.info.parameters.get('camera_mount', [0.0, 0.0, 0.0])
        self.camera_mount = np.asarray(mount, float).reshape(3)
        classes = database.classes
        self.descriptors = classes.descriptors.astype(np.float32)
        self.descriptor_norms = np.einsum('ij,ij->i', self.descriptors, self.descriptors)
        self.descriptor_class = np.asarray(classes.descriptor_classes, np.int64)
        self.n_classes = classes.n_classes
        # Each class's descriptor rows, for re-detection: rows _by_class[_starts[c]:
        # _starts[c + 1]] (a scan of every descriptor per class would grow with the database).
        self._by_class = np.argsort(self.descriptor_class, kind='stable')
        self._starts = np.searchsorted(self.descriptor_class[self._by_class],
                                       np.arange(self.n_classes + 1))
        self._flann = _kd_forest(self.descriptors)
        self.membership: sp.csr_matrix = database.membership.tocsr()  # (classes, regions)
        self.regions = tuple(self._region(i, r) for i, r in enumerate(database.regions))
        self.region_poses: sp.csr_matrix = database.region_poses.tocsr(copy=True)  # (regions,
        self.region_poses.sort_indices()   # poses); region_contains searches each row
        self.pose_regions: sp.csc_matrix = self.region_poses.tocsc()
        self.xy = np.asarray(database.poses.xy, float)
        self.position_tree = cKDTree(self.xy)
        self.spacing = float(database.poses.spacing or _median_spacing(self.position_tree,
                                                                       self.xy))
        # The pose space: positions, or positions and heading sectors. A
        # heading h joins the position as r (cos h, sin h), with r such that the
        # neighbouring sectors lie one grid spacing apart: distances, balls and nearest
        # poses then weigh a turn by one sector like a step to a neighbouring position.
        self.headings = int(database.info.parameters.get('pose_headings', 1) or 1)
        self.heading_radius = 0.0 if self.headings == 1 else \
            self.spacing / (2.0 * math.sin(math.pi / self.headings))
        self.yaw = np.asarray(database.poses.yaw, float)
        self.tree = cKDTree(self._embed(self.xy, self.yaw))
        adjacency = database.adjacency
        n = database.n_regions
        pairs = np.asarray(adjacency.pairs, np.int64).reshape(-1, 2)
        graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        self.region_graph = (graph + graph.T).tocsr()
        # (The builder's scene points of these classes were tried here: on the pinhole
        # room they polished the tracked poses worse, p95 4.9 -> 6.7 cm.)
        self.points = self._triangulate()
        scene = database.points
        self.scene_xyz = np.asarray(scene.xyz, float)
        self.scene_class = np.asarray(scene.class_ids, np.int64)
        self._scene_flann = _kd_forest(scene.descriptors.astype(np.float32)) \
            if scene.n_points >= 2 else None

    @property
    def residual_focal(self) -> float:
        """Pixels per radian at which a pose's residuals are judged.

        Every residual mixes the database's measurements (model view keypoints, class
        points triangulated from them) with the frame's, so its noise is that of the
        coarser camera: a run camera of twice the database's resolution, judged at its
        own pixels, rejected correct correspondences for the database's half-pixel
        noise and fitted a wrong pose to the few it kept (a 1280 x 960 pinhole run on a
        640 x 480 database: tracked poses 20 to 40 cm off from tracks within 0.6 px).
        """
        return min(pixels_per_radian(self.camera), pixels_per_radian(self.frame_camera))

    def class_descriptors(self, class_id: int) -> np.ndarray:
        """(d, 128) float32: the representative descriptors of one class."""
        rows = self._by_class[self._starts[class_id]:self._starts[class_id + 1]]
        return self.descriptors[rows]

    # -- voting --------------------------------------------------------------------------
    def nearest_classes(self, query: np.ndarray, checks: int = 64
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest class of each query descriptor and the distance to the nearest other.

        Args:
            query: (n, 128) descriptors.
            checks: FLANN leaves visited per query (more: nearer exact, slower); 0 for
                the exact answer by one BLAS product over every descriptor (its cost
                grows with the database: 0.8 s per image on the floor's).

        Returns:
            ``(best_class, best_distance, other_distance)``, each (n,); ``-1`` and inf
            where nothing is found (the other distance is inf when the
            ``FLANN_NEIGHBOURS`` nearest descriptors all belong to the best class).
        """
        query = np.ascontiguousarray(query, np.float32)
        n = len(query)
        if n == 0:
            return np.full(0, -1, np.int64), np.zeros(0), np.zeros(0)
        if checks <= 0:
            d2 = squared_distances(query, self.descriptors, self.descriptor_norms)
            return grouped_nearest(d2, self.descriptor_class, self.n_classes)
        k = min(FLANN_NEIGHBOURS, len(self.descriptors))
        rows, d2 = self._flann.knnSearch(query, k, params={'checks': int(checks)})
        rows = rows.reshape(n, k)
        found = rows >= 0
        classes = np.where(found, self.descriptor_class[np.maximum(rows, 0)], -1)
        distances = np.where(found, np.sqrt(np.maximum(d2.reshape(n, k), 0.0)), np.inf)
        best = classes[:, 0]
        other = found & (classes != best[:, None])
        first_other = np.argmax(other, axis=1)
        other_d = np.where(other.any(axis=1), distances[np.arange(n), first_other], np.inf)
        return best.astype(np.int64), distances[:, 0].astype(float), other_d.astype(float)

    def nearest_scene_points(self, query: np.ndarray, checks: int = 64
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Nearest scene point of each query descriptor and the second nearest's distance.

        Returns:
            ``(point, distance, second_distance)``, each (n,), or None when the database
            holds no scene points (a schema 1 file).
        """
        if self._scene_flann is None:
            return None
        query = np.ascontiguousarray(query, np.float32)
        n = len(query)
        if n == 0:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
        rows, d2 = self._scene_flann.knnSearch(query, 2, params={'checks': int(checks)})
        rows, d2 = rows.reshape(n, 2), np.maximum(d2.reshape(n, 2), 0.0)
        found = rows >= 0
        distances = np.where(found, np.sqrt(d2), np.inf)
        return np.where(found[:, 0], rows[:, 0], -1).astype(np.int64), \
            distances[:, 0].astype(float), distances[:, 1].astype(float)

    # -- construction ------------------------------------------------------------------
    @staticmethod
    def _region(index: int, record: Any) -> RegionData:
        views = []
        for view in record.model_views:
            keep = np.flatnonzero(view.class_ids >= 0)
            ids = view.class_ids[keep].astype(np.int64)
            views.append(ViewData(
                pose=np.array([view.x, view.y, view.yaw]), class_ids=ids,
                keypoints=view.keypoints[keep].astype(np.float64),
                descriptors=view.descriptors[keep].astype(np.float32),
                position={int(c): i for i, c in enumerate(ids)}))
        return RegionData(index, np.asarray(record.poses, np.int64),
                          np.asarray(record.features, np.int64),
                          np.asarray(record.landmark, np.int64), tuple(views))

    def view_rays(self, view: ViewData) -> np.ndarray:
        """``(m, 3)`` optical rays of a model view's keypoints (computed once per view)."""
        rays = self._view_rays.get(id(view))
        if rays is None:
            rays = self._view_rays[id(view)] = self.camera.unproject(view.keypoints)
        return rays

    def rays_in_map(self, view_pose: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """(n, 3) unit directions in ``map`` (z up) of pixels seen from a camera pose."""
        rays = self.camera.unproject(np.asarray(uv, float).reshape(-1, 2))
        base = rays @ BASE_TO_CAMERA_ROTATION.T
        c, s = math.cos(view_pose[2]), math.sin(view_pose[2])
        return np.stack([c * base[:, 0] - s * base[:, 1], s * base[:, 0] + c * base[:, 1],
                         base[:, 2]], axis=1)

    def _triangulate(self) -> np.ndarray:
        """(n_classes, 3) points relative to the camera height (NaN: not triangulated).

        For each class, the rays of every model view that shows it (over all regions)
        meet in the least-squares point; classes seen by fewer than two views, or by
        nearly parallel rays (under 2 degrees), stay NaN.
        """
        ray_sum = np.zeros((self.n_classes, 3, 3))
        rhs = np.zeros((self.n_classes, 3))
        count = np.zeros(self.n_classes, int)
        seen: set[tuple[int, int]] = set()
        directions: dict[int, list[np.ndarray]] = {}
        for region in self.regions:
            for view in region.views:
                key = (round(float(view.pose[0]), 6), round(float(view.pose[1]), 6))
                dirs = self.rays_in_map(view.pose, view.keypoints)
                origin = np.array([view.pose[0], view.pose[1], 0.0])
                for c, d in zip(view.class_ids, dirs, strict=True):
                    if (int(c), hash(key)) in seen:
                        continue
                    seen.add((int(c), hash(key)))
                    projector = np.eye(3) - np.outer(d, d)
                    ray_sum[c] += projector
                    rhs[c] += projector @ origin
                    count[c] += 1
                    directions.setdefault(int(c), []).append(d)
        points = np.full((self.n_classes, 3), np.nan)
        for c in np.flatnonzero(count >= 2):
            dirs = np.array(directions[int(c)])
            cosines = np.clip(np.abs(dirs @ dirs.T), 0, 1)
            if cosines.min() > math.cos(math.radians(2.0)):
                continue
            try:
                points[c] = np.linalg.solve(ray_sum[c], rhs[c])
            except np.linalg.LinAlgError:
                continue
        return points

    # -- queries ------------------------------------------------------------------------
    def region_contains(self, region: int, poses: np.ndarray) -> np.ndarray:
        """(len(poses),) bool: which of the pose indices belong to the region."""
        m = self.region_poses  # slices of the CSR arrays: a sparse row costs 0.1 ms
        row = m.indices[m.indptr[region]:m.indptr[region + 1]]   # sorted (__init__)
        poses = np.asarray(poses, np.int64)
        if not len(row):
            return np.zeros(poses.shape, bool)
        at = np.minimum(np.searchsorted(row, poses), len(row) - 1)
        return row[at] == poses

    def regions_of_pose(self, pose: int) -> np.ndarray:
        """Region indices containing the pose."""
        m = self.pose_regions
        return m.indices[m.indptr[pose]:m.indptr[pose + 1]]

    def same_sector(self, a: int, b: int) -> bool:
        """Whether two sampled poses lie in one heading sector (always without sectors)."""
        if self.headings == 1:
            return True
        turn = (self.yaw[a] - self.yaw[b] + math.pi) % (2 * math.pi) - math.pi
        return abs(turn) < math.pi / self.headings

    def _embed(self, xy: np.ndarray, camera_heading: np.ndarray) -> np.ndarray:
        if self.headings == 1:
            return np.asarray(xy, float)
        r = self.heading_radius
        return np.column_stack([xy, r * np.cos(camera_heading), r * np.sin(camera_heading)])

    def pose_points(self, base_poses: np.ndarray) -> np.ndarray:
        """Return ``(n, 3)`` base poses ``(x, y, yaw)`` as points of the pose space.

        ``(n, 2)`` positions without heading sectors; ``(n, 4)`` with them, from the
        camera's heading (base yaw plus the mount's).
        """
        poses = np.asarray(base_poses, float).reshape(-1, 3)
        return self._embed(poses[:, :2], poses[:, 2] + self.camera_mount[2])

    def nearest_pose(self, pose: np.ndarray) -> tuple[int, float]:
        """Return the sampled pose nearest a base pose ``(x, y, yaw)`` and its distance.

        Without heading sectors only the position counts (a position alone will do).
        """
        pose = np.asarray(pose, float)
        if self.headings == 1:
            distance, index = self.tree.query(pose[:2])
        else:
            distance, index = self.tree.query(self.pose_points(pose[:3])[0])
        return int(index), float(distance)

    def poses_near(self, pose: np.ndarray, radius: float) -> list[int]:
        """Return the sampled poses within ``radius`` (metres in the pose space)."""
        pose = np.asarray(pose, float)
        point = pose[:2] if self.headings == 1 else self.pose_points(pose[:3])[0]
        return list(self.tree.query_ball_point(point, r=radius))

    def project(self, camera_pose: np.ndarray, class_ids: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """Predicted pixels of classes from a camera pose: ``(uv (n, 2), valid (n,))``.

        Pixels of :attr:`frame_camera`, the camera of the frames being localized.
        """
        return self.project_points(camera_pose, self.points[class_ids])

    def project_points(self, camera_pose: np.ndarray, points: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of 3-D points (``z`` from the camera height) from a camera pose.

        ``camera_pose``: planar ``(x, y, yaw)``, or ``(x, y, yaw, pitch, roll, dz)`` with
        the frame's own tilt and height offset (the state of
        :func:`.absolute_pose.refine_absolute`). Returns ``(uv (n, 2), valid (n,))``: NaN
        and False for a point that is not finite or falls outside the image of
        :attr:`frame_camera`.
        """
        pts = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 3))
        state = np.zeros(6)
        state[:min(len(camera_pose), 6)] = np.asarray(camera_pose, float)[:6]
        optical, ok = _optical_points(state, pts, BASE_TO_CAMERA_ROTATION)
        uv = np.full((len(pts), 2), np.nan)
        if ok.any():
            proj, valid = self.frame_camera.project(optical[ok])
            uv[ok] = proj
            ok[ok] = valid
        return uv, ok


@njit(cache=True)
def _optical_points(state: np.ndarray, pts: np.ndarray, m: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``(n, 3)`` points seen from ``state`` ``(x, y, yaw, pitch, roll, dz)``, optical frame.

    The base-frame vector ``v`` of each point (turned by the yaw, ``dz`` below its
    height), through the frame's tilt (``R^T v``, :func:`tilt_rotation`) and into the
    optical frame (``M^T``, ``m`` the base-from-optical rotation), and whether the
    point is finite. Compiled: a dozen numpy calls for a few dozen points.
    """
    c, s = math.cos(state[2]), math.sin(state[2])
    cp, sp = math.cos(state[3]), math.sin(state[3])
    cr, sr = math.cos(state[4]), math.sin(state[4])
    tilted = state[3] != 0.0 or state[4] != 0.0 or state[5] != 0.0
    # tilt_rotation(pitch, roll) = R_y(pitch) R_x(roll); a row vector v becomes v R.
    r = np.array([[cp, sp * sr, sp * cr], [0.0, cr, -sr], [-sp, cp * sr, cp * cr]])
    n = pts.shape[0]
    out, finite = np.empty((n, 3)), np.empty(n, np.bool_)
    for i in range(n):
        finite[i] = (math.isfinite(pts[i, 0]) and math.isfinite(pts[i, 1])
                     and math.isfinite(pts[i, 2]))
        dx, dy = pts[i, 0] - state[0], pts[i, 1] - state[1]
        v0, v1, v2 = c * dx + s * dy, -s * dx + c * dy, pts[i, 2]
        if tilted:
            v2 -= state[5]
            v0, v1, v2 = (v0 * r[0, 0] + v1 * r[1, 0] + v2 * r[2, 0],
                          v0 * r[0, 1] + v1 * r[1, 1] + v2 * r[2, 1],
                          v0 * r[0, 2] + v1 * r[1, 2] + v2 * r[2, 2])
        for j in range(3):
            out[i, j] = v0 * m[0, j] + v1 * m[1, j] + v2 * m[2, j]
    return out, finite


def tilt_rotation(pitch: float, roll: float) -> np.ndarray:
    """Return a small extra tilt of the frame, applied to its rays in the base frame.

    A frame tilted by ``(pitch, roll)`` sees the level direction ``v`` along the ray
    ``R^T v``, ``R`` this matrix (:func:`.absolute_pose.refine_absolute` turns measured
    rays by ``R`` into the level base frame).
    """
    cp, sp, cr, sr = math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])  # about y (left)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])  # about x (forward)
    return ry @ rx


def _kd_forest(descriptors: np.ndarray) -> cv2.flann_Index:
    """Build FLANN's randomized kd-trees the same way every time.

    They draw their split dimensions from OpenCV's global generator, so without a fixed
    seed the approximate neighbours (and the poses) of a database depended on what the
    process had drawn before: the same run localized after another gave other figures.
    """
    cv2.setRNGSeed(FLANN_SEED)
    return cv2.flann_Index(descriptors, {'algorithm': _FLANN_KDTREE, 'trees': FLANN_TREES})


def _median_spacing(tree: cKDTree, xy: np.ndarray) -> float:
    if len(xy) < 2:
        return 0.25
    distances, _ = tree.query(xy, k=2)
    return float(np.median(distances[:, 1])) or 0.25
