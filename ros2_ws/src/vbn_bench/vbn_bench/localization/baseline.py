"""The baseline the thesis argues against: every frame against the full feature database.

The thesis (Chapters 1 and 3) argues for a database of a few landmark features per
region, tracked while the robot stays in the region, against the obvious alternative:
keep every SIFT feature of every exploration image with its image's pose, and match
each query image against all of them. This module is that alternative, for the
comparison in ``vbn bench-localize``:

- :func:`build_full_database`: every SIFT feature (keypoint and descriptor) of every
  image of the exploration bag, with the image's camera pose; its size is the bytes
  of all descriptors and keypoints;
- :class:`FullDatabaseLocalizer`: per frame, SIFT, a FLANN (randomised KD-trees)
  2-nearest-neighbour search of every query feature in the whole database with
  Lowe's ratio test, the exploration images with most matches as candidates, each
  verified by the two-view solve, and the pose from the two images with most
  verified matches by the same solve as ours
  (:func:`~vbn_common.geometry.two_view.relative_motion` and
  :func:`~vbn_common.geometry.localize.position_from_views`, as
  :mod:`landmark_localizer.pose` uses them). It has no state: every frame is a
  global localization.

FLANN rather than exhaustive matching keeps the baseline's latency as low as an
honest implementation would have it (exhaustive matching is slower still).
"""
from __future__ import annotations

from dataclasses import dataclass
import logging
import math
import os
from pathlib import Path
import time

import cv2
import numpy as np

from landmark_localizer.localizer import LOST, TRACKING, Estimate, Frame
from vbn_common.errors import VbnCommonError
from vbn_common.features import SiftConfig, extract_features, extract_many
from vbn_common.geometry.camera import CameraModel, camera_from_info, pixels_per_radian
from vbn_common.geometry.frames import compose_poses, invert_pose
from vbn_common.geometry.localize import position_from_views
from vbn_common.geometry.motion import RelativeMotion, TwoViewConfig
from vbn_common.geometry.two_view import relative_motion

