"""Writing and reading the landmark database file (SQLite, schema in :mod:`.schema`).

Writing never leaves a half-written file and never touches the previous database: the
whole database is built in ONE transaction in an in-memory SQLite database, its image
(``Connection.serialize``) is written to a hidden temporary sibling of the target by
:func:`vbn_common.atomic.atomic_output`, fsynced and renamed into place, and the
folder is fsynced. A crash or ``kill -9`` while the tables are filled (nearly all of a
write) leaves nothing on disk; only one during the final copy of the finished image
(a fraction of a second) can leave a hidden ``.NAME.*.tmp`` file beside the untouched
previous database.

Reading opens the file read-only (``file:...?mode=ro``) and refuses, with one
``LandmarkDbError`` line naming the path and the problem, a missing file, a file that
is not SQLite, a truncated or damaged file (``PRAGMA quick_check``), a SQLite file of
another application (``PRAGMA application_id``), a schema version newer than
:data:`~.schema.SCHEMA_VERSION`, a missing table, and contents that break the
invariants of :mod:`.model` or disagree with themselves (counts, the stored region
graph, the content checksum that catches a changed descriptor byte or coordinate, which
SQLite's own checks cannot see). Opening never modifies the file.
:func:`database_summary` makes the file checks but reads only counts and parameters.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
import json
import logging
import os
from pathlib import Path
import sqlite3
import time
from typing import Any

import numpy as np

from landmark_db.database.build_info import BuildInfo
from landmark_db.database.model import (
    LandmarkDatabase,
    RegionAdjacency,
    SampledPoses,
)
from landmark_db.database.points_sql import insert_points, load_points
from landmark_db.database.schema import (
    APPLICATION_ID,
    APPLICATION_NAME,
    SCHEMA_SQL,
    SCHEMA_VERSION,
    required_tables,
)
from landmark_db.database.sql_rows import (
    check_ids,
    has_table,
    load_codebook,
    rows_array,
    write_codebook,
)
from landmark_db.database.tables_sql import (
    insert_classes,
    insert_regions,
    load_classes,
    load_regions,
)
from landmark_db.errors import LandmarkDbError
from vbn_common.atomic import atomic_output

__all__ = ['DatabaseSummary', 'database_image', 'database_summary', 'open_database',
           'write_database']

_LOG = logging.getLogger(__name__)

_SQLITE_MAGIC = b'SQLite format 3\x00'
# What damaged file contents raise while read: SQLite errors, undecodable text
# (UnicodeDecodeError is a ValueError), NULLs or wrong types where numbers belong.
_DAMAGE = (sqlite3.Error, ValueError, TypeError)


# --- writing ------------------------------------------------------------------------


def write_database(path: str | Path, db: LandmarkDatabase) -> None:
    """Write ``db`` to the SQLite file ``path``, atomically.

    Args:
        path: the database file; a previous file there is replaced only once the new
            one is complete and on disk.
        db: the database.

    Raises:
        LandmarkDbError: ``db`` is not a :class:`LandmarkDatabase`, the output folder
            is missing or not writable, or SQLite fails.
    """
    if not isinstance(db, LandmarkDatabase):
        raise LandmarkDbError(f'write_database needs a LandmarkDatabase, '
                              f'got {type(db).__name__}')
    start = time.perf_counter()
    image = database_image(db)
    with atomic_output(path) as temporary:
        with open(temporary, 'wb') as stream:
            stream.write(image)
    _LOG.info('wrote %s: %d regions, %d classes, %d poses, %.1f MB in %.2f s', path,
              db.n_regions, db.n_classes, db.n_poses, len(image) / 1e6,
              time.perf_counter() - start)


def database_image(db: LandmarkDatabase) -> bytes:
    """Return the bytes of the SQLite file holding ``db`` (built in memory).

    Raises:
        LandmarkDbError: if SQLite fails.
    """
    connection = sqlite3.connect(':memory:', isolation_level=None)
    try:
        connection.execute('PRAGMA foreign_keys = OFF')
        connection.execute('BEGIN')
        for statement in SCHEMA_SQL.split(';'):
            if statement.strip():
                connection.execute(statement)
        connection.execute(f'PRAGMA application_id = {APPLICATION_ID}')
        connection.execute(f'PRAGMA user_version = {SCHEMA_VERSION}')
        _insert_all(connection, db)
        connection.execute('COMMIT')
        return connection.serialize()
    except sqlite3.Error as error:
        raise LandmarkDbError(f'cannot build the database: {error}') from error
    finally:
        connection.close()


def _insert_all(connection: sqlite3.Connection, db: LandmarkDatabase) -> None:
    from landmark_db import __version__

    connection.executemany('INSERT INTO meta VALUES (?, ?)', [
        ('schema_version', str(SCHEMA_VERSION)),
        ('application', APPLICATION_NAME),
        ('writer', f'landmark_db {__version__}'),
        ('content_digest', db.content_digest()),
    ])
    _insert_build_parameters(connection, db)
    _insert_poses(connection, db.poses)
    write_codebook(connection, db.codebook)
    insert_classes(connection, db.classes, db.codebook)
    insert_regions(connection, db)
    insert_points(connection, db.points, db.codebook)


def _insert_build_parameters(connection: sqlite3.Connection, db: LandmarkDatabase) -> None:
    values = db.info.to_dict()
    values['pose_spacing'] = db.poses.spacing
    connection.executemany('INSERT INTO build_parameters VALUES (?, ?)',
                           [(key, json.dumps(value, sort_keys=True, allow_nan=False))
                            for key, value in values.items()])


def _insert_poses(connection: sqlite3.Connection, poses: SampledPoses) -> None:
    rows = zip(range(poses.n_poses), poses.xy[:, 0].tolist(), poses.xy[:, 1].tolist(),
               poses.yaw.tolist(), poses.grid[:, 0].tolist(), poses.grid[:, 1].tolist())
    connection.executemany('INSERT INTO poses VALUES (?, ?, ?, ?, ?, ?)', rows)
    connection.executemany('INSERT INTO edges VALUES (?, ?, ?)',
                           zip(range(poses.edges.shape[0]), poses.edges[:, 0].tolist(),
                               poses.edges[:, 1].tolist()))


# --- reading ------------------------------------------------------------------------


def open_database(path: str | Path) -> LandmarkDatabase:
    """Open a landmark database read-only, check it and load it whole.

    Args:
        path: the database file.

    Returns:
        The database; its :attr:`~LandmarkDatabase.adjacency` equals the stored
        region graph (checked).

    Raises:
        LandmarkDbError: one line ``'<path>: <problem>'`` (or ``'database <path> has
            schema version N, this build reads up to 1: upgrade vbn'``) when the file
            is missing, not SQLite, truncated, damaged, of another application, of a
            newer schema, or inconsistent.
    """
    start = time.perf_counter()
    with _checked_connection(path) as connection:
        try:
            digest = connection.execute(
                "SELECT value FROM meta WHERE key = 'content_digest'").fetchone()
            if digest is None:
                raise LandmarkDbError("meta 'content_digest' is missing")
            digest = digest[0]
            db, stored_adjacency = _load(connection)
        except (LandmarkDbError, *_DAMAGE) as error:
            raise LandmarkDbError(f'{path}: damaged database: {_shorten(str(error))}') \
                from error
    if digest != db.content_digest():
        raise LandmarkDbError(f'{path}: damaged database: its contents do not match their '
                              f'checksum (content_digest)')
    if stored_adjacency != db.adjacency:
        raise LandmarkDbError(f'{path}: damaged database: the stored region graph does '
                              f'not match the regions')
    _LOG.debug('opened %s in %.3f s', path, time.perf_counter() - start)
    return db


@dataclass(frozen=True)
class DatabaseSummary:
    """What ``vbn db-info`` shows, read without loading the database.

    Attributes:
        path: the file.
        file_bytes: the file's size.
        schema_version: its schema version.
        counts: rows per kind (``poses``, ``classes``, ``regions``, ...).
        table_bytes: bytes per table including its indexes (empty when this SQLite
            lacks the ``dbstat`` table).
        build: the build parameters (decoded JSON, :class:`BuildInfo` fields plus
            ``pose_spacing``).
    """

    path: str
    file_bytes: int
    schema_version: int
    counts: dict[str, int] = field(default_factory=dict)
    table_bytes: dict[str, int] = field(default_factory=dict)
    build: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready dict."""
        return {'path': self.path, 'file_bytes': self.file_bytes,
                'schema_version': self.schema_version, 'counts': dict(self.counts),
                'table_bytes': dict(self.table_bytes), 'build': dict(self.build)}


_COUNT_QUERIES = {
    'poses': 'SELECT COUNT(*) FROM poses',
    'edges': 'SELECT COUNT(*) FROM edges',
    'classes': 'SELECT COUNT(*) FROM classes',
    'class_descriptors': 'SELECT COALESCE(SUM(n_descriptors), 0) FROM classes',
    'visibility': 'SELECT COALESCE(SUM(n_poses), 0) FROM classes',
    'regions': 'SELECT COUNT(*) FROM regions',
    'region_poses': 'SELECT COALESCE(SUM(n_poses), 0) FROM regions',
    'landmark_features': 'SELECT COALESCE(SUM(n_landmark), 0) FROM regions',
    'extra_features': 'SELECT COALESCE(SUM(n_extra), 0) FROM regions',
    'model_views': 'SELECT COUNT(*) FROM model_views',
    'model_view_features': 'SELECT COALESCE(SUM(n_features), 0) FROM model_views',
    'region_adjacency': 'SELECT COUNT(*) FROM region_adjacency',
    'uncovered': 'SELECT COUNT(*) FROM uncovered',
}
# The scene points of schemas 2 to 4 and of schema 5 (counted when the file has them).
_POINT_COUNT = 'SELECT COUNT(*) FROM scene_points'
_POINT_SHAPE = "SELECT shape FROM scene_point_columns WHERE name = 'xyz'"


def database_summary(path: str | Path) -> DatabaseSummary:
    """Summarise a database (counts, sizes, parameters) after the same checks as opening.

    Only counts and the build parameters are read, so this is fast on big files.

    Raises:
        LandmarkDbError: as :func:`open_database` for a missing, foreign, newer or
            damaged file.
    """
    with _checked_connection(path) as connection:
        try:
            counts = {name: int(connection.execute(sql).fetchone()[0])
                      for name, sql in _COUNT_QUERIES.items()}
            if has_table(connection, 'scene_points'):
                counts['scene_points'] = int(connection.execute(_POINT_COUNT).fetchone()[0])
            code = connection.execute('SELECT code_size FROM descriptor_codebook'
                                      ).fetchone() if has_table(
                connection, 'descriptor_codebook') else None
            counts['descriptor_bytes'] = int(code[0]) if code else 128
            if has_table(connection, 'scene_point_columns'):
                shape = connection.execute(_POINT_SHAPE).fetchone()
                counts['scene_points'] = int(json.loads(shape[0])[0]) if shape else 0
            build = {key: json.loads(value) for key, value in connection.execute(
                'SELECT key, value FROM build_parameters ORDER BY key')}
            table_bytes = _table_bytes(connection)
            version = int(connection.execute('PRAGMA user_version').fetchone()[0])
        except _DAMAGE as error:
            raise LandmarkDbError(f'{path}: damaged database: {_shorten(str(error))}') \
                from error
    return DatabaseSummary(str(path), Path(path).stat().st_size, version, counts,
                           table_bytes, build)


def _table_bytes(connection: sqlite3.Connection) -> dict[str, int]:
    """Bytes per table, its indexes included (``dbstat``), or {} without ``dbstat``."""
    try:
        rows = connection.execute(
            'SELECT COALESCE(m.tbl_name, s.name), SUM(s.pgsize) FROM dbstat AS s '
            'LEFT JOIN sqlite_master AS m ON m.name = s.name '
            'GROUP BY COALESCE(m.tbl_name, s.name) ORDER BY 1').fetchall()
    except sqlite3.OperationalError:
        return {}
    return {str(name): int(size) for name, size in rows}


@contextmanager
def _checked_connection(path: str | Path) -> Iterator[sqlite3.Connection]:
    """Open ``path`` read-only after checking that it is a landmark database we read."""
    target = Path(path)
    try:
        with open(target, 'rb') as stream:
            header = stream.read(100)
            size = os.fstat(stream.fileno()).st_size
    except FileNotFoundError as error:
        raise LandmarkDbError(f'{path}: no such file') from error
    except IsADirectoryError as error:
        raise LandmarkDbError(f'{path}: is a folder, not a landmark database') from error
    except OSError as error:
        raise LandmarkDbError(f'{path}: cannot read ({error.strerror})') from error
    if not header:
        raise LandmarkDbError(f'{path}: empty file, not a landmark database')
    if not header.startswith(_SQLITE_MAGIC):
        raise LandmarkDbError(f'{path}: not a SQLite database')
    if len(header) < 100:
        raise LandmarkDbError(f'{path}: truncated file ({len(header)} bytes)')
    expected = _size_in_header(header)
    if expected is not None and size < expected:
        raise LandmarkDbError(f'{path}: truncated file ({size} bytes, its header says '
                              f'{expected})')
    uri = target.resolve().as_uri() + '?mode=ro'
    try:
        connection = sqlite3.connect(uri, uri=True)
    except sqlite3.Error as error:
        raise LandmarkDbError(f'{path}: cannot open ({error})') from error
    try:
        _check_file(connection, path)
        yield connection
    finally:
        connection.close()


def _size_in_header(header: bytes) -> int | None:
    """File size the SQLite header records, or None when that field is not valid.

    The page count at offset 28 is valid when the change counter (offset 24) equals
    the version-valid-for number (offset 92), as every file this module writes has.
    """
    page_size = int.from_bytes(header[16:18], 'big')
    page_size = 65536 if page_size == 1 else page_size
    if header[24:28] != header[92:96]:
        return None
    return page_size * int.from_bytes(header[28:32], 'big')


def _check_file(connection: sqlite3.Connection, path: str | Path) -> None:
    def pragma(name: str) -> Any:
        return connection.execute(f'PRAGMA {name}').fetchone()[0]

    try:
        application_id = pragma('application_id')
        if application_id != APPLICATION_ID:
            raise LandmarkDbError(
                f'{path}: not a landmark database (a SQLite file of another application: '
                f'application_id {application_id:#x}, expected {APPLICATION_ID:#x})')
        version = pragma('user_version')
        if version > SCHEMA_VERSION:
            raise LandmarkDbError(
                f'database {path} has schema version {version}, this build reads up to '
                f'{SCHEMA_VERSION}: upgrade vbn')
        if version < 1:
            raise LandmarkDbError(f'{path}: invalid schema version {version}')
        problems = [row[0] for row in connection.execute('PRAGMA quick_check(5)')]
        if problems != ['ok']:
            detail = ' '.join(' '.join(problems).replace('*** in database main ***', '')
                              .split())
            raise LandmarkDbError(f'{path}: damaged database ({_shorten(detail)})')
        tables = {row[0] for row in connection.execute(
            "SELECT name FROM sqlite_master WHERE type = 'table'")}
        required = required_tables(version)
        missing = [name for name in required if name not in tables]
        if missing:
            raise LandmarkDbError(f'{path}: damaged database: table {missing[0]!r} is '
                                  f'missing')
        meta = dict(connection.execute('SELECT key, value FROM meta'))
        if meta.get('application') != APPLICATION_NAME:
            raise LandmarkDbError(f'{path}: not a landmark database (meta application '
                                  f'{_shorten(repr(meta.get("application")), 60)})')
        if meta.get('schema_version') != str(version):
            raise LandmarkDbError(
                f'{path}: damaged database: meta schema_version '
                f'{_shorten(repr(meta.get("schema_version")), 60)} differs from '
                f'user_version {version}')
    except _DAMAGE as error:
        raise LandmarkDbError(
            f'{path}: damaged or not a SQLite database ({_shorten(str(error))})') from error


def _shorten(text: str, limit: int = 160) -> str:
    """One printable line of at most ``limit`` characters (SQLite may quote raw bytes)."""
    text = text.split(' with text ', 1)[0]
    text = ''.join(c if c.isprintable() else '?' for c in ' '.join(text.split()))
    return text if len(text) <= limit else text[:limit - 3] + '...'


def _load(connection: sqlite3.Connection) -> tuple[LandmarkDatabase, RegionAdjacency]:
    build = {key: json.loads(value) for key, value in
             connection.execute('SELECT key, value FROM build_parameters')}
    if 'pose_spacing' not in build:
        raise LandmarkDbError("build parameter 'pose_spacing' is missing")
    info = BuildInfo.from_dict(build)

    ints = rows_array(connection, 'SELECT id, grid_ix, grid_iy FROM poses ORDER BY id',
                  np.int64, 3)
    check_ids(ints[:, 0], 'poses')
    reals = rows_array(connection, 'SELECT x, y, yaw FROM poses ORDER BY id', np.float64, 3)
    edges = rows_array(connection, 'SELECT id, a, b FROM edges ORDER BY id', np.int64, 3)
    check_ids(edges[:, 0], 'edges')
    poses = SampledPoses(reals[:, :2], reals[:, 2], ints[:, 1:], edges[:, 1:],
                         build['pose_spacing'])
    n = poses.n_poses

    codebook = load_codebook(connection)
    version = int(connection.execute('PRAGMA user_version').fetchone()[0])
    classes = load_classes(connection, version, n, codebook)
    regions = load_regions(connection, version, n, classes.n_classes, codebook)
    uncovered = rows_array(connection, 'SELECT pose FROM uncovered ORDER BY pose', np.int64, 1)
    db = LandmarkDatabase(info, poses, classes, regions, uncovered[:, 0],
                          load_points(connection, codebook), codebook)
    stored = rows_array(connection, 'SELECT region_a, region_b, shared_poses, joining_edges '
                    'FROM region_adjacency ORDER BY region_a, region_b', np.int64, 4)
    return db, RegionAdjacency(stored[:, :2], stored[:, 2], stored[:, 3])
