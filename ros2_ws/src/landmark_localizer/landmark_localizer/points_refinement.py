"""A two-view pose checked and polished on 3-D points.

Not in the thesis. The thesis's pose comes from the region's k features in two or three
model views (7.4, 7.5). The tracked features that have a triangulated class point
(``DatabaseIndex.points``) judge that pose (a wrong motion that few points on one wall
fit is refused) and polish it: Gauss-Newton with Huber weights on the angular errors
(:func:`~landmark_localizer.absolute_pose.refine_absolute`), over the planar pose and
the frame's own tilt and height, with the motion model's prediction as a prior. The
scene points measured in the frame (:mod:`.scene_patches`, :mod:`.scene_tracks`) join
the final refinement; they never judge the seed.
"""
from __future__ import annotations

from collections.abc import Callable
import math

import numpy as np

from landmark_localizer.absolute_pose import (
    JUDGE_POINTS,
    _coarse_inliers,
    _spread,
    base_rays,
    refine_absolute,
)
from landmark_localizer.angular_kernels import angular_errors
from landmark_localizer.config import LocalizerConfig
from landmark_localizer.index import DatabaseIndex
from landmark_localizer.pose import PoseSolution
from vbn_common.geometry.frames import wrap_angle
from vbn_common.geometry.localize import PoseEstimate

__all__ = ['BALANCE_POINTS', 'BALANCE_RANGE', 'SceneMeasure', 'SourceBalance', 'motion_prior',
           'point_errors', 'refine_on_points']

#: Measures the scene points from a camera state ``(x, y, yaw, pitch, roll, dz)``:
#: ``(uv, xyz)``.
SceneMeasure = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

#: Least points of each source for a frame to measure their errors.
BALANCE_POINTS = 5
#: The tracked features' weight beside the scene points' stays within this range.
BALANCE_RANGE = (0.2, 5.0)


class SourceBalance:
    """How much a tracked feature's point counts beside a scene point.

    Not in the thesis. Two sources measure a tracked frame's points: the tracked features
    (Lucas-Kanade from frame to frame, re-anchored on a SIFT keypoint a few a frame, so
    they drift between anchors) and the scene points (aligned by their exploration
    patches, which do not drift). How well each measures depends on the camera and the
    scene: at the refined poses of ``room_run`` the tracked features' mean squared error
    is about 1.2 times the scene points', on the pinhole room about 2 times. Weighting
    each source by the inverse of its variance is the least-squares optimum (a variance
    component estimate over two groups); the variances are exponential averages, at
    ``rate`` a frame, of each source's mean squared error at the refined pose of the
    frames where both measured at least :data:`BALANCE_POINTS`. Equal weights at first.
    """

    def __init__(self, rate: float = 0.05) -> None:
        if not 0.0 < rate <= 1.0:
            raise ValueError(f'rate must be in (0, 1], got {rate}')
        self.rate = rate
        self.tracked: float | None = None
        self.scene: float | None = None

    def weight(self) -> float:
        """Return the tracked features' weight beside the scene points' (1 until measured)."""
        if self.tracked is None or self.scene is None or not self.tracked > 0.0:
            return 1.0
        return float(np.clip(self.scene / self.tracked, *BALANCE_RANGE))

    def update(self, noise: tuple[float, float] | None) -> None:
        """Take one frame's ``(tracked, scene)`` mean squared errors (None: nothing)."""
        if noise is None or not all(np.isfinite(noise)):
            return
        if self.tracked is None or self.scene is None:
            self.tracked, self.scene = float(noise[0]), float(noise[1])
            return
        self.tracked += self.rate * (float(noise[0]) - self.tracked)
        self.scene += self.rate * (float(noise[1]) - self.scene)