__all__ = ['BaselineConfig', 'FullDatabaseLocalizer', 'FullFeatureDatabase',
           'build_full_database', 'load_full_database']

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class FullFeatureDatabase:
    """Every SIFT feature of every exploration image, with the image's pose.

    Attributes:
        view_poses: (v, 3) camera poses ``(x, y, heading)`` in ``map``.
        keypoints: (n, 2) float32 pixels of every feature.
        descriptors: (n, 128) uint8 SIFT descriptors.
        view_of: (n,) int32 image of each feature.
        camera_info: ``(width, height, distortion_model, d, k)`` of the camera.
        camera_mount: (3,) planar pose of the camera on ``base_link``.
        sift: SIFT settings used.
    """

    view_poses: np.ndarray
    keypoints: np.ndarray
    descriptors: np.ndarray
    view_of: np.ndarray
    camera_info: tuple
    camera_mount: np.ndarray
    sift: SiftConfig

    @property
    def nbytes(self) -> int:
        """Bytes of all descriptors (uint8) and keypoints (two float32 each)."""
        return int(self.descriptors.nbytes + self.keypoints.nbytes)

    def camera(self) -> CameraModel:
        """Return the camera model."""
        width, height, model, d, k = self.camera_info
        info = _Info(int(width), int(height), str(model), np.asarray(d, float),
                     np.asarray(k, float))
        return camera_from_info(info)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write it as one ``.npz`` file (a cache for repeated benchmarks)."""
        width, height, model, d, k = self.camera_info
        np.savez(path, view_poses=self.view_poses, keypoints=self.keypoints,
                 descriptors=self.descriptors, view_of=self.view_of,
                 camera=np.array([width, height], np.int64), model=np.array(model),
                 d=np.asarray(d, float), k=np.asarray(k, float),
                 camera_mount=self.camera_mount,
                 sift=np.array([self.sift.n_features, self.sift.n_octave_layers,
                                self.sift.contrast_threshold, self.sift.edge_threshold,
                                self.sift.sigma], float))


@dataclass(frozen=True)
class _Info:
    width: int
    height: int
    distortion_model: str
    d: np.ndarray
    k: np.ndarray


def load_full_database(path: str | os.PathLike[str]) -> FullFeatureDatabase:
    """Read a database written by :meth:`FullFeatureDatabase.save`."""
    with np.load(path) as data:
        s = data['sift']
        sift = SiftConfig(n_features=int(s[0]), n_octave_layers=int(s[1]),
                          contrast_threshold=float(s[2]), edge_threshold=float(s[3]),
                          sigma=float(s[4]))
        width, height = (int(v) for v in data['camera'])
        return FullFeatureDatabase(
            data['view_poses'], data['keypoints'], data['descriptors'], data['view_of'],
            (width, height, str(data['model']), data['d'], data['k']),
            data['camera_mount'], sift)


def build_full_database(bag: str | os.PathLike[str], sift: SiftConfig | None = None,
                        workers: int | None = None, cache: str | os.PathLike[str] | None = None
                        ) -> FullFeatureDatabase:
    """Extract every SIFT feature of every image of an exploration bag.

    Args:
        bag: The exploration bag (images with poses, as ``vbn build`` reads it).
        sift: SIFT settings (use the landmark database's, for a fair comparison;
            default :class:`SiftConfig`).
        workers: Processes for SIFT (default every core).
        cache: An ``.npz`` file: read when it exists with the same SIFT settings, else
            written after building.

    Returns:
        The full feature database.

    Raises:
        LocalizerError: The bag cannot be read.
    """
    sift = sift or SiftConfig()
    if cache is not None and Path(cache).is_file():
        cached = load_full_database(cache)
        if cached.sift == sift:
            _LOG.info('full feature database from %s', cache)
            return cached
        _LOG.info('%s holds other SIFT settings: extracting again', cache)
    from vbn_common.exploration import read_exploration

    exploration = read_exploration(bag)
    start = time.perf_counter()
    features = extract_many([f.image for f in exploration.frames], sift, workers)
    keypoints, descriptors, view_of, poses = [], [], [], []
    for frame, found in zip(exploration.frames, features, strict=True):
        if isinstance(found, str):
            _LOG.warning('skipped an exploration image: %s', found)
            continue
        view_of.append(np.full(len(found), len(poses), np.int32))
        poses.append(frame.camera_pose)
        keypoints.append(found.keypoints.astype(np.float32))
        descriptors.append(found.descriptors)
    first = exploration.frames[0]
    mount = compose_poses(invert_pose(np.asarray(first.base_pose, float)),
                          np.asarray(first.camera_pose, float))
    info = exploration.camera_info
    database = FullFeatureDatabase(
        np.asarray(poses, float).reshape(-1, 3), np.concatenate(keypoints),
        np.concatenate(descriptors), np.concatenate(view_of),
        (info.width, info.height, info.distortion_model, info.d, info.k), mount, sift)
    _LOG.info('full feature database: %d images, %d features, %.1f MB in %.1f s',
              len(poses), len(database.view_of), database.nbytes / 1e6,
              time.perf_counter() - start)
    if cache is not None:
        database.save(cache)
    return database


@dataclass(frozen=True)
class BaselineConfig:
    """How the baseline matches and solves.

    Attributes:
        ratio: Lowe's ratio test of a match.
        candidates: Exploration images (most matches first) verified by the two-view solve.
        min_inliers: Least verified matches of a model view.
        max_residual_px: Largest RMS epipolar error of a model view's solve.
        min_ray_angle_deg: Least angle between the two views' rays to the position.
        trees: FLANN randomised KD-trees.
        checks: FLANN leaves visited per query.
        seed: Random generator of the robust solver.
    """

    ratio: float = 0.8
    candidates: int = 6
    min_inliers: int = 8
    max_residual_px: float = 2.0
    min_ray_angle_deg: float = 0.5
    trees: int = 4
    checks: int = 32
    seed: int = 0


class FullDatabaseLocalizer:
    """Localizes every frame by matching it against the full feature database.

    Same ``step(frame) -> Estimate`` interface as :class:`~.localizer.Localizer`;
    ``region`` is 0 when a pose is found and -1 otherwise (there are no regions).

    Args:
        database: The full feature database.
        config: Settings.
    """

    def __init__(self, database: FullFeatureDatabase,
                 config: BaselineConfig = BaselineConfig()) -> None:
        self.database = database
        self.config = config
        self.camera = database.camera()
        self.detector = database.sift.create()
        self.rng = np.random.default_rng(config.seed)
        start = time.perf_counter()
        self.matcher = cv2.FlannBasedMatcher(
            {'algorithm': 1, 'trees': config.trees},  # FLANN_INDEX_KDTREE
            {'checks': config.checks})
        self.matcher.add([database.descriptors.astype(np.float32)])
        self.matcher.train()
        self.index_seconds = time.perf_counter() - start
        self.two_view = TwoViewConfig(threshold_px=max(1.0, 0.75 * config.max_residual_px))

    def step(self, frame: Frame) -> Estimate:
        """Localize one frame from scratch."""
        start = time.perf_counter()
        pose = cov = camera = None
        features = extract_features(np.asarray(frame.image), self.database.sift,
                                    self.detector)
        used = 0
        if len(features) >= self.config.min_inliers:
            solved = self._solve(features.keypoints.astype(np.float64),
                                 features.descriptors.astype(np.float32))
            if solved is not None:
                camera, cov, used = solved
                pose = compose_poses(camera, invert_pose(self.database.camera_mount))
        state = TRACKING if pose is not None else LOST
        return Estimate(frame.stamp_ns, state, 0 if pose is not None else -1, pose, cov,
                        camera, used, '', time.perf_counter() - start)

    def _solve(self, query_uv: np.ndarray, query_desc: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, int] | None:
        config = self.config
        pairs = self.matcher.knnMatch(query_desc, k=2)
        rows, train = [], []
        for m in pairs:
            if len(m) == 2 and m[0].distance < config.ratio * m[1].distance:
                rows.append(m[0].queryIdx)
                train.append(m[0].trainIdx)
        if len(rows) < config.min_inliers:
            return None
        rows_a, train_a = np.asarray(rows), np.asarray(train)
        views = self.database.view_of[train_a]
        counts = np.bincount(views)
        order = np.argsort(-counts, kind='stable')[:config.candidates]
        solved: list[tuple[int, int, RelativeMotion]] = []
        focal = pixels_per_radian(self.camera)
        for view in order:
            if counts[view] < config.min_inliers:
                break
            pick = views == view
            try:
                motion = relative_motion(self.database.keypoints[train_a[pick]].astype(float),
                                         query_uv[rows_a[pick]], self.camera,
                                         config=self.two_view, rng=self.rng)
            except VbnCommonError:
                continue
            n_in = int(motion.inliers.sum())
            if n_in >= config.min_inliers and motion.residual * focal <= config.max_residual_px:
                solved.append((n_in, int(view), motion))
        solved.sort(key=lambda s: -s[0])
        min_angle = math.radians(config.min_ray_angle_deg)
        for i in range(len(solved)):
            for j in range(i + 1, len(solved)):
                (n_a, a, m_a), (n_b, b, m_b) = solved[i], solved[j]
                try:
                    est = position_from_views(self.database.view_poses[[a, b]], [m_a, m_b],
                                              min_ray_angle=min_angle)
                except VbnCommonError:
                    continue
                if est.in_front and np.all(np.isfinite(est.pose)):
                    return est.pose, est.covariance, n_a + n_b
        return None


