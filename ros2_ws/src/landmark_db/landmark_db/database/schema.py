"""The SQLite schema of the landmark database, version 4.

One SQLite file holds one :class:`~landmark_db.database.model.LandmarkDatabase`. The
file identifies itself three ways: ``PRAGMA application_id`` (:data:`APPLICATION_ID`,
the bytes ``VBNL``), ``PRAGMA user_version`` and the ``meta`` row ``schema_version``
(both :data:`SCHEMA_VERSION`). A reader refuses a file whose application id differs,
whose schema version is newer than it knows, or that lacks a table of
:data:`REQUIRED_TABLES`.

Tables (all indices are 0-based and equal to the in-memory indices):

======================  ==================================================================
table                   rows
======================  ==================================================================
meta                    ``key, value``: schema_version, application, writer,
                        content_digest (BLAKE2b of the contents, checked on opening)
build_parameters        ``key, value``: one JSON value per :class:`BuildInfo` field, and
                        ``pose_spacing``
poses                   ``id, x, y, yaw, grid_ix, grid_iy`` (grid -1 off the grid)
edges                   ``id, a, b``: the pose graph G, in order
classes                 ``id, n_descriptors, n_poses``: one per feature class
class_descriptors       ``class_id, ordinal, descriptor``: 128-byte uint8 BLOBs
visibility              ``pose, class_ids``: the classes seen from the pose (after
                        filtering), sorted little-endian int32 BLOB; one row per pose,
                        not per pair: 1.5 million pairs took 3 s to write and 2.5 s to
                        read as rows, 0.1 s as BLOBs
regions                 ``id, n_poses, n_landmark, n_extra, n_model_views``
region_poses            ``region, pose``
region_features         ``region, class_id, role ('landmark'|'extra'), ordinal``; indexed
                        by class: the feature-to-region membership used for voting
model_views             ``id, region, ordinal, pose, image_stamp_ns, image_index, x, y,
                        yaw, n_features``
model_view_features     ``view, class_ids, keypoints, descriptors``: little-endian BLOBs,
                        int64 ``(m,)``, float32 ``(m, 2)``, uint8 ``(m, 128)``
region_adjacency        ``region_a < region_b, shared_poses, joining_edges``: the region
                        graph, stored for a fast start-up and checked against the
                        regions when the database is opened
uncovered               ``pose``: k-coverable poses no region covers
scene_points            ``id, class_id, views, x, y, z, descriptor, seen_x, seen_y,
                        seen_radius, patch, patch_axes``: the triangulated scene points
                        (:mod:`.points`), class -1 for a point the filters did not keep,
                        a 128-byte uint8 descriptor, where the exploration saw it from
                        (schema 3), and its exploration patch, ``s * s`` uint8 bytes
                        row by row, with its axes, six little-endian float32 (schema
                        4; NULL for a point with no patch). Schema 3 has no ``patch*``
                        columns and schema 2 no ``seen_*``: they are read as unknown; a
                        schema 1 file has no table and is read with no point
======================  ==================================================================

A new column or table that old readers could ignore still bumps the version: readers
refuse newer files rather than guess.
"""
from __future__ import annotations

__all__ = ['APPLICATION_ID', 'APPLICATION_NAME', 'REQUIRED_TABLES', 'SCHEMA_SQL',
           'SCHEMA_VERSION']

SCHEMA_VERSION = 4
"""The schema version this code writes and the newest it reads."""

APPLICATION_ID = int.from_bytes(b'VBNL', 'big')
"""``PRAGMA application_id`` of a landmark database (0x56424E4C)."""

APPLICATION_NAME = 'vbn-landmark-database'
"""The ``meta`` row ``application``."""

