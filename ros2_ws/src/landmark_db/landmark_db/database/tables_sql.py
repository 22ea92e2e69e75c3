"""The classes' and regions' rows of the database file (:mod:`.schema`), every version.

Written and read by :mod:`.store` inside its transaction. Schema 5 (a
database a third of a structure-based peer's compact map) keeps what earlier versions
spread over one row per item in BLOBs of the narrowest exact type: a class's
descriptors (whole or their codes, :mod:`.codebook`) in its ``classes`` row, a
region's poses, landmark and extra features in its ``regions`` row, pose and class ids
in 16 bits where they fit. Files of schemas 1 to 4 are read as they were written.
"""
from __future__ import annotations

import sqlite3
from typing import Any

import numpy as np
import scipy.sparse as sp

from landmark_db.database.codebook import DescriptorCodebook
from landmark_db.database.fields import DESCRIPTOR_SIZE
from landmark_db.database.model import (
    FeatureClasses,
    LandmarkDatabase,
    ModelView,
    RegionRecord,
)
from landmark_db.database.sql_rows import (
    check_ids,
    descriptor_blob,
    read_descriptors,
    rows_array,
)
from landmark_db.errors import LandmarkDbError

__all__ = ['id_dtype', 'insert_classes', 'insert_regions', 'load_classes', 'load_regions']


def id_dtype(count: int, signed: bool = False) -> str:
    """Little-endian dtype of ids ``0..count-1`` (and -1 when ``signed``), schema 5."""
    if signed:
        return '<i2' if count <= np.iinfo(np.int16).max else '<i4'
    return '<u2' if count <= np.iinfo(np.uint16).max + 1 else '<i4'


def _ids(values: np.ndarray, dtype: str) -> bytes:
    return np.asarray(values).astype(dtype).tobytes()


# --- writing (schema 5) --------------------------------------------------------------


def insert_classes(connection: sqlite3.Connection, classes: FeatureClasses,
                   codebook: DescriptorCodebook | None) -> None:
    """Write ``classes`` (with each class's descriptors) and ``visibility``."""
    visibility = classes.visibility
    n = classes.n_classes
    if n > np.iinfo(np.int32).max:
        raise LandmarkDbError(f'{n} classes do not fit the int32 visibility lists')
    seen_by = np.bincount(visibility.indices, minlength=n)
    blob = descriptor_blob(classes.descriptors, codebook)
    size = DESCRIPTOR_SIZE if codebook is None else codebook.code_size
    bounds = (classes.offsets * size).tolist()
    connection.executemany('INSERT INTO classes VALUES (?, ?, ?, ?)', (
        (c, count, seen, blob[bounds[c]:bounds[c + 1]]) for c, (count, seen) in enumerate(
            zip(np.diff(classes.offsets).tolist(), seen_by.tolist(), strict=True))))
    ids = visibility.indices.astype(id_dtype(n))
    rows = visibility.indptr.tolist()
    connection.executemany('INSERT INTO visibility VALUES (?, ?)',
                           ((pose, ids[rows[pose]:rows[pose + 1]].tobytes())
                            for pose in range(visibility.shape[0])))


def insert_regions(connection: sqlite3.Connection, db: LandmarkDatabase) -> None:
    """Write ``regions`` (members in BLOBs), the model views, the region graph, uncovered."""
    pose_type, class_type = id_dtype(db.n_poses), id_dtype(db.n_classes)
    view_type = id_dtype(db.n_classes, signed=True)
    view_id = 0
    for r, region in enumerate(db.regions):
        connection.execute('INSERT INTO regions VALUES (?, ?, ?, ?, ?, ?, ?, ?)', (
            r, region.poses.size, region.landmark.size, region.extra.size,
            len(region.model_views), _ids(region.poses, pose_type),
            _ids(region.landmark, class_type), _ids(region.extra, class_type)))
        for ordinal, view in enumerate(region.model_views):
            connection.execute(
                'INSERT INTO model_views VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)',
                (view_id, r, ordinal, view.pose, view.image_stamp_ns, view.image_index,
                 view.x, view.y, view.yaw, len(view)))
            connection.execute(
                'INSERT INTO model_view_features VALUES (?, ?, ?, ?)',
                (view_id, _ids(view.class_ids, view_type),
                 view.keypoints.astype('<f4').tobytes(),
                 descriptor_blob(view.descriptors, db.codebook)))
            view_id += 1
    adjacency = db.adjacency
    connection.executemany(
        'INSERT INTO region_adjacency VALUES (?, ?, ?, ?)',
        zip(adjacency.pairs[:, 0].tolist(), adjacency.pairs[:, 1].tolist(),
            adjacency.shared_poses.tolist(), adjacency.joining_edges.tolist()))
    connection.executemany('INSERT INTO uncovered VALUES (?)',
                           ((pose,) for pose in db.uncovered.tolist()))


