"""Small readers of the database file's rows, shared by :mod:`.store` and :mod:`.points_sql`."""
from __future__ import annotations

import sqlite3
from typing import Any

import numpy as np

from landmark_db.errors import LandmarkDbError

__all__ = ['check_ids', 'has_table', 'rows_array']


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
