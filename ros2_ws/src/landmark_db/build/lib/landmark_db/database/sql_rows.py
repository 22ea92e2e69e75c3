"""Small readers of the database file's rows, shared by :mod:`.store` and :mod:`.points_sql`."""
from __future__ import annotations

import sqlite3
from typing import Any

import numpy as np

from landmark_db.database.codebook import DescriptorCodebook
from landmark_db.database.fields import DESCRIPTOR_SIZE
from landmark_db.errors import LandmarkDbError

__all__ = ['check_ids', 'descriptor_blob', 'has_table', 'load_codebook', 'read_descriptors',
           'rows_array', 'write_codebook']


def has_table(connection: sqlite3.Connection, name: str) -> bool:
    """Whether the file has table ``name``."""
    return connection.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND "
                              'name = ?', (name,)).fetchone() is not None


def rows_array(connection: sqlite3.Connection, sql: str, dtype: Any, width: int) -> np.ndarray:
    """Return the rows of ``sql`` as a ``(n, width)`` array."""
    rows = connection.execute(sql).fetchall()
    return np.array(rows, dtype=dtype).reshape(-1, width)


def check_ids(ids: np.ndarray, table: str) -> None:
    """Refuse a table whose ids are not ``0..n-1`` in order."""
    if not np.array_equal(ids, np.arange(ids.size)):
        raise LandmarkDbError(f'{table} ids are not 0..{ids.size - 1}')


def descriptor_blob(descriptors: np.ndarray, codebook: DescriptorCodebook | None) -> bytes:
    """Return the stored bytes of ``(n, 128)`` descriptors: whole, or their codes.

    Raises:
        LandmarkDbError: a descriptor its code does not give back (not quantized with
            this codebook: :meth:`~.model.LandmarkDatabase.quantized`).
    """
    if codebook is None:
        return np.ascontiguousarray(descriptors, np.uint8).tobytes()
    codes = codebook.encode(descriptors)
    if not np.array_equal(codebook.decode(codes), descriptors):
        raise LandmarkDbError('descriptors are not quantized with the database codebook '
                              '(LandmarkDatabase.quantized)')
    return codes.tobytes()


def read_descriptors(blob: bytes, codebook: DescriptorCodebook | None, what: str
                     ) -> np.ndarray:
    """Return the ``(n, 128)`` uint8 descriptors of stored bytes (decoded codes)."""
    size = DESCRIPTOR_SIZE if codebook is None else codebook.code_size
    if len(blob) % size:
        raise LandmarkDbError(f'{what} are not whole {size}-byte '
                              f'{"descriptors" if codebook is None else "codes"}')
    rows = np.frombuffer(blob, np.uint8).reshape(-1, size)
    return rows if codebook is None else codebook.decode(rows)


def write_codebook(connection: sqlite3.Connection, codebook: DescriptorCodebook | None
                   ) -> None:
    """Write the codebook's row (none without a codebook)."""
    if codebook is not None:
        connection.execute('INSERT INTO descriptor_codebook VALUES (0, ?, ?, ?)',
                           (codebook.code_size, codebook.centroids.tobytes(),
                            codebook.rms_error))


def load_codebook(connection: sqlite3.Connection) -> DescriptorCodebook | None:
    """Read the codebook (None: no row, or a file older than schema 5)."""
    if not has_table(connection, 'descriptor_codebook'):
        return None
    rows = connection.execute('SELECT id, code_size, centroids, rms_error '
                              'FROM descriptor_codebook').fetchall()
    if not rows:
        return None
    if len(rows) != 1 or rows[0][0] != 0 or not isinstance(rows[0][2], bytes) or \
            isinstance(rows[0][1], bool) or not isinstance(rows[0][1], int) or \
            rows[0][1] < 1 or len(rows[0][2]) != rows[0][1] * 256 * (
                DESCRIPTOR_SIZE // rows[0][1]):
        raise LandmarkDbError('descriptor_codebook is not one row of a code size and its '
                              'centroids')
    size = rows[0][1]
    return DescriptorCodebook(np.frombuffer(rows[0][2], np.uint8).reshape(
        size, 256, DESCRIPTOR_SIZE // size), rows[0][3])