def motion_prior(predicted: np.ndarray, last_pose: np.ndarray | None,
                 last: PoseSolution | None, config: LocalizerConfig
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """Return the motion model's prior on the tracked camera pose, or None.

    Its spread is the configured one, or a fifth of the predicted motion where that is
    larger (at 2 Hz a frame is 20 cm on, and a wheel slipping by 20 % or a turn the
    constant velocity did not foresee moves the prediction by centimetres), widened by
    the last pose's own covariance (``last``), which the prediction carries on (a
    Kalman prediction; None when that covariance is not finite). Without it, a pose that
    narrow points and the prior had held 16 cm off went on claiming the prior's 2 cm,
    and only crept back at 2 cm a frame (a changed room).
    """
    if config.motion_prior_m <= 0 or config.motion_prior_deg <= 0:
        return None
    moved = np.zeros(3) if last_pose is None else \
        np.abs(np.asarray(predicted[:3], float) - np.asarray(last_pose[:3], float))
    moved[2] = abs(float(wrap_angle(moved[2])))   # a turn across +-pi is small
    std = np.array([max(config.motion_prior_m, 0.2 * math.hypot(moved[0], moved[1]))] * 2
                   + [max(math.radians(config.motion_prior_deg), 0.2 * moved[2])])
    if last is not None:
        var = np.diag(np.asarray(last.estimate.covariance, float))[:3]
        if not np.all(np.isfinite(var)):
            return None   # the last pose's doubt unknown: no prior rather than a tight one
        std = np.sqrt(std ** 2 + np.maximum(var, 0.0))
    return np.asarray(predicted[:3], float), std


def point_errors(index: DatabaseIndex, state: np.ndarray, uv: np.ndarray, xyz: np.ndarray
                 ) -> np.ndarray:
    """(n,) angles between pixels' rays and the directions to their 3-D points.

    ``state``: a planar camera pose ``(x, y, yaw)``, or ``(x, y, yaw, pitch, roll, dz)``
    with the frame's own tilt and height offset (:func:`refine_absolute`).
    """
    state = np.concatenate([np.asarray(state, float), np.zeros(3)])[:6] \
        if len(state) == 3 else np.asarray(state, float)
    return _state_errors(state, base_rays(index.frame_camera.unproject(np.asarray(uv, float))),
                         np.asarray(xyz, float))


def _state_errors(state: np.ndarray, rays: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """(n,) angular errors of rays (level base frame) at a ``(6,)`` state, radians."""
    return angular_errors(np.asarray(state, float), np.ascontiguousarray(rays, float),
                          np.ascontiguousarray(xyz, float))


#: Mahalanobis distance (3 degrees of freedom, the motion prior's own spread) of the
#: refined pose from the motion model's prediction beyond which the prior is dropped:
#: 3 sigma (chi-square 14.16 at 99.73 %).
PRIOR_GATE = math.sqrt(14.16)


def _prior_distance(state: np.ndarray, motion_prior: tuple[np.ndarray, np.ndarray]) -> float:
    """Mahalanobis distance of ``state``'s ``(x, y, yaw)`` from the motion prior."""
    centre, std = (np.asarray(a, float) for a in motion_prior)
    offset = np.asarray(state[:3], float) - centre
    offset[2] = float(wrap_angle(offset[2]))
    return float(np.linalg.norm(offset / np.maximum(std, 1e-12)))


def _scene_inliers(state: np.ndarray, rays: np.ndarray, xyz: np.ndarray, threshold: float
                   ) -> np.ndarray:
    """(n,) bool: scene measurements (rays in the level base frame) the state explains."""
    if not len(rays):
        return np.zeros(0, bool)
    return _state_errors(state, rays, xyz) <= threshold


def refine_on_points(index: DatabaseIndex, class_ids: np.ndarray, uv: np.ndarray,
                     seed: PoseSolution, config: LocalizerConfig, strict: bool = False,
                     motion_prior: tuple[np.ndarray, np.ndarray] | None = None,
                     scene: tuple[np.ndarray, np.ndarray] | SceneMeasure | None = None,
                     tracked_weight: float = 1.0) -> PoseSolution | None:
    """Check and polish a pose solve on the tracked features' class points.

    The two-view pose (7.4, 7.5) seeds a robust refinement on the angular errors of the
    tracked features that have a triangulated point; the seed's inlier classes are
    kept for the tracks. With fewer than :data:`JUDGE_POINTS` such features the seed is
    returned as it is (nothing to judge it by); when fewer than half of them lie within
    twice ``absolute_threshold_px`` of where the seed puts them, the seed found a wrong
    motion (few points on one wall can fit a second one) and None is returned; the seed
    is also returned when the polished pose keeps fewer than ``min_inliers``, or when
    they span less than ``absolute_min_spread_deg`` and no ``motion_prior`` holds the
    range they leave free. When the polished pose lies more than :data:`PRIOR_GATE` of
    the prior's spreads from the prediction, the points are refined again without it
    (which returns the seed where they cannot stand alone).
    Thresholds are in :attr:`DatabaseIndex.residual_focal` pixels. ``strict`` (a vote,
    which no prediction checks): None as well when there are too few points to judge
    by. ``scene``: ``(uv, xyz)`` of scene points measured in the frame
    (:mod:`.scene_tracks`), or a function measuring them from a camera state
    (:data:`SceneMeasure`), which is then asked at the state the tracked features'
    points give with the motion prior, tilt and height included (not at the seed's: a
    two-view pose 8 cm and 2 degrees off predicted the points beyond their search, and a
    third of them were measured), and again at their state without it where the gate
    drops the prior; it is not asked where the seed is returned before that refinement
    (the scene tracker then neither prunes nor births that frame). Those within
    ``absolute_threshold_px`` of that pose join its final refinement (they never judge
    the seed). The refinement's Huber threshold is ``absolute_huber_px``. ``tracked_weight``: the
    weight of a tracked feature's point beside a scene point's in that refinement
    (:class:`SourceBalance`); the solution reports both sources' errors there.
    """
    points = index.points[class_ids]
    have = np.all(np.isfinite(points), axis=1)
    if have.sum() < JUDGE_POINTS:
        return None if strict else seed
    rays = base_rays(index.frame_camera.unproject(np.asarray(uv, float)[have]))
    points = points[have]
    focal = index.residual_focal
    threshold = config.absolute_threshold_px / focal
    start = np.asarray(seed.estimate.pose, float)
    tilt_prior = math.radians(config.tilt_prior_deg)
    inliers = _coarse_inliers(start[None], rays, points, 2.0 * threshold, tilt_prior,
                              config.height_prior_m)[0]
    if inliers.sum() < 0.5 * len(rays):
        return None
    if inliers.sum() < config.min_inliers:
        return seed
    args = (config.absolute_huber_px / focal, 0.5 / focal, tilt_prior, config.height_prior_m,
            8, motion_prior)
    found = refine_absolute(start, rays[inliers], points[inliers], *args)
    if found is None:
        return seed
    state, _ = found
    first, inliers = inliers, _state_errors(state, rays, points) <= threshold
    rays, points = rays[inliers], points[inliers]
    measure = scene if callable(scene) else None
    if measure is not None:
        scene = measure(state.copy())
    scene_rays = scene_xyz = np.zeros((0, 3))
    if scene is not None and len(scene[0]):
        scene_rays = base_rays(index.frame_camera.unproject(np.asarray(scene[0], float)))
        scene_xyz = np.asarray(scene[1], float)
    near = _scene_inliers(state, scene_rays, scene_xyz, threshold)
    all_rays = np.concatenate([rays, scene_rays[near]])
    all_points = np.concatenate([points, scene_xyz[near]])
    # Points in a narrow cone fix their bearing, not the range: alone they cannot judge
    # the pose, but with the motion prior they can (the prior holds what they leave
    # free). Keeping the seed there kept a two-view pose 20 cm off that the points and
    # the prior together put within 1 cm (a 1280 x 960 run, 17 points within 7 deg).
    # The spread of the class points alone: the scene points never judge the seed.
    narrow = _spread(rays) < math.radians(config.absolute_min_spread_deg)
    if inliers.sum() < config.min_inliers or (narrow and motion_prior is None):
        return seed
    if near.any() or not np.array_equal(first, inliers):  # else: refined on them already
        for attempt in range(2):  # scene points the refined pose brings near then join
            weights = None if tracked_weight == 1.0 or not near.any() else \
                np.r_[np.full(len(rays), tracked_weight), np.ones(int(near.sum()))]
            found = refine_absolute(state, all_rays, all_points, *args,
                                    point_weights=weights)
            if found is None:
                return seed
            state = found[0]
            again = _scene_inliers(state, scene_rays, scene_xyz, threshold)
            if attempt == 1 or np.array_equal(again, near):
                break   # the pose and its covariance are of the points in all_rays
            near = again
            all_rays = np.concatenate([rays, scene_rays[near]])
            all_points = np.concatenate([points, scene_xyz[near]])
    state, cov = found
    if motion_prior is not None and not narrow and \
            _prior_distance(state, motion_prior) > PRIOR_GATE:
        # The points disagree with the prediction (an odometry gap, a slip the prior's
        # spread does not cover): they decide alone. Pulled by a prediction 10 cm off,
        # a 2 Hz pose settled 22 cm off claiming 1.8 cm, where the points alone gave
        # 0.3 cm (room, wheels slipping and odometry dropping out).
        # Alone they may not stand (too narrow or too few once re-selected): the seed.
        alone = refine_on_points(index, class_ids, uv, seed, config, strict, None,
                                 scene if measure is None else measure, tracked_weight)
        return alone if alone is not None else seed
    est = seed.estimate
    estimate = PoseEstimate(float(state[0]), float(state[1]), float(state[2]),
                            0.5 * (cov + cov.T), est.ray_angle, est.residual, est.n_views,
                            est.in_front)
    noise = None
    if len(rays) >= BALANCE_POINTS and len(all_rays) - len(rays) >= BALANCE_POINTS:
        errors = _state_errors(state, all_rays, all_points) ** 2
        noise = (float(errors[:len(rays)].mean()), float(errors[len(rays):].mean()))
    return PoseSolution(estimate, seed.inlier_classes, seed.views_used, seed.inliers,
                        seed.residual_px, state[3:].copy(), seed.two_view_pose, noise)
