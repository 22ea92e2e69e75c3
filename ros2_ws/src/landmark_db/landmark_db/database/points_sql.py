"""The scene points' rows of the database file (``scene_points``, :mod:`.schema`).

Written and read by :mod:`.store` inside its transaction: schema 1 files have no table
(no point), schema 2 no ``seen_*`` columns, schema 3 no ``patch*`` columns;
what a file lacks is read as unknown.
"""
from __future__ import annotations

import json
import math
import sqlite3

import numpy as np

from landmark_db.database.codebook import DescriptorCodebook
from landmark_db.database.fields import DESCRIPTOR_SIZE
from landmark_db.database.patch_codec import decode_patches
from landmark_db.database.points import ScenePoints
from landmark_db.database.sql_rows import (
    check_ids,
    descriptor_blob,
    has_table,
    read_descriptors,
    rows_array,
)
from landmark_db.errors import LandmarkDbError

__all__ = ['insert_points', 'load_points']


def insert_points(connection: sqlite3.Connection, points: ScenePoints,
                  codebook: DescriptorCodebook | None = None) -> None:
    """Write the points as columns (schema 5), each in the narrowest exact dtype.

    Descriptors are whole or their codes (``codebook``); the patches of the points that
    have one are their JPEG code when the points carry it (:meth:`ScenePoints.compact`).
    """
    n = points.n_points
    mask = points.patch_mask
    columns: list[tuple[str, str, tuple[int, ...], bytes]] = [
        _column('xyz', points.xyz, _FLOATS[1:]),
        _column('class_ids', points.class_ids, _INTS),
        _column('views', points.views, _INTS),
        ('descriptors', '|u1', (n,), descriptor_blob(points.descriptors, codebook))]
    if points.has_seen_from:
        columns.append(_seen_column(points))
    if mask.any():
        columns.append(_column('patch_points', np.flatnonzero(mask), _INTS))
        columns.append(_column('patch_axes', points.patch_axes[mask], _FLOATS))
        side = points.patches.shape[1]
        columns.append(('patches', 'jpeg', (int(mask.sum()), side, side), points.patch_code)
                       if points.patch_code is not None else
                       ('patches', '|u1', (int(mask.sum()), side, side),
                        points.patches[mask].tobytes()))
    connection.executemany('INSERT INTO scene_point_columns VALUES (?, ?, ?, ?)',
                           ((name, dtype, json.dumps(list(shape)), data)
                            for name, dtype, shape, data in columns))


_FLOATS = ('<f2', '<f4', '<f8')
_MAX_PATCH_PX = 255  # (a damaged shape would allocate before the code is read)
_INTS = ('|u1', '<i2', '<u2', '<i4', '<i8')


def _seen_column(points: ScenePoints) -> tuple[str, str, tuple[int, ...], bytes]:
    """Where the points were seen from: as an offset from them when that is exact."""
    seen = points.seen_from
    offset = np.column_stack([seen[:, :2] - points.xyz[:, :2], seen[:, 2]])
    name, dtype, shape, data = _column('seen_offset', offset, _FLOATS)
    back = np.frombuffer(data, dtype).reshape(shape).astype(np.float64)
    if np.array_equal(back[:, :2] + points.xyz[:, :2], seen[:, :2]):
        return name, dtype, shape, data
    return _column('seen_from', seen, _FLOATS)


def _column(name: str, values: np.ndarray, dtypes: tuple[str, ...]
            ) -> tuple[str, str, tuple[int, ...], bytes]:
    """``(name, dtype, shape, bytes)`` in the first of ``dtypes`` that holds it exactly."""
    values = np.asarray(values)
    for dtype in dtypes:
        with np.errstate(over='ignore', invalid='ignore'):
            cast = values.astype(dtype)
        if np.array_equal(cast.astype(values.dtype), values, equal_nan=values.dtype.kind == 'f'):
            return name, dtype, values.shape, cast.tobytes()
    raise LandmarkDbError(f'scene point {name} fits none of {dtypes}')


