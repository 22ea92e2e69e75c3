"""The sampled pose graph G = (V, E) of a simulated world (Section 8.1, Definition 3.1).

Poses are the vertices of a square grid of ``spacing`` metres laid over the world's
bounding box that lie in free space at least ``margin`` metres from every wall.
Edges join 4-neighbours on the grid when both are poses and the segment between them
crosses no wall (an obstacle corner can cut a grid edge).
"""
from __future__ import annotations

import numpy as np

from landmark_db.geometry2d import segments_blocked
from landmark_db.scene import Scene
from vbn_worlds.errors import WorldsError

__all__ = ['pose_grid']


def pose_grid(scene: Scene, spacing: float = 0.5,
              margin: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sample the free space of ``scene`` on a square grid.

    Args:
        scene: the polygon world.
        spacing: grid step, metres (the thesis uses 0.5).
        margin: minimum distance from a pose to any wall, metres; default
            ``spacing / 4``, which keeps poses off the walls without losing the
            poses next to them.

    Returns:
        ``(poses, edges)``: ``(n, 2)`` pose coordinates in metres, row-major by
        ``(y, x)`` grid cell, and ``(m, 2)`` index pairs ``i < j`` of 4-connected
        neighbours.

    Raises:
        WorldsError: if ``spacing`` is not positive.
    """
    if not spacing > 0:
        raise WorldsError(f'spacing must be positive, got {spacing}')
    margin = spacing / 4 if margin is None else margin
    xmin, ymin, xmax, ymax = scene.bounds()
    xs = np.arange(np.floor(xmin / spacing), np.ceil(xmax / spacing) + 1) * spacing
    ys = np.arange(np.floor(ymin / spacing), np.ceil(ymax / spacing) + 1) * spacing
    gx, gy = np.meshgrid(xs, ys)  # (rows = y, cols = x)
    points = np.stack([gx.ravel(), gy.ravel()], axis=1)
    free = scene.free_space(points)
    if margin > 0 and free.any():
        free[free] = scene.wall_distance(points[free]) >= margin
    index = np.full(points.shape[0], -1, dtype=np.int64)
    index[free] = np.arange(int(free.sum()))
    grid_index = index.reshape(gy.shape)
    pairs = []
    for a, b in ((grid_index[:, :-1], grid_index[:, 1:]), (grid_index[:-1, :], grid_index[1:, :])):
        both = (a >= 0) & (b >= 0)
        pairs.append(np.stack([a[both], b[both]], axis=1))
    edges = np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64)
    poses = points[free]
    if len(edges):
        starts, ends, _ = scene.wall_segments()
        blocked = segments_blocked(poses[edges[:, 0]], poses[edges[:, 1]], starts, ends)
        edges = edges[~blocked]
    edges = np.sort(edges, axis=1)
    edges = edges[np.lexsort((edges[:, 1], edges[:, 0]))]
    return poses, edges
