"""The SQLite schema of the landmark database, version 5.

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
classes                 ``id, n_descriptors, n_poses, descriptors``: one per feature
                        class, its representative descriptors in one BLOB, whole (128
                        bytes each, uint8) or their codes (``code_size`` bytes each)
                        where ``descriptor_codebook`` has its row
visibility              ``pose, class_ids``: the classes seen from the pose (after
                        filtering), sorted little-endian ids in one BLOB, uint16 when
                        there are at most 65,536 classes, int32 otherwise; one row per
                        pose, not per pair: 1.5 million pairs took 3 s to write and 2.5 s
                        to read as rows, 0.1 s as BLOBs
regions                 ``id, n_poses, n_landmark, n_extra, n_model_views, poses,
                        landmark, extra``: the members in BLOBs of pose and class ids
                        (uint16 where the poses, or classes, number at most 65,536, int32
                        otherwise), the landmark and the extra features in their order
model_views             ``id, region, ordinal, pose, image_stamp_ns, image_index, x, y,
                        yaw, n_features``
model_view_features     ``view, class_ids, keypoints, descriptors``: little-endian BLOBs,
                        class ids ``(m,)`` (-1: none) int16 where the classes number at
                        most 32,767, int32 otherwise, float32 ``(m, 2)`` keypoints, and
                        the descriptors whole (uint8 ``(m, 128)``) or their codes
region_adjacency        ``region_a < region_b, shared_poses, joining_edges``: the region
                        graph, stored for a fast start-up and checked against the
                        regions when the database is opened
uncovered               ``pose``: k-coverable poses no region covers
scene_point_columns     ``name, dtype, shape, data``: the triangulated scene points
                        (:mod:`.points`, schema 5) one column a row, each array in the
                        narrowest NumPy dtype that holds it exactly (``shape`` a JSON
                        list): ``xyz`` (n, 3), ``class_ids`` (n,) (-1 for a point the
                        filters did not keep), ``views`` (n,), ``descriptors`` (the n
                        descriptors or codes, ``|u1``), ``seen_from`` (n, 3; absent when
                        unknown), and for the p points with a patch ``patch_points`` (p,)
                        their indices, ``patch_axes`` (p, 2, 3) and ``patches`` (p, s, s),
                        whole (``|u1``) or as the JPEG mosaics of :mod:`.patch_codec`
                        (dtype ``jpeg``)
*(schemas 1 to 4)*       ``classes`` without ``descriptors`` and ``class_descriptors``
                        (``class_id, ordinal, descriptor``) one row a descriptor;
                        visibility lists of int32; ``regions`` without members and
                        ``region_poses`` (``region, pose``) and ``region_features``
                        (``region, class_id, role, ordinal``) one row a member; model
                        view class ids int64; whole descriptors only
scene_points            schemas 2 to 4, one row a point: ``id, class_id, views, x, y, z,
                        descriptor, seen_x, seen_y, seen_radius, patch, patch_axes``
                        (128-byte descriptor; ``seen_*`` since schema 3, the patch,
                        ``s * s`` uint8, and its axes, six float32, since schema 4,
                        NULL for a point with no patch): what a file lacks is read as
                        unknown; a schema 1 file has no table and is read with no point
descriptor_codebook     ``id = 0, code_size, centroids, rms_error``: at most one row
                        (schema 5), the product quantizer of :mod:`.codebook`,
                        ``code_size * 256 * 128 / code_size`` uint8 bytes, and how far
                        the descriptors it coded moved (RMS); with the row, every
                        descriptor BLOB is a ``code_size``-byte code, without it a whole
                        descriptor
======================  ==================================================================

A new column or table that old readers could ignore still bumps the version: readers
refuse newer files rather than guess.
"""
from __future__ import annotations

__all__ = ['APPLICATION_ID', 'APPLICATION_NAME', 'REQUIRED_TABLES', 'SCHEMA_SQL',
           'SCHEMA_VERSION', 'required_tables']

SCHEMA_VERSION = 5
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
    n_poses INTEGER NOT NULL,
    descriptors BLOB NOT NULL
);
CREATE TABLE visibility (
    pose INTEGER PRIMARY KEY REFERENCES poses(id),
    class_ids BLOB NOT NULL
);
CREATE TABLE regions (
    id INTEGER PRIMARY KEY,
    n_poses INTEGER NOT NULL,
    n_landmark INTEGER NOT NULL,
    n_extra INTEGER NOT NULL,
    n_model_views INTEGER NOT NULL,
    poses BLOB NOT NULL,
    landmark BLOB NOT NULL,
    extra BLOB NOT NULL
);
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
CREATE TABLE scene_point_columns (
    name TEXT PRIMARY KEY,
    dtype TEXT NOT NULL,
    shape TEXT NOT NULL,
    data BLOB NOT NULL
);
CREATE TABLE descriptor_codebook (
    id INTEGER PRIMARY KEY CHECK (id = 0),
    code_size INTEGER NOT NULL,
    centroids BLOB NOT NULL,
    rms_error REAL NOT NULL
);
"""

REQUIRED_TABLES = (
    'meta', 'build_parameters', 'poses', 'edges', 'classes', 'visibility', 'regions',
    'model_views', 'model_view_features', 'region_adjacency', 'uncovered',
)
"""Tables every version has (:func:`required_tables` adds each version's own)."""


def required_tables(version: int) -> tuple[str, ...]:
    """Return the tables a file of schema ``version`` has."""
    if version >= 5:
        return REQUIRED_TABLES + ('scene_point_columns', 'descriptor_codebook')
    return REQUIRED_TABLES + ('class_descriptors', 'region_poses', 'region_features') \
        + (('scene_points',) if version >= 2 else ())
