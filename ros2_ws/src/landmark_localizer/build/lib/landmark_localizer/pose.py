"""The pose from the region's model views (thesis 7.2 to 7.5).

For each model view of the region, the tracked features it shows give point
correspondences (model view pixel, current pixel); the motion from the view to the
current camera is solved by the method the database's camera model picks (7.5.2 for
panoramas, 7.5.1 for pinhole cameras; ``method`` overrides it), and the current
position is the least-squares intersection of the views' translation rays (7.4), using
every view with enough inliers: the thesis's two model views, plus the third where
the two rays are nearly parallel (the robot near the line through the two views). The
camera pose is then carried to ``base_link`` through the camera's mount.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from landmark_localizer.config import LocalizerConfig
from landmark_localizer.index import DatabaseIndex, RegionData
from landmark_localizer.planar_kernels import refine_planar
from landmark_localizer.tilt_refinement import marginal_covariance, refine_tilted
from vbn_common.errors import VbnCommonError
from vbn_common.geometry.frames import (
    BASE_TO_CAMERA_ROTATION,
    compose_poses,
    invert_pose,
    wrap_angle,
)
from vbn_common.geometry.localize import PoseEstimate, position_from_views
from vbn_common.geometry.motion import RelativeMotion, TwoViewConfig
from vbn_common.geometry.two_view import relative_motion

__all__ = ['PoseSolution', 'base_covariance', 'base_pose', 'refine_pose', 'solve_pose']


@dataclass(frozen=True)
class PoseSolution:
    """A pose solve against a region's model views.

    Attributes:
        estimate: The current camera's pose in ``map`` with its covariance.
        inlier_classes: Classes that every view that saw them kept as inliers.
        views_used: Model views used (2 or 3).
        inliers: Correspondences kept, summed over the views.
        residual_px: Largest RMS epipolar error of the views, pixels.
        tilt: ``(pitch, roll, dz)`` of the frame where a refinement on 3-D points found
            them (:func:`~landmark_localizer.points_refinement.refine_on_points`), else None.
        two_view: The camera pose the model views gave (7.4, 7.5) where a refinement on
            3-D points moved it; None where the estimate is that pose itself.
        point_noise: ``(tracked, scene)`` mean squared angular errors (rad^2) of the
            tracked features' points and of the scene points at the refined pose, where
            enough of both joined it (:class:`~.points_refinement.SourceBalance`).
    """

    estimate: PoseEstimate
    inlier_classes: np.ndarray
    views_used: int
    inliers: int
    residual_px: float
    tilt: np.ndarray | None = None
    two_view: np.ndarray | None = None
    point_noise: tuple[float, float] | None = None

    @property
    def two_view_pose(self) -> np.ndarray | None:
        """The two-view camera pose (the seed of any refinement); None without views."""
        if not self.views_used:
            return None
        return self.two_view if self.two_view is not None else self.estimate.pose


#: The frame's tilt and height are taken when they lower the cost to this fraction.
TILT_GAIN = 0.3

#: A planar fit with at least this share of its matches as inliers, at an RMS below
#: :data:`LEVEL_RMS_PX`, is kept without trying the tilt: to lower the cost to
#: :data:`TILT_GAIN` the tilted fit would need an RMS under 0.55 of the planar one,
#: 0.27 px, below the noise of a level camera's points (the room run's planar RMS: 0.32
#: px median, 0.46 px p95; that of a camera 5 cm higher than explored: 0.49 px at the
#: least, 0.85 px median). It saves the tilt's refinement, a millisecond a frame.
LEVEL_SHARE = 0.9
LEVEL_RMS_PX = 0.5


def solve_pose(index: DatabaseIndex, region: RegionData, class_ids: np.ndarray,
               uv: np.ndarray, config: LocalizerConfig, rng: np.random.Generator,
               predicted: np.ndarray | None = None) -> PoseSolution | None:
    """Solve the current camera pose from tracked features against the model views.

    Every view's motion also gives the current camera's heading (the view's yaw plus
    the motion's rotation), and all views see the same camera: a view whose heading
    disagrees with the others' (their circular median; with two views, each other) by
    more than ``max_heading_disagreement_deg`` found a
    wrong motion (few points on one wall can fit a second solution) and is dropped
    before the rays are intersected.

    Args:
        index: The database index (camera model, focal length).
        region: The region whose model views are used.
        class_ids: (t,) classes of the tracked features.
        uv: (t, 2) their pixels in the current image.
        config: ``min_inliers``, ``max_residual_px``, ``method``.
        rng: Random generator of the robust solvers.
        predicted: (3,) the predicted camera pose, if any (tie-breaker of the headings).

    Returns:
        The solution, or None when fewer than two views give a trustworthy motion.
    """
    focal = index.residual_focal
    two_view = TwoViewConfig(threshold_px=max(1.0, 0.75 * config.max_residual_px))
    poses, motions, kept, outliers = [], [], [], set()
    total, worst = 0, 0.0
    for view in region.views:
        rows = np.array([view.position.get(int(c), -1) for c in class_ids])
        have = rows >= 0
        if have.sum() < config.min_inliers:
            continue
        try:
            motion: RelativeMotion = relative_motion(
                view.keypoints[rows[have]], uv[have], index.camera,
                method=config.method or None, config=two_view, rng=rng,
                current_camera=index.frame_camera)
        except VbnCommonError:
            continue
        n_in = int(motion.inliers.sum())
        residual_px = motion.residual * focal
        if n_in < config.min_inliers or not residual_px <= config.max_residual_px:
            continue
        poses.append(view.pose)
        motions.append(motion)
        seen = class_ids[have]
        kept.append(seen[motion.inliers])
        outliers.update(int(c) for c in seen[~motion.inliers])
        total += n_in
        worst = max(worst, residual_px)
    if len(motions) < 2:
        return None
    keep = _consistent_headings(np.array(poses), motions, predicted,
                                math.radians(config.max_heading_disagreement_deg))
    if keep.sum() < 2:
        return None
    for k in np.flatnonzero(~keep):
        outliers.update(int(c) for c in kept[k])
    poses = [p for p, ok in zip(poses, keep, strict=True) if ok]
    motions = [m for m, ok in zip(motions, keep, strict=True) if ok]
    kept = [c for c, ok in zip(kept, keep, strict=True) if ok]
    total = int(sum(int(m.inliers.sum()) for m in motions))
    try:
        estimate = position_from_views(np.array(poses), motions,
                                       min_ray_angle=math.radians(0.5))
    except VbnCommonError:
        return None
    if not estimate.in_front:
        return None
    inliers = np.setdiff1d(np.unique(np.concatenate(kept)), np.fromiter(outliers, np.int64,
                                                                        len(outliers)))
    return PoseSolution(estimate, inliers, len(motions), total, worst)


def _consistent_headings(poses: np.ndarray, motions: list[RelativeMotion],
                         predicted: np.ndarray | None, limit: float) -> np.ndarray:
    """(k,) bool: the views whose implied heading agrees with the consensus.

    Three or more views: within ``limit`` of their circular median. Two views: both
    when they agree with each other, else the one nearer the predicted heading alone
    (which leaves too few views to solve).
    """
    headings = np.array([p[2] + m.theta for p, m in zip(poses, motions, strict=True)])
    if len(headings) >= 3:
        return np.abs(wrap_angle(headings - _circular_median(headings))) <= limit
    if abs(float(wrap_angle(headings[0] - headings[1]))) <= limit:
        return np.ones(2, bool)
    keep = np.zeros(2, bool)
    if predicted is not None:
        keep[int(np.argmin(np.abs(wrap_angle(headings - predicted[2]))))] = True
    return keep


def _circular_median(angles: np.ndarray) -> float:
    """Return the input angle with the least summed absolute deviation from the others."""
    cost = np.abs(wrap_angle(angles[:, None] - angles[None, :])).sum(axis=1)
    return float(angles[int(np.argmin(cost))])


def base_pose(index: DatabaseIndex, camera_pose: np.ndarray) -> np.ndarray:
    """``base_link`` pose in ``map`` from the camera pose, through the camera mount."""
    return compose_poses(camera_pose, invert_pose(index.camera_mount))


@dataclass(frozen=True)
class _Correspondences:
    """Every model view's correspondences stacked, for the joint refinement.

    Attributes:
        view_poses: (V, 3) camera poses of the views.
        view: (n,) the view of each correspondence.
        classes: (n,) its class.
        rays_model: (n, 3) rays in its model view.
        rays_current: (n, 3) rays in the current view.
    """

    view_poses: np.ndarray
    view: np.ndarray
    classes: np.ndarray
    rays_model: np.ndarray
    rays_current: np.ndarray


def _correspondences(index: DatabaseIndex, region: RegionData, class_ids: np.ndarray,
                     uv: np.ndarray, min_points: int) -> _Correspondences | None:
    rays_current = index.frame_camera.unproject(uv)
    poses, view, classes, model, current = [], [], [], [], []
    for v in region.views:
        rows = np.array([v.position.get(int(c), -1) for c in class_ids])
        have = rows >= 0
        if have.sum() < min_points:
            continue
        view.append(np.full(int(have.sum()), len(poses)))
        poses.append(v.pose)
        classes.append(class_ids[have])
        model.append(index.view_rays(v)[rows[have]])
        current.append(rays_current[have])
    if len(poses) < 2:
        return None
    return _Correspondences(np.array(poses), np.concatenate(view), np.concatenate(classes),
                            np.concatenate(model), np.concatenate(current))


def refine_pose(index: DatabaseIndex, region: RegionData, class_ids: np.ndarray,
                uv: np.ndarray, initial: np.ndarray, config: LocalizerConfig,
                iterations: int = 8, level_gate: bool = False) -> PoseSolution | None:
    """Polish the camera pose on the epipolar errors of every model view at once.

    The per-view solve of Section 7.5 followed by the intersection of 7.4 treats each
    view alone; given a starting pose (the prediction while tracking, or the
    intersection after a vote), the pose ``(x, y, yaw)`` itself is the unknown here:
    it fixes each view's rotation and translation direction, and Gauss-Newton with
    Huber weights minimises the Sampson errors of all views' correspondences together.
    Near the horizon the panoramic planar constraint is weak and a second, wrong
    motion can fit a single view's points as well as the true one (measured on the
    room run: 22 of 27 points within 0.1 px at 20 degrees off); starting from the
    prediction picks the right one. The covariance is ``s^2 (J^T W J)^-1`` with the
    weighted residuals' variance ``s^2`` (floored at 0.1 px): large along the line
    through two views when the robot stands on it.

    The frame's own tilt and height are tried (``tilt_prior_deg``) on every call, or with
    ``level_gate`` only where the level fit leaves them something to gain
    (:data:`LEVEL_SHARE`): a tracked frame's seed, which the points' refinement checks
    and finds the tilt of. Not a vote's polish, once a start, where nothing checks it
    (from a vote 7 mm off on a camera 4 cm lower than explored, a level fit within the
    gate converged 66 cm off).

    Returns:
        The solution, or None when fewer than two views have ``min_inliers`` inliers,
        the step diverges, or the residual exceeds ``max_residual_px``.
    """
    focal = index.residual_focal
    data = _correspondences(index, region, class_ids, uv, config.min_inliers)
    if data is None:
        return None
    threshold = 0.75 * config.max_residual_px / focal
    planar = _refine_planar(np.asarray(initial, float), data, threshold, iterations)
    tilt = False
    if config.tilt_prior_deg > 0 and not (level_gate and
                                          _level_enough(planar, threshold, focal)):
        # The frame's pitch, roll and height with the pose (tilt_refinement), taken
        # when it explains the points markedly better than the planar pose: three
        # more unknowns cost a level camera accuracy (the room run: p95 3.0 -> 3.8 cm).
        found = refine_tilted(planar[0] if planar else initial, data.view_poses, data.view,
                              data.rays_model, data.rays_current, threshold, 0.5 / focal,
                              config.tilt_prior_deg, config.height_prior_m)
        if found is not None and (planar is None or _cost(found[1], threshold)
                                  < TILT_GAIN * _cost(planar[1], threshold)):
            (state, r, jac), tilt = found, True
            pose = state[:3].copy()
    if not tilt:
        if planar is None:
            return None
        pose, r, jac = planar
    inlier = np.abs(r) <= 2.0 * threshold
    per_view = np.bincount(data.view[inlier], minlength=len(data.view_poses))
    if int((per_view >= config.min_inliers).sum()) < 2:
        return None
    rms_px = float(np.sqrt(np.mean(r[inlier] ** 2)) * focal)
    if not rms_px <= config.max_residual_px:
        return None
    jac = jac[inlier]
    sigma2 = max(float(np.mean(r[inlier] ** 2)), (0.1 / focal) ** 2)
    if tilt:
        cov = marginal_covariance(jac, sigma2, 0.5 / focal, config.tilt_prior_deg,
                                  config.height_prior_m)
        if cov is None:
            return None
    else:
        try:
            cov = sigma2 * np.linalg.inv(jac.T @ jac)
        except np.linalg.LinAlgError:
            return None
    bad = np.unique(data.classes[~inlier])
    good = np.setdiff1d(np.unique(data.classes[inlier]), bad)
    angle = _ray_angle(pose, list(data.view_poses))
    estimate = PoseEstimate(float(pose[0]), float(pose[1]), float(pose[2]), 0.5 * (cov + cov.T),
                            angle, rms_px / focal, len(data.view_poses), True)
    return PoseSolution(estimate, good, len(data.view_poses), int(inlier.sum()), rms_px)


def _refine_planar(initial: np.ndarray, data: _Correspondences, threshold: float,
                   iterations: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Gauss-Newton with Huber weights on ``(x, y, yaw)``: ``(pose, r, jacobian)``.

    Compiled (:func:`.planar_kernels.refine_planar`): the Sampson errors of
    :func:`vbn_common.geometry.epipolar.planar_sampson`, each view's motion from the pose.
    """
    pose = np.array(initial, float)
    n = len(data.view)
    r, jac = np.empty(n), np.empty((n, 3))
    if not refine_planar(pose, np.ascontiguousarray(data.view_poses, float),
                         np.ascontiguousarray(data.view, np.int64),
                         data.rays_model @ BASE_TO_CAMERA_ROTATION.T,
                         data.rays_current @ BASE_TO_CAMERA_ROTATION.T,
                         threshold, iterations, r, jac):
        return None
    return pose, r, jac


