"""The structure-based peer: every frame's SIFT matched to a 3-D map, posed by pycolmap.

The localizer a user of hloc or pycolmap would put beside ours, against the
map of :mod:`.peer_map` built from the same exploration:

- per frame, SIFT on the whole image (the landmark database's settings);
- ``global``: each keypoint's two nearest map points by descriptor (FLANN randomised
  KD-trees over every observation's descriptor, the second nearest belonging to
  another point) with Lowe's ratio test;
- ``tracking``: the pose predicted from the last one and the odometry since; a keypoint
  is matched only to the points that prediction projects within ``search_radius_px``
  of it, by each point's most central descriptor (the ratio test among those); a
  frame without a prediction, or whose matches give no pose, falls back to the global
  query;
- the pose by ``pycolmap.estimate_and_refine_generalized_absolute_pose`` (LO-RANSAC on
  P3P, then a robust non-linear refinement). Rays go through the camera model of the
  frame (any lens, the cylindrical panorama included) onto the six faces of a virtual
  cube of pinhole cameras sharing one centre, so one solver serves every camera;
  a face's focal length is the camera's pixels per radian, so its thresholds are
  pixels of the real image.

The 6-DoF pose is reported as the planar pose of ``base_link`` (the camera's position,
the azimuth of its optical axis, the mount), the way ours is judged.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import time

import cv2
import numpy as np
from scipy.spatial import cKDTree

from landmark_localizer.errors import LocalizerError
from landmark_localizer.localizer import LOST, TRACKING, Estimate, Frame
from vbn_bench.localization.peer_map import PeerMap
from vbn_common.features import extract_features
from vbn_common.geometry.camera import CameraModel, pixels_per_radian
from vbn_common.geometry.frames import (
    BASE_TO_CAMERA_ROTATION,
    compose_poses,
    invert_pose,
    wrap_angle,
)

__all__ = ['PEER_MODES', 'PeerConfig', 'PeerLocalizer', 'cube_faces']

PEER_MODES = ('global', 'tracking')
_CHUNK = 20000  # descriptor pairs compared at once

#: face_from_camera rotations: the six axis directions of the optical frame.
_FACES = np.array([
    np.eye(3),                                           # +z
    [[-1.0, 0, 0], [0, 1, 0], [0, 0, -1]],               # -z
    [[0.0, 0, -1], [0, 1, 0], [1, 0, 0]],                # +x
    [[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]],                # -x
    [[1.0, 0, 0], [0, 0, -1], [0, 1, 0]],                # +y
    [[1.0, 0, 0], [0, 0, 1], [0, -1, 0]],                # -y
])


def cube_faces(rays: np.ndarray, focal: float) -> tuple[np.ndarray, np.ndarray]:
    """Put rays onto the virtual cube: ``(face (n,), pixel (n, 2))`` on a ``2f x 2f`` face."""
    rays = np.asarray(rays, float)
    along = np.einsum('fj,nj->nf', _FACES[:, 2], rays)           # depth along each axis
    face = np.argmax(along, axis=1)
    local = np.einsum('nij,nj->ni', _FACES[face], rays)
    return face, focal * local[:, :2] / local[:, 2:3] + focal


@dataclass(frozen=True)
class PeerConfig:
    """How the peer matches and solves.

    Attributes:
        mode: ``global`` or ``tracking`` (module docstring).
        descriptors: ``all`` (every observation's) or ``one`` per point (compact map).
        ratio: Lowe's ratio test.
        search_radius_px: Tracking: a keypoint's candidates lie within this many pixels
            of where the predicted pose projects them.
        max_error_px: RANSAC's inlier threshold.
        min_inliers: Least inliers of an accepted pose.
        trees: FLANN randomised KD-trees.
        checks: FLANN leaves visited per query.
        seed: RANSAC's random seed.
    """

    mode: str = 'global'
    descriptors: str = 'all'
    ratio: float = 0.8
    search_radius_px: float = 15.0
    max_error_px: float = 4.0
    min_inliers: int = 12
    trees: int = 4
    checks: int = 64
    seed: int = 0

    def __post_init__(self) -> None:
        if self.mode not in PEER_MODES:
            raise LocalizerError(f'peer mode must be one of {PEER_MODES}, got {self.mode!r}')
        if self.descriptors not in ('all', 'one'):
            raise LocalizerError(f"peer descriptors must be 'all' or 'one', got "
                                 f'{self.descriptors!r}')


class PeerLocalizer:
    """Localizes every frame against the peer's map (module docstring).

    Same ``step(frame) -> Estimate`` interface as :class:`~.localizer.Localizer`;
    ``region`` is 0 with a pose and -1 without (there are no regions).

    Args:
        peer_map: The map.
        camera: The run frames' camera model (levelled by the run's mount).
        config: Settings.
    """

    def __init__(self, peer_map: PeerMap, camera: CameraModel,
                 config: PeerConfig = PeerConfig()) -> None:
        import pycolmap

        self._pycolmap = pycolmap
        self.map = peer_map
        self.camera = camera
        self.config = config
        if not len(peer_map.points) or not len(peer_map.descriptors):
            raise LocalizerError('the peer map holds no points (FLANN cannot index none)')
        self.detector = peer_map.sift.create()
        if config.descriptors == 'one':
            rows = peer_map.representative
            self.descriptors = peer_map.descriptors[rows].astype(np.float32)
            self.point_of = np.arange(len(rows), dtype=np.int64)
        else:
            self.descriptors = peer_map.descriptors.astype(np.float32)
            self.point_of = peer_map.point_of.astype(np.int64)
        start = time.perf_counter()
        self._flann = cv2.flann_Index(self.descriptors, {'algorithm': 1,
                                                          'trees': config.trees})
        self.index_seconds = time.perf_counter() - start
        self._central = peer_map.descriptors[peer_map.representative].astype(np.float32)
        self.focal = pixels_per_radian(camera)
        size = int(math.ceil(2 * self.focal))
        self._cameras = [pycolmap.Camera(model='SIMPLE_PINHOLE', width=size, height=size,
                                         params=[self.focal, self.focal, self.focal])
                         for _ in range(len(_FACES))]
        self._cams_from_rig = [pycolmap.Rigid3d(pycolmap.Rotation3d(r), np.zeros(3))
                               for r in _FACES]
        self._ransac = pycolmap.RANSACOptions(max_error=config.max_error_px,
                                              random_seed=config.seed)
        self._last: tuple[np.ndarray, np.ndarray | None] | None = None  # base pose, odom
        self.mount = np.asarray(peer_map.camera_mount, float)

    def step(self, frame: Frame) -> Estimate:
        """Localize one frame."""
        start = time.perf_counter()
        features = extract_features(np.asarray(frame.image), self.map.sift, self.detector)
        camera = base = None
        used = 0
        if len(features) >= self.config.min_inliers:
            rays = self.camera.unproject(features.keypoints.astype(float))
            predicted = self._predicted(frame)
            solved = None
            if predicted is not None:
                solved = self._solve(rays, *self._match_near(rays, features.descriptors,
                                                             predicted))
            if solved is None:
                solved = self._solve(rays, *self._match_global(features.descriptors))
            if solved is not None:
                camera, used = solved
                base = compose_poses(camera, invert_pose(self.mount))
        self._last = (base, frame.odom) if base is not None else None
        state = TRACKING if base is not None else LOST
        return Estimate(frame.stamp_ns, state, 0 if base is not None else -1, base, None,
                        camera, used, '', time.perf_counter() - start)

    def _predicted(self, frame: Frame) -> np.ndarray | None:
        """Return the camera pose the last pose and the odometry predict (tracking only)."""
        if self.config.mode != 'tracking' or self._last is None:
            return None
        base, odom = self._last
        if odom is not None and frame.odom is not None:
            base = compose_poses(base, compose_poses(invert_pose(odom), frame.odom))
        return compose_poses(base, self.mount)

    def _match_global(self, descriptors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, points): ratio-tested nearest points of the keypoints' descriptors."""
        k = min(2 if self.config.descriptors == 'one' else 4, len(self.descriptors))
        idx, dist = self._flann.knnSearch(descriptors.astype(np.float32), k,
                                          params={'checks': self.config.checks})
        idx = idx.astype(np.int64)
        dist = np.sqrt(np.maximum(dist, 0.0))
        point = np.where(idx >= 0, self.point_of[np.maximum(idx, 0)], -1)
        other = point != point[:, :1]                 # the nearest of another point
        has = other.any(axis=1)
        second = np.where(has, dist[np.arange(len(dist)), np.argmax(other, axis=1)], np.inf)
        ok = (point[:, 0] >= 0) & (dist[:, 0] < self.config.ratio * second)
        rows = np.flatnonzero(ok)
        return rows, point[rows, 0]

    def _match_near(self, rays: np.ndarray, descriptors: np.ndarray, camera_pose: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
        """(rows, points): each keypoint against the points projected near it."""
        uv_points, visible = self._project(camera_pose)
        if visible.sum() < self.config.min_inliers:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        ids = np.flatnonzero(visible)
        uv_keys = self.camera.project(rays)[0]
        pairs = cKDTree(uv_keys).sparse_distance_matrix(
            cKDTree(uv_points[ids]), self.config.search_radius_px, output_type='ndarray')
        if len(pairs) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        key, point = pairs['i'].astype(np.int64), ids[pairs['j']]
        # Against each candidate's most central descriptor (all of them would multiply
        # the pairs by the observations per point).
        dist = np.empty(len(key))
        query = descriptors.astype(np.float32)
        for lo in range(0, len(key), _CHUNK):
            a = query[key[lo:lo + _CHUNK]]
            b = self._central[point[lo:lo + _CHUNK]]
            dist[lo:lo + _CHUNK] = np.einsum('ij,ij->i', a - b, a - b)
        dist = np.sqrt(dist)
        order = np.lexsort((dist, key))
        key, point, dist = key[order], point[order], dist[order]
        head = np.concatenate([[True], np.diff(key) != 0])
        starts = np.flatnonzero(head)
        ends = np.r_[starts[1:], len(key)]
        second = np.where(ends - starts > 1, dist[np.minimum(starts + 1, len(dist) - 1)],
                          np.inf)
        ok = dist[starts] < self.config.ratio * second
        return key[starts[ok]], point[starts[ok]]

    def _project(self, camera_pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of every map point in a camera at the planar pose, and which are seen."""
        x, y, yaw = camera_pose
        c, s = math.cos(yaw), math.sin(yaw)
        world_from_optical = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ \
            BASE_TO_CAMERA_ROTATION
        optical = (self.map.points - np.array([x, y, 0.0])) @ world_from_optical
        return self.camera.project(optical)

    def _solve(self, rays: np.ndarray, rows: np.ndarray, points: np.ndarray
               ) -> tuple[np.ndarray, int] | None:
        """Return the planar camera pose from 2D-3D matches and its inliers, or None."""
        if len(rows) < self.config.min_inliers:
            return None
        face, pixels = cube_faces(rays[rows], self.focal)
        found = self._pycolmap.estimate_and_refine_generalized_absolute_pose(
            pixels, self.map.points[points], face.tolist(), self._cams_from_rig,
            self._cameras, estimation_options=self._ransac)
        if found is None or int(found['num_inliers']) < self.config.min_inliers:
            return None
        rig_from_world = found['rig_from_world']
        rotation = rig_from_world.rotation.matrix()
        centre = -rotation.T @ rig_from_world.translation
        heading = rotation.T @ BASE_TO_CAMERA_ROTATION.T   # world_from_optical @ M^T
        yaw = math.atan2(heading[1, 0], heading[0, 0])
        return np.array([centre[0], centre[1], float(wrap_angle(yaw))]), \
            int(found['num_inliers'])

