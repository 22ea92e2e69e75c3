"""Synthetic correspondences with known answers for the two-view pose solvers.

Scene points lie on the walls of a 6 m x 3 m room (like the ``room`` scene) with a
pillar, between the floor and 2.5 m; cameras are 1.2 m above the floor. Points are
projected with the project's camera models, so the tests exercise the same pixel
conventions as the bags. Randomness comes from an explicit ``rng``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vbn_common.geometry import (
    CameraModel,
    compose_poses,
    invert_pose,
    world_points_to_camera,
)

CAMERA_HEIGHT = 1.2
ROOM = (6.0, 3.0)
WALL_HEIGHT = 2.5


def wall_points(rng: np.random.Generator, n: int) -> np.ndarray:
    """Return ``(n, 3)`` random points on the room's walls and a pillar (``map``)."""
    w, h = ROOM
    side = rng.integers(0, 5, n)
    s = rng.random(n)
    z = rng.uniform(0.0, WALL_HEIGHT, n)
    x = np.select([side == 0, side == 1, side == 2, side == 3], [w * s, w, w * s, 0.0],
                  3.4 + 0.4 * s)
    y = np.select([side == 0, side == 1, side == 2, side == 3], [0.0, h * s, h, h * s], 1.3)
    return np.stack([x, y, z], axis=1)


@dataclass(frozen=True)
class Views:
    """Matched pixels of the same scene points in several views.

    Attributes:
        poses: ``(k, 3)`` camera poses ``(x, y, yaw)`` in ``map``.
        uv: ``(k, n, 2)`` pixels of the ``n`` points in each view.
        points: ``(n, 3)`` the points.
    """

    poses: np.ndarray
    uv: np.ndarray
    points: np.ndarray

    def truth(self, model: int, current: int) -> tuple[float, float]:
        """Return ``(theta, phi)`` of view ``current`` relative to view ``model``."""
        rel = compose_poses(invert_pose(self.poses[model]), self.poses[current])
        return float(rel[2]), float(np.arctan2(rel[1], rel[0]))


def render_views(camera: CameraModel, poses: np.ndarray, rng: np.random.Generator,
                 n: int = 50, noise_px: float = 0.0, outliers: float = 0.0,
                 noisy_views: tuple[int, ...] | None = None,
                 min_range: float = 0.3) -> Views:
    """Project wall points seen by every view, with noise and outliers.

    Args:
        camera: the camera model of all views.
        poses: ``(k, 3)`` camera poses in ``map``.
        rng: random generator.
        n: points wanted (all visible in every view).
        noise_px: Gaussian pixel noise (standard deviation), every view.
        outliers: fraction of points whose pixels in the last view are replaced by
            random pixels (wrong matches).
        noisy_views: views that get noise (default all).
        min_range: points nearer than this to a camera are skipped.

    Returns:
        The views.
    """
    poses = np.asarray(poses, dtype=float)
    kept: list[np.ndarray] = []
    uv_kept: list[np.ndarray] = []
    total = 0
    while total < n:
        points = wall_points(rng, 4000)
        ok = np.ones(len(points), dtype=bool)
        uvs = []
        for pose in poses:
            cam_points = world_points_to_camera(pose, CAMERA_HEIGHT, points)
            uv, valid = camera.project(cam_points)
            ok &= valid & (np.hypot(cam_points[:, 0], cam_points[:, 2]) > min_range)
            uvs.append(uv)
        kept.append(points[ok])
        uv_kept.append(np.stack(uvs)[:, ok])
        total += int(ok.sum())
    points = np.concatenate(kept)[:n]
    uv = np.concatenate(uv_kept, axis=1)[:, :n].copy()
    views = range(len(poses)) if noisy_views is None else noisy_views
    for k in views:
        uv[k] += rng.normal(0.0, noise_px, uv[k].shape) if noise_px > 0 else 0.0
    if outliers > 0:
        bad = rng.choice(n, size=int(round(outliers * n)), replace=False)
        uv[-1, bad] = rng.uniform([0, 0], [camera.width - 1, camera.height - 1],
                                  (len(bad), 2))
    return Views(poses=poses, uv=uv, points=points)


def random_pose_near(rng: np.random.Generator, centre: np.ndarray, radius: float,
                     yaw_spread: float) -> np.ndarray:
    """Return a pose within ``radius`` of ``centre`` (x, y) and ``yaw_spread`` of its yaw."""
    angle = rng.uniform(-np.pi, np.pi)
    r = radius * np.sqrt(rng.random())
    return np.array([centre[0] + r * np.cos(angle), centre[1] + r * np.sin(angle),
                     centre[2] + rng.uniform(-yaw_spread, yaw_spread)])