def _level_enough(planar: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
                  threshold: float, focal: float) -> bool:
    """Whether a planar fit leaves the frame's tilt nothing to gain (:data:`LEVEL_SHARE`)."""
    if planar is None:
        return False
    inlier = np.abs(planar[1]) <= 2.0 * threshold
    if inlier.mean() < LEVEL_SHARE:
        return False
    return float(np.sqrt(np.mean(planar[1][inlier] ** 2))) * focal < LEVEL_RMS_PX


def _cost(r: np.ndarray, threshold: float) -> float:
    """Return the truncated quadratic cost (an outlier counts as twice the threshold)."""
    return float(np.sum(np.minimum(np.abs(r), 2.0 * threshold) ** 2))


def _ray_angle(pose: np.ndarray, view_poses: list[np.ndarray]) -> float:
    """Largest angle between the directions from the views to the pose, in [0, pi/2]."""
    d = np.array([pose[:2] - p[:2] for p in view_poses])
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    cosines = np.clip(np.abs(d @ d.T), 0.0, 1.0)
    return float(np.arccos(cosines.min()))


def base_covariance(cov: np.ndarray, camera: np.ndarray, mount: np.ndarray) -> np.ndarray:
    """Covariance of ``camera (+) mount^-1`` from the camera pose's covariance."""
    t = invert_pose(mount)
    c, s = np.cos(camera[2]), np.sin(camera[2])
    jac = np.array([[1.0, 0.0, -s * t[0] - c * t[1]],
                    [0.0, 1.0, c * t[0] - s * t[1]],
                    [0.0, 0.0, 1.0]])
    out = jac @ cov @ jac.T
    return 0.5 * (out + out.T)