SCHEMA_SQL = """
CREATE TABLE meta (
    key TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE build_parameters (
    key TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE poses (
    id INTEGER PRIMARY KEY,
    x REAL NOT NULL,
    y REAL NOT NULL,
    yaw REAL NOT NULL,
    grid_ix INTEGER NOT NULL,
    grid_iy INTEGER NOT NULL
);
CREATE TABLE edges (
    id INTEGER PRIMARY KEY,
    a INTEGER NOT NULL REFERENCES poses(id),
    b INTEGER NOT NULL REFERENCES poses(id)
);
CREATE TABLE classes (
    id INTEGER PRIMARY KEY,
    n_descriptors INTEGER NOT NULL,
    n_poses INTEGER NOT NULL
);
CREATE TABLE class_descriptors (
    class_id INTEGER NOT NULL REFERENCES classes(id),
    ordinal INTEGER NOT NULL,
    descriptor BLOB NOT NULL,
    PRIMARY KEY (class_id, ordinal)
) WITHOUT ROWID;
CREATE TABLE visibility (
    pose INTEGER PRIMARY KEY REFERENCES poses(id),
    class_ids BLOB NOT NULL
);
CREATE TABLE regions (
    id INTEGER PRIMARY KEY,
    n_poses INTEGER NOT NULL,
    n_landmark INTEGER NOT NULL,
    n_extra INTEGER NOT NULL,
    n_model_views INTEGER NOT NULL
);
CREATE TABLE region_poses (
    region INTEGER NOT NULL REFERENCES regions(id),
    pose INTEGER NOT NULL REFERENCES poses(id),
    PRIMARY KEY (region, pose)
) WITHOUT ROWID;
CREATE TABLE region_features (
    region INTEGER NOT NULL REFERENCES regions(id),
    class_id INTEGER NOT NULL REFERENCES classes(id),
    role TEXT NOT NULL CHECK (role IN ('landmark', 'extra')),
    ordinal INTEGER NOT NULL,
    PRIMARY KEY (region, class_id)
) WITHOUT ROWID;
CREATE INDEX region_features_by_class ON region_features (class_id, region);
CREATE TABLE model_views (
    id INTEGER PRIMARY KEY,
    region INTEGER NOT NULL REFERENCES regions(id),
    ordinal INTEGER NOT NULL,
    pose INTEGER NOT NULL REFERENCES poses(id),
    image_stamp_ns INTEGER NOT NULL,
    image_index INTEGER NOT NULL,
    x REAL NOT NULL,
    y REAL NOT NULL,
    yaw REAL NOT NULL,
    n_features INTEGER NOT NULL,
    UNIQUE (region, ordinal)
);
CREATE TABLE model_view_features (
    view INTEGER PRIMARY KEY REFERENCES model_views(id),
    class_ids BLOB NOT NULL,
    keypoints BLOB NOT NULL,
    descriptors BLOB NOT NULL
);
CREATE TABLE region_adjacency (
    region_a INTEGER NOT NULL REFERENCES regions(id),
    region_b INTEGER NOT NULL REFERENCES regions(id),
    shared_poses INTEGER NOT NULL,
    joining_edges INTEGER NOT NULL,
    PRIMARY KEY (region_a, region_b),
    CHECK (region_a < region_b)
) WITHOUT ROWID;
CREATE TABLE uncovered (
    pose INTEGER PRIMARY KEY REFERENCES poses(id)
);
CREATE TABLE scene_points (
    id INTEGER PRIMARY KEY,
    class_id INTEGER NOT NULL,
    views INTEGER NOT NULL,
    x REAL NOT NULL,
    y REAL NOT NULL,
    z REAL NOT NULL,
    descriptor BLOB NOT NULL,
    seen_x REAL,
    seen_y REAL,
    seen_radius REAL,
    patch BLOB,
    patch_axes BLOB
);
"""

REQUIRED_TABLES = (
    'meta', 'build_parameters', 'poses', 'edges', 'classes', 'class_descriptors',
    'visibility', 'regions', 'region_poses', 'region_features', 'model_views',
    'model_view_features', 'region_adjacency', 'uncovered',
)
"""Tables every version has; version 2 adds ``scene_points``."""
