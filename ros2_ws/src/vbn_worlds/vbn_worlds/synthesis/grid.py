"""The exploration grid: every free pose of a regular lattice (thesis Section 8.3.2).

The thesis's Room 408 data set sampled a 6 m x 3 m space every 25 cm and took images
at each lattice pose. Here the lattice is centred in the scene's bounding box, keeps
the poses inside the free space with at least ``clearance`` metres to every wall,
and is visited in boustrophedon order (row by row, alternating direction), the way a
robot would drive it.
"""
from __future__ import annotations

import math

import numpy as np

from landmark_db.scene import Scene
from vbn_worlds.errors import WorldsError

__all__ = ['exploration_poses']


def exploration_poses(scene: Scene, spacing: float, clearance: float = 0.2) -> np.ndarray:
    """Return the free lattice poses, in boustrophedon visiting order.

    Args:
        scene: the scene.
        spacing: lattice spacing, metres (> 0).
        clearance: minimum distance from a pose to any wall, metres.

    Returns:
        ``(n, 2)`` positions ``(x, y)``; the lattice rows run along ``x``.

    Raises:
        WorldsError: invalid spacing, or no free pose at all.
    """
    if not (math.isfinite(spacing) and spacing > 0):
        raise WorldsError(f'grid spacing must be a positive number, got {spacing}')
    xmin, ymin, xmax, ymax = scene.bounds()
    axes = []
    for lo, hi in ((xmin, xmax), (ymin, ymax)):
        span = hi - lo - 2 * clearance
        count = int(math.floor(span / spacing + 1e-9)) + 1 if span >= 0 else 1
        if count > 100_000:
            raise WorldsError(f'grid spacing {spacing} m is too small for this scene')
        offset = (hi - lo - (count - 1) * spacing) / 2.0
        axes.append(lo + offset + spacing * np.arange(count))
    gx, gy = np.meshgrid(axes[0], axes[1])  # rows along x
    gx[1::2] = gx[1::2, ::-1]  # boustrophedon: every other row backwards
    points = np.stack([gx.ravel(), gy.ravel()], axis=1)
    keep = scene.free_space(points)
    keep[keep] = scene.wall_distance(points[keep]) >= clearance
    if not np.any(keep):
        raise WorldsError(
            f'no free pose at spacing {spacing} m with {clearance} m clearance in the scene')
    return points[keep]
