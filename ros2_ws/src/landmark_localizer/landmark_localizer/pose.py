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
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.geometry.frames import compose_poses, invert_pose
from visibility_builder.geometry.localize import PoseEstimate, position_from_views
from visibility_builder.geometry.two_view import RelativeMotion, TwoViewConfig, relative_motion

__all__ = ['PoseSolution', 'base_pose', 'solve_pose']


@dataclass(frozen=True)
class PoseSolution:
    """A pose solve against a region's model views.

    Attributes:
        estimate: The current camera's pose in ``map`` with its covariance.
        inlier_classes: Classes that every view that saw them kept as inliers.
        views_used: Model views used (2 or 3).
        inliers: Correspondences kept, summed over the views.
        residual_px: Largest RMS epipolar error of the views, pixels.
    """

    estimate: PoseEstimate
    inlier_classes: np.ndarray
    views_used: int
    inliers: int
    residual_px: float


def _focal(index: DatabaseIndex) -> float:
    return float(index.database.info.camera.K[0, 0])


def solve_pose(index: DatabaseIndex, region: RegionData, class_ids: np.ndarray,
               uv: np.ndarray, config: LocalizerConfig, rng: np.random.Generator,
               ) -> PoseSolution | None:
    """Solve the current camera pose from tracked features against the model views.

    Args:
        index: The database index (camera model, focal length).
        region: The region whose model views are used.
        class_ids: (t,) classes of the tracked features.
        uv: (t, 2) their pixels in the current image.
        config: ``min_inliers``, ``max_residual_px``, ``method``.
        rng: Random generator of the robust solvers.

    Returns:
        The solution, or None when fewer than two views give a trustworthy motion.
    """
    focal = _focal(index)
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
                method=config.method or None, config=two_view, rng=rng)
        except VisibilityBuilderError:
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
    try:
        estimate = position_from_views(np.array(poses), motions,
                                       min_ray_angle=math.radians(0.5))
    except VisibilityBuilderError:
        return None
    if not estimate.in_front:
        return None
    inliers = np.setdiff1d(np.unique(np.concatenate(kept)), np.fromiter(outliers, np.int64,
                                                                         len(outliers)))
    return PoseSolution(estimate, inliers, len(motions), total, worst)


def base_pose(index: DatabaseIndex, camera_pose: np.ndarray) -> np.ndarray:
    """``base_link`` pose in ``map`` from the camera pose, through the camera mount."""
    return compose_poses(camera_pose, invert_pose(index.camera_mount))
