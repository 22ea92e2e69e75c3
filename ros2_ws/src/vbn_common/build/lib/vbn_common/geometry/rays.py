"""The point nearest several rays: least-squares triangulation of known cameras' rays.

For rays ``c_i + t d_i`` (unit ``d_i``) the point ``p`` minimising the sum of squared
distances to the rays solves ``sum_i (I - d_i d_i^T) p = sum_i (I - d_i d_i^T) c_i``
(Hartley and Zisserman's mid-point method generalised to many views). The builder
triangulates its scene points so (:mod:`visibility_builder.scene_points`,
:mod:`visibility_builder.point_patches`) and the structure-based peer its tracks
(:mod:`vbn_bench.localization.peer_map`), many groups of rays at once.
"""
from __future__ import annotations

import numpy as np

__all__ = ['intersect_rays']


def intersect_rays(rays: np.ndarray, centres: np.ndarray, group: np.ndarray, n: int,
                   solve: np.ndarray | None = None) -> np.ndarray:
    """Return the least-squares point of each group's rays.

    Args:
        rays: ``(m, 3)`` unit rays.
        centres: ``(m, 3)`` where they start.
        group: ``(m,)`` each ray's group, in ``[0, n)``.
        n: number of groups.
        solve: ``(n,)`` bool, the groups to solve (default: those of two rays or more).

    Returns:
        ``(n, 3)``, NaN for the groups not solved (parallel rays give a far, poorly
        fixed point: a caller judges the rays' spread).

    Example:
        >>> rays = np.array([[1.0, 0, 0], [0, 1.0, 0]])
        >>> intersect_rays(rays, np.array([[0.0, 2, 0], [3, 0, 0]]), np.array([0, 0]), 1)
        array([[3., 2., 0.]])
    """
    proj = np.eye(3)[None] - rays[:, :, None] * rays[:, None, :]
    a = np.zeros((n, 3, 3))
    b = np.zeros((n, 3))
    np.add.at(a, group, proj)
    np.add.at(b, group, np.einsum('nij,nj->ni', proj, centres))
    out = np.full((n, 3), np.nan)
    if solve is None:
        solve = np.bincount(group, minlength=n) >= 2
    if solve.any():
        out[solve] = np.linalg.solve(a[solve] + 1e-9 * np.eye(3),
                                     b[solve][:, :, None])[:, :, 0]
    return out