def load_points(connection: sqlite3.Connection, codebook: DescriptorCodebook | None = None
                ) -> ScenePoints:
    """Read the scene points (none in a schema 1 file; codes decoded by ``codebook``)."""
    if has_table(connection, 'scene_point_columns'):
        return _load_columns(connection, codebook)
    if not has_table(connection, 'scene_points'):
        return ScenePoints.empty()
    ints = rows_array(connection, 'SELECT id, class_id, views FROM scene_points ORDER BY id',
                 np.int64, 3)
    check_ids(ints[:, 0], 'scene_points')
    xyz = rows_array(connection, 'SELECT x, y, z FROM scene_points ORDER BY id', np.float64, 3)
    blobs = [row[0] for row in connection.execute(
        'SELECT descriptor FROM scene_points ORDER BY id')]
    size = DESCRIPTOR_SIZE if codebook is None else codebook.code_size
    if any(not isinstance(blob, bytes) or len(blob) != size for blob in blobs):
        raise LandmarkDbError(f'a scene point descriptor is not {size} bytes')
    descriptors = read_descriptors(b''.join(blobs), codebook, 'scene point descriptors')
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


_SHAPES = {'xyz': (None, 3), 'class_ids': (None,), 'views': (None,), 'descriptors': (None,),
           'seen_from': (None, 3), 'seen_offset': (None, 3), 'patch_points': (None,),
           'patch_axes': (None, 2, 3),
           'patches': (None, None, None)}


def _load_columns(connection: sqlite3.Connection, codebook: DescriptorCodebook | None
                  ) -> ScenePoints:
    """Read the columns of schema 5 (:func:`insert_points`)."""
    stored = {}
    for name, dtype, shape, data in connection.execute(
            'SELECT name, dtype, shape, data FROM scene_point_columns'):
        shape = tuple(json.loads(shape))
        if name not in _SHAPES or len(shape) != len(_SHAPES[name]) or any(
                want is not None and got != want for got, want in zip(shape, _SHAPES[name])):
            raise LandmarkDbError(f'scene point column {name!r} of shape {shape} is unknown')
        stored[name] = (dtype, shape, data)
    if {'xyz', 'class_ids', 'views', 'descriptors'} - set(stored):
        raise LandmarkDbError('scene point columns lack xyz, class_ids, views or descriptors')
    arrays = {name: _array(name, *stored[name]) for name in stored
              if name not in ('descriptors', 'patches')}
    n = len(arrays['xyz'])
    descriptors = read_descriptors(stored['descriptors'][2], codebook,
                                   'scene point descriptors')
    if len(descriptors) != n or stored['descriptors'][1] != (n,):
        raise LandmarkDbError(f'{len(descriptors)} scene point descriptors for {n} points')
    patches = axes = code = None
    if 'patches' in stored:
        dtype, shape, data = stored['patches']
        index = arrays.get('patch_points')
        if index is None or index.dtype.kind not in 'iu' or 'patch_axes' not in arrays or \
                len(index) != shape[0] or \
                len(arrays['patch_axes']) != shape[0] or shape[1] != shape[2] or \
                (index.size and (index.min() < 0 or index.max() >= n or
                                 np.any(np.diff(index) <= 0))):
            raise LandmarkDbError('scene point patches, their points and axes disagree')
        if shape[1] > _MAX_PATCH_PX or not isinstance(data, bytes):
            raise LandmarkDbError(f'scene point patches of {shape[1]} px are not '
                                  f'patches of a database')
        if dtype == 'jpeg':
            code = data
            own = decode_patches(data, shape[0], shape[1])
        else:
            own = _array('patches', dtype, shape, data)
        patches = np.zeros((n, shape[1], shape[2]), np.uint8)
        patches[index] = own
        axes = np.full((n, 2, 3), np.nan, np.float32)
        axes[index] = arrays['patch_axes']
    seen = arrays.get('seen_from')
    if 'seen_offset' in arrays:
        offset = arrays['seen_offset'].astype(np.float64)
        if len(offset) != n:
            raise LandmarkDbError(f'{len(offset)} scene point seen_offset rows for {n} points')
        seen = np.column_stack([arrays['xyz'][:, :2] + offset[:, :2], offset[:, 2]])
    return ScenePoints(arrays['xyz'], arrays['class_ids'], descriptors, arrays['views'],
                       seen, patches, axes, code)


def _array(name: str, dtype: str, shape: tuple[int, ...], data: bytes) -> np.ndarray:
    """One stored column as an array of its stored shape."""
    if dtype not in _FLOATS + _INTS or not isinstance(data, bytes) or \
            len(data) != np.dtype(dtype).itemsize * math.prod(shape):
        raise LandmarkDbError(f'scene point column {name!r} is not {shape} of {dtype}')
    return np.frombuffer(data, dtype).reshape(shape)
