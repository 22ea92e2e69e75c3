"""Feature visibility from the sampled poses of a simulated world (Section 8.1).

The thesis's simulator takes a feature as visible from a grid vertex "if the line
connecting the vertex to the feature does not intersect an obstacle or the
perimeter, and if that line is entirely contained in the visibility region of the
feature". The visibility region is the cone of the feature's angular extent about
its wall's inward normal, cut to the ring ``range_min <= distance <= range_max``.
For a cone with its apex at the feature, the whole segment lies in the cone exactly
when the pose does; the ring condition is applied to the pose's distance (the
segment always starts at the feature, inside ``range_min``).

The computation is vectorised in two passes over spatial tiles of poses:

1. the cone and range test over the tile's poses x the features in range of it;
2. the occlusion test only for the pairs that pass, as a batched segment-segment
   intersection against the wall segments near the tile (in chunks of pairs).

A segment that only touches the feature's own wall at the feature is not blocked; a
segment that grazes an obstacle corner is.
"""
from __future__ import annotations

import numpy as np

from landmark_db.geometry2d import point_segment_distance, segments_blocked
from landmark_db.scene import Scene

__all__ = ['compute_visibility', 'feature_walls', 'visible_pairs']

_POSE_CHUNK_CELLS = 4_000_000  # poses x features per chunk of the cone/range pass


def compute_visibility(scene: Scene, poses: np.ndarray, tile: float = 8.0) -> np.ndarray:
    """Tell which scene features are visible from which poses, as a dense matrix.

    See :func:`visible_pairs` for the method.

    Args:
        scene: the polygon world with its features.
        poses: ``(n, 2)`` pose coordinates, metres (assumed in free space).
        tile: tile side, metres.

    Returns:
        ``visible  # (n_poses, n_features) bool``, column ``j`` for
        ``scene.features`` row ``j``.
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 2)
    visible = np.zeros((poses.shape[0], len(scene.features)), dtype=bool)
    rows, cols = visible_pairs(scene, poses, tile)
    visible[rows, cols] = True
    return visible


def visible_pairs(scene: Scene, poses: np.ndarray,
                  tile: float = 8.0) -> tuple[np.ndarray, np.ndarray]:
    """List the (pose, feature) pairs where the feature is visible from the pose.

    Poses are processed in square tiles of ``tile`` metres; for each tile only the
    features within range of its bounding box, and only the walls whose bounding box
    meets the box spanned by the tile and those features, are tested. No segment from
    a pose of the tile to one of those features can leave that box, so the result is
    the same as testing every wall; the culling only makes large worlds fast.

    Args:
        scene: the polygon world with its features.
        poses: ``(n, 2)`` pose coordinates, metres (assumed in free space).
        tile: tile side, metres.

    Returns:
        ``(rows, cols)``: int64 pose indices and feature rows of ``scene.features``,
        sorted by pose then feature.
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 2)
    features = scene.features
    n, f = poses.shape[0], len(features)
    if n == 0 or f == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    out_rows: list[np.ndarray] = []
    out_cols: list[np.ndarray] = []
    starts, ends, _ = scene.wall_segments()
    wall_lo = np.minimum(starts, ends)
    wall_hi = np.maximum(starts, ends)
    own_wall = feature_walls(scene)
    position = features.positions
    normal = features.normals
    cos_half = np.cos(np.radians(np.clip(features.angular_extent_deg, 0.0, 360.0) / 2))
    rmin, rmax = features.range_min, features.range_max
    cell = np.floor((poses - poses.min(axis=0)) / tile).astype(np.int64)
    key = cell[:, 1] * (int(cell[:, 0].max()) + 1) + cell[:, 0]
    order = np.argsort(key, kind='stable')
    bounds = np.flatnonzero(np.diff(key[order])) + 1
    for members in np.split(order, bounds):
        tile_poses = poses[members]
        lo, hi = tile_poses.min(axis=0), tile_poses.max(axis=0)
        # Features whose range reaches the tile's box.
        gap = np.maximum(np.maximum(lo - position, position - hi), 0.0)
        near = np.flatnonzero(np.hypot(gap[:, 0], gap[:, 1]) <= rmax)
        if near.size == 0:
            continue
        box_lo = np.minimum(lo, position[near].min(axis=0))
        box_hi = np.maximum(hi, position[near].max(axis=0))
        walls = np.flatnonzero(np.all(wall_lo <= box_hi, axis=1)
                               & np.all(wall_hi >= box_lo, axis=1))
        wall_map = np.full(len(starts), -1, dtype=np.int64)
        wall_map[walls] = np.arange(walls.size)
        step = max(1, _POSE_CHUNK_CELLS // near.size)
        for lo_index in range(0, members.size, step):
            rows_global = members[lo_index:lo_index + step]
            chunk = poses[rows_global]
            offset = chunk[:, None, :] - position[None, near, :]  # feature -> pose
            dist = np.hypot(offset[..., 0], offset[..., 1])
            along_normal = offset[..., 0] * normal[near, 0] + offset[..., 1] * normal[near, 1]
            candidate = ((dist >= rmin[near]) & (dist <= rmax[near]) & (dist > 0)
                         & (along_normal >= cos_half[near] * dist))
            rows, cols = np.nonzero(candidate)
            cols = near[cols]
            blocked = segments_blocked(chunk[rows], position[cols], starts[walls], ends[walls],
                                       skip_wall=wall_map[own_wall[cols]])
            out_rows.append(rows_global[rows[~blocked]])
            out_cols.append(cols[~blocked])
    if not out_rows:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    rows_all = np.concatenate(out_rows).astype(np.int64)
    cols_all = np.concatenate(out_cols).astype(np.int64)
    order = np.lexsort((cols_all, rows_all))
    return rows_all[order], cols_all[order]


def feature_walls(scene: Scene) -> np.ndarray:
    """Return the index of the wall segment each feature lies on (the nearest one).

    Returns:
        ``(f,)`` indices into :meth:`Scene.wall_segments`.
    """
    positions = scene.features.positions
    if len(positions) == 0:
        return np.zeros(0, dtype=np.int64)
    starts, ends, _ = scene.wall_segments()
    return np.argmin(point_segment_distance(positions[:, None, :], starts, ends), axis=1)
