"""The sampled pose graph G = (V, E) of a simulated world (Section 8.1, Definition 3.1).

Poses are the vertices of a square grid of ``spacing`` metres laid over the world's
bounding box that lie in free space at least ``margin`` metres from every wall.
Edges join 4-neighbours on the grid when both are poses and the segment between them
crosses no wall (an obstacle corner can cut a grid edge).
"""
from __future__ import annotations

import numpy as np

from landmark_db.errors import LandmarkDbError
from landmark_db.scene import Scene
from landmark_db.simulator.visibility import segments_blocked

__all__ = ['pose_grid', 'wall_distance']


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
        LandmarkDbError: if ``spacing`` is not positive.
    """
    if not spacing > 0:
        raise LandmarkDbError(f'spacing must be positive, got {spacing}')
    margin = spacing / 4 if margin is None else margin
    xmin, ymin, xmax, ymax = scene.bounds()
    xs = np.arange(np.floor(xmin / spacing), np.ceil(xmax / spacing) + 1) * spacing
    ys = np.arange(np.floor(ymin / spacing), np.ceil(ymax / spacing) + 1) * spacing
    gx, gy = np.meshgrid(xs, ys)  # (rows = y, cols = x)
    points = np.stack([gx.ravel(), gy.ravel()], axis=1)
    free = scene.free_space(points)
    if margin > 0 and free.any():
        free[free] = wall_distance(scene, points[free]) >= margin
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


def wall_distance(scene: Scene, points: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest wall segment, metres.

    Args:
        scene: the polygon world.
        points: ``(n, 2)`` query points.

    Returns:
        ``(n,)`` distances.
    """
    starts, ends, _ = scene.wall_segments()
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    out = np.full(points.shape[0], np.inf)
    d = ends - starts
    length2 = np.maximum(np.sum(d * d, axis=1), 1e-300)
    for lo in range(0, points.shape[0], 20000):
        p = points[lo:lo + 20000, None, :]
        t = np.clip(np.sum((p - starts) * d, axis=-1) / length2, 0.0, 1.0)
        closest = starts + t[..., None] * d
        out[lo:lo + 20000] = np.linalg.norm(p - closest, axis=-1).min(axis=1)
    return out
