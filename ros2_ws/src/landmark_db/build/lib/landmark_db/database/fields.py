"""Checked fields of the database's dataclasses: arrays copied to their dtype and frozen.

Every dataclass of :mod:`landmark_db.database.model` validates its input in
``__post_init__`` with these helpers: numbers, strings and timestamps checked, arrays
copied into the documented dtype and shape and made read-only, indices checked against
their range, incidence matrices built; :class:`ArrayEquality` compares arrays and
sparse matrices by value.
"""
from __future__ import annotations

from dataclasses import fields
from datetime import datetime, timedelta
import json
from typing import Any

import numpy as np
import scipy.sparse as sp

from landmark_db.errors import LandmarkDbError

__all__ = [
    'DESCRIPTOR_SIZE',
    'ArrayEquality',
    'bool_csr',
    'check_range',
    'check_str',
    'check_utc',
    'descriptor_array',
    'float_array',
    'incidence',
    'int_array',
    'int_at_least',
    'json_dict',
    'positive_int',
    'read_only',
    'set_field',
]


DESCRIPTOR_SIZE = 128
"""Length of a SIFT descriptor; descriptors are stored as uint8 (SIFT's are integers)."""

class ArrayEquality:
    """Field-by-field equality that compares arrays and sparse matrices by value."""

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(values_equal(getattr(self, f.name), getattr(other, f.name))
                   for f in fields(self))  # type: ignore[arg-type]

    __hash__ = None  # type: ignore[assignment]




def set_field(obj: object, name: str, value: Any) -> None:
    object.__setattr__(obj, name, value)


def read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def values_equal(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)
                and a.dtype == b.dtype and a.shape == b.shape
                and bool(np.array_equal(a, b, equal_nan=a.dtype.kind in 'fc')))
    if sp.issparse(a) or sp.issparse(b):
        return (sp.issparse(a) and sp.issparse(b) and a.shape == b.shape
                and (a != b).nnz == 0)
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(values_equal(x, y) for x, y in zip(a, b))
    return bool(a == b)


def check_str(value: Any, name: str, nonempty: bool = False) -> None:
    if not isinstance(value, str) or (nonempty and not value):
        raise LandmarkDbError(f'{name} must be a {"non-empty " if nonempty else ""}string, '
                              f'got {value!r}')


def int_at_least(value: Any, name: str, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
        raise LandmarkDbError(f'{name} must be an integer >= {least}, got {value!r}')
    return int(value)


def positive_int(value: Any, name: str) -> int:
    return int_at_least(value, name, 1)


def check_utc(value: Any) -> None:
    check_str(value, 'created_utc', nonempty=True)
    try:
        moment = datetime.fromisoformat(value)
    except ValueError as error:
        raise LandmarkDbError(f'created_utc must be an ISO 8601 time, got {value!r}') from error
    if moment.tzinfo is not None and moment.utcoffset() != timedelta(0):
        raise LandmarkDbError(f'created_utc must be in UTC, got {value!r}')


def json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f'{type(value).__name__} is not JSON-serialisable')


def json_dict(value: Any, name: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise LandmarkDbError(f'{name} must be a dict, got {type(value).__name__}')
    try:
        text = json.dumps(value, default=json_default, allow_nan=False, sort_keys=True)
    except (TypeError, ValueError) as error:
        raise LandmarkDbError(f'{name} must be JSON-serialisable: {error}') from error
    return json.loads(text)


def _shape_ok(shape: tuple[int, ...], expected: tuple[int | None, ...]) -> bool:
    return len(shape) == len(expected) and all(
        want is None or got == want for got, want in zip(shape, expected))


def _shape_text(expected: tuple[int | None, ...]) -> str:
    return '(' + ', '.join('n' if s is None else str(s) for s in expected) + \
        (',)' if len(expected) == 1 else ')')


def _numeric(value: Any, name: str) -> np.ndarray:
    try:
        array = np.asarray(value)
    except (TypeError, ValueError) as error:
        raise LandmarkDbError(f'{name} must be a _numeric array') from error
    if array.size and (array.dtype == bool or array.dtype.kind not in 'iuf'):
        raise LandmarkDbError(f'{name} must be a _numeric array, got dtype {array.dtype}')
    return array


def float_array(value: Any, name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    array = _numeric(value, name)
    if array.size == 0:
        array = array.reshape([0 if s is None else s for s in shape])
    if not _shape_ok(array.shape, shape):
        raise LandmarkDbError(f'{name} must have shape {_shape_text(shape)}, '
                              f'got {array.shape}')
    array = np.array(array, dtype=np.float64)
    if not np.all(np.isfinite(array)):
        raise LandmarkDbError(f'{name} holds a non-finite number')
    return read_only(array)


def int_array(value: Any, name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    array = _numeric(value, name)
    if array.size == 0:
        array = np.zeros([0 if s is None else s for s in shape], dtype=np.int64)
    if not _shape_ok(array.shape, shape):
        raise LandmarkDbError(f'{name} must have shape {_shape_text(shape)}, '
                              f'got {array.shape}')
    if array.dtype.kind == 'f':
        raise LandmarkDbError(f'{name} must hold integers, got dtype {array.dtype}')
    if array.dtype.kind == 'u' and array.size and array.max() > np.iinfo(np.int64).max:
        raise LandmarkDbError(f'{name} holds an integer beyond int64')
    return read_only(np.array(array, dtype=np.int64))


def descriptor_array(value: Any, name: str) -> np.ndarray:
    array = _numeric(value, name)
    if array.size == 0:
        array = np.zeros((0, DESCRIPTOR_SIZE), dtype=np.uint8)
    if array.ndim != 2 or array.shape[1] != DESCRIPTOR_SIZE:
        raise LandmarkDbError(f'{name} must have shape (n, {DESCRIPTOR_SIZE}), '
                              f'got {array.shape}')
    if array.dtype != np.uint8:
        if not (np.all(np.isfinite(array)) and np.all(array == np.round(array))
                and array.min(initial=0) >= 0 and array.max(initial=0) <= 255):
            raise LandmarkDbError(f'{name} must hold integers 0..255 (SIFT descriptors), '
                                  f'got values outside that')
    return read_only(np.array(array, dtype=np.uint8))


def bool_csr(value: Any, name: str) -> sp.csr_matrix:
    if sp.issparse(value):
        matrix = sp.csr_matrix(value, dtype=bool, copy=True)
    else:
        dense = np.asarray(value)
        if dense.ndim != 2:
            raise LandmarkDbError(f'{name} must be a 2-D matrix, got shape {dense.shape}')
        matrix = sp.csr_matrix(dense.astype(bool))
    matrix.sum_duplicates()
    matrix.eliminate_zeros()
    matrix.sort_indices()
    return matrix


def check_range(array: np.ndarray, n: int, name: str, what: str) -> None:
    if array.size and (array.min() < 0 or array.max() >= n):
        bad = int(array[(array < 0) | (array >= n)][0])
        raise LandmarkDbError(f'{name}: {what} index {bad} out of range (there are {n})')


def incidence(rows: list[np.ndarray], n_columns: int) -> sp.csr_matrix:
    """``(len(rows), n_columns)`` bool CSR with row ``i`` set at ``rows[i]``."""
    lengths = np.array([row.size for row in rows], dtype=np.int64)
    indptr = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    indices = np.concatenate(rows).astype(np.int64) if rows else np.zeros(0, np.int64)
    matrix = sp.csr_matrix((np.ones(indices.size, dtype=bool), indices, indptr),
                           shape=(len(rows), n_columns))
    matrix.sum_duplicates()
    matrix.sort_indices()
    return matrix