# --- reading (every version) ---------------------------------------------------------


def load_classes(connection: sqlite3.Connection, version: int, n_poses: int,
                 codebook: DescriptorCodebook | None) -> FeatureClasses:
    """Read the classes, their descriptors and the visibility lists."""
    counts = rows_array(connection, 'SELECT id, n_descriptors FROM classes ORDER BY id',
                        np.int64, 2)
    check_ids(counts[:, 0], 'classes')
    n_classes = counts.shape[0]
    size = DESCRIPTOR_SIZE if codebook is None else codebook.code_size
    if version >= 5:
        blobs = [row[0] for row in connection.execute(
            'SELECT descriptors FROM classes ORDER BY id')]
        if any(not isinstance(blob, bytes) or len(blob) != size * count
               for blob, count in zip(blobs, counts[:, 1].tolist(), strict=True)):
            raise LandmarkDbError('class descriptor counts differ from the classes table')
        per_class = counts[:, 1]
    else:
        rows = connection.execute('SELECT class_id, descriptor FROM class_descriptors '
                                  'ORDER BY class_id, ordinal').fetchall()
        owners = np.array([row[0] for row in rows], dtype=np.int64)
        blobs = [row[1] for row in rows]
        if any(not isinstance(blob, bytes) or len(blob) != size for blob in blobs):
            raise LandmarkDbError(f'a class descriptor is not {size} bytes')
        if owners.size and (owners.min() < 0 or owners.max() >= n_classes):
            raise LandmarkDbError('a class descriptor belongs to no class')
        per_class = np.bincount(owners, minlength=n_classes)
        if not np.array_equal(per_class, counts[:, 1]):
            raise LandmarkDbError('class descriptor counts differ from the classes table')
    descriptors = read_descriptors(b''.join(blobs), codebook, 'class descriptors')
    offsets = np.concatenate([[0], np.cumsum(per_class)]).astype(np.int64)
    rows = connection.execute('SELECT pose, class_ids FROM visibility ORDER BY pose'
                              ).fetchall()
    if [row[0] for row in rows] != list(range(n_poses)):
        raise LandmarkDbError(f'visibility does not list poses 0..{n_poses - 1}')
    dtype = np.dtype(id_dtype(n_classes) if version >= 5 else '<i4')
    if any(not isinstance(row[1], bytes) or len(row[1]) % dtype.itemsize for row in rows):
        raise LandmarkDbError(f'a visibility list is not a whole number of {dtype.name} ids')
    indices = np.frombuffer(b''.join(row[1] for row in rows), dtype=dtype).astype(np.int64)
    indptr = np.concatenate([[0], np.cumsum([len(row[1]) // dtype.itemsize
                                             for row in rows])])
    if indices.size and (indices.min() < 0 or indices.max() >= n_classes):
        raise LandmarkDbError('visibility holds a class out of range')
    visibility = sp.csr_matrix((np.ones(indices.size, dtype=bool), indices,
                                indptr.astype(np.int64)), shape=(n_poses, n_classes))
    return FeatureClasses(descriptors, offsets, visibility)


