"""The scene points' rows of the database file (``scene_points``, :mod:`.schema`).

Written and read by :mod:`.store` inside its transaction: schema 1 files have no table
(no point), schema 2 no ``seen_*`` columns, schema 3 no ``patch*`` columns (issue 16);
what a file lacks is read as unknown.
"""
from __future__ import annotations

import math
import sqlite3

import numpy as np

from landmark_db.database.fields import DESCRIPTOR_SIZE
from landmark_db.database.points import ScenePoints
from landmark_db.database.sql_rows import check_ids, has_table, rows_array
from landmark_db.errors import LandmarkDbError

__all__ = ['insert_points', 'load_points']


def insert_points(connection: sqlite3.Connection, points: ScenePoints) -> None:
    """Write one row per scene point."""
    seen = [None if not np.isfinite(row).all() else tuple(float(v) for v in row)
            for row in points.seen_from]
    mask = points.patch_mask
    patches = [points.patches[i].tobytes() if mask[i] else None for i in range(len(mask))]
    axes = [points.patch_axes[i].astype('<f4').tobytes() if mask[i] else None
            for i in range(len(mask))]
    connection.executemany(
        'INSERT INTO scene_points VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)', (
            (i, int(c), int(v), float(p[0]), float(p[1]), float(p[2]), d.tobytes(),
             *(s if s is not None else (None, None, None)), patch, axis)
            for i, (c, v, p, d, s, patch, axis) in enumerate(zip(
                points.class_ids.tolist(), points.views.tolist(), points.xyz,
                points.descriptors, seen, patches, axes, strict=True))))


def load_points(connection: sqlite3.Connection) -> ScenePoints:
    """Read the scene points (none in a schema 1 file)."""
    if not has_table(connection, 'scene_points'):
        return ScenePoints.empty()
    ints = rows_array(connection, 'SELECT id, class_id, views FROM scene_points ORDER BY id',
                 np.int64, 3)
    check_ids(ints[:, 0], 'scene_points')
    xyz = rows_array(connection, 'SELECT x, y, z FROM scene_points ORDER BY id', np.float64, 3)
    blobs = [row[0] for row in connection.execute(
        'SELECT descriptor FROM scene_points ORDER BY id')]
    if any(len(blob) != DESCRIPTOR_SIZE for blob in blobs):
        raise LandmarkDbError(f'a scene point descriptor is not {DESCRIPTOR_SIZE} bytes')
    descriptors = np.frombuffer(b''.join(blobs), dtype=np.uint8).reshape(-1, DESCRIPTOR_SIZE)
    columns = {row[1] for row in connection.execute('PRAGMA table_info(scene_points)')}
    seen = None
    if 'seen_radius' in columns:  # schema 3
        rows = connection.execute('SELECT seen_x, seen_y, seen_radius FROM scene_points '
                                  'ORDER BY id').fetchall()
        seen = np.array([[np.nan if v is None else v for v in row] for row in rows],
                        np.float64).reshape(-1, 3)
    patches = axes = None
    if 'patch' in columns:  # schema 4
        patches, axes = _load_patches(connection, len(xyz))
    return ScenePoints(xyz, ints[:, 1], descriptors, ints[:, 2], seen, patches, axes)


def _load_patches(connection: sqlite3.Connection, n: int
                  ) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
    """Read the scene points' patches and axes (NULL rows: no patch)."""
    rows = connection.execute('SELECT patch, patch_axes FROM scene_points ORDER BY id'
                              ).fetchall()
    sizes = {len(patch) for patch, _ in rows if patch is not None}
    if not sizes:
        return None, None
    side = math.isqrt(sizes.pop())
    if sizes or side * side != len(next(p for p, _ in rows if p is not None)) or \
            side % 2 == 0:
        raise LandmarkDbError('scene point patches are not all one odd square size')
    patches = np.zeros((n, side, side), np.uint8)
    axes = np.full((n, 2, 3), np.nan, np.float32)
    for i, (patch, axis) in enumerate(rows):
        if (patch is None) != (axis is None) or (axis is not None and len(axis) != 24):
            raise LandmarkDbError(f'scene point {i}: a patch needs its axes '
                                  f'(six float32)')
        if patch is not None:
            patches[i] = np.frombuffer(patch, np.uint8).reshape(side, side)
            axes[i] = np.frombuffer(axis, '<f4').reshape(2, 3)
    return patches, axes