def load_regions(connection: sqlite3.Connection, version: int, n_poses: int,
                 n_classes: int, codebook: DescriptorCodebook | None
                 ) -> tuple[RegionRecord, ...]:
    """Read the regions and their model views."""
    table = rows_array(connection, 'SELECT id, n_poses, n_landmark, n_extra, n_model_views '
                       'FROM regions ORDER BY id', np.int64, 5)
    check_ids(table[:, 0], 'regions')
    n_regions = table.shape[0]
    members = _members(connection, version, n_poses, n_classes, table)
    views = connection.execute(
        'SELECT v.region, v.pose, v.image_stamp_ns, v.image_index, v.x, v.y, v.yaw, '
        'v.n_features, f.class_ids, f.keypoints, f.descriptors FROM model_views AS v '
        'JOIN model_view_features AS f ON f.view = v.id ORDER BY v.region, v.ordinal'
    ).fetchall()
    view_regions = np.array([row[0] for row in views], dtype=np.int64)
    if view_regions.size and (view_regions.min() < 0 or view_regions.max() >= n_regions):
        raise LandmarkDbError('a region model view belongs to no region')
    if not np.array_equal(np.bincount(view_regions, minlength=n_regions), table[:, 4]):
        raise LandmarkDbError('region model view counts differ from the regions table')
    view_bounds = np.searchsorted(view_regions, np.arange(n_regions + 1))
    id_type = '<i8' if version < 5 else id_dtype(n_classes, signed=True)
    return tuple(
        RegionRecord(poses, landmark, extra, tuple(
            _model_view(row, codebook, id_type)
            for row in views[view_bounds[r]:view_bounds[r + 1]]))
        for r, (poses, landmark, extra) in enumerate(members))


def _members(connection: sqlite3.Connection, version: int, n_poses: int, n_classes: int,
             table: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Each region's ``(poses, landmark, extra)``, checked against the regions table."""
    n_regions = table.shape[0]
    if version >= 5:
        rows = connection.execute('SELECT poses, landmark, extra FROM regions ORDER BY id'
                                  ).fetchall()
        out = []
        for r, row in enumerate(rows):
            arrays = []
            for blob, dtype, count in zip(row, (id_dtype(n_poses), id_dtype(n_classes),
                                                id_dtype(n_classes)), table[r, 1:4].tolist(),
                                          strict=True):
                if not isinstance(blob, bytes) or len(blob) != np.dtype(dtype).itemsize * count:
                    raise LandmarkDbError(f'region {r}: its members differ from its counts '
                                          f'in the regions table')
                arrays.append(np.frombuffer(blob, dtype).astype(np.int64))
            out.append(tuple(arrays))
        return out
    members = rows_array(connection, 'SELECT region, pose FROM region_poses '
                         'ORDER BY region, pose', np.int64, 2)
    features = rows_array(connection, "SELECT region, role = 'landmark', ordinal, class_id "
                          'FROM region_features', np.int64, 4)
    # Per region: landmark (flag 1) first, then extra, each in stored order.
    features = features[np.lexsort((features[:, 2], -features[:, 1], features[:, 0]))]
    for name, values, expected in (('pose', members[:, 0], table[:, 1]),
                                   ('feature', features[:, 0], table[:, 2] + table[:, 3])):
        if values.size and (values.min() < 0 or values.max() >= n_regions):
            raise LandmarkDbError(f'a region {name} belongs to no region')
        if not np.array_equal(np.bincount(values, minlength=n_regions), expected):
            raise LandmarkDbError(f'region {name} counts differ from the regions table')
    pose_bounds = np.searchsorted(members[:, 0], np.arange(n_regions + 1))
    feature_bounds = np.searchsorted(features[:, 0], np.arange(n_regions + 1))
    out = []
    for r in range(n_regions):
        own = features[feature_bounds[r]:feature_bounds[r + 1]]
        if int(own[:, 1].sum()) != table[r, 2]:
            raise LandmarkDbError(f'region {r} landmark count differs from the regions table')
        out.append((members[pose_bounds[r]:pose_bounds[r + 1], 1], own[own[:, 1] == 1, 3],
                    own[own[:, 1] == 0, 3]))
    return out


def _model_view(row: tuple[Any, ...], codebook: DescriptorCodebook | None, id_type: str
                ) -> ModelView:
    _, pose, stamp, image_index, x, y, yaw, m, class_blob, keypoint_blob, descriptors \
        = row
    size = DESCRIPTOR_SIZE if codebook is None else codebook.code_size
    if (len(class_blob) != np.dtype(id_type).itemsize * m or len(keypoint_blob) != 8 * m
            or len(descriptors) != size * m):
        raise LandmarkDbError(f'model view of image {image_index}: feature arrays do not '
                              f'hold {m} features')
    return ModelView(pose, stamp, image_index, x, y, yaw,
                     np.frombuffer(class_blob, dtype=id_type),
                     np.frombuffer(keypoint_blob, dtype='<f4').reshape(m, 2),
                     read_descriptors(descriptors, codebook, 'model view descriptors'))
