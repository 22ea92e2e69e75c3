"""World instances of the landmark selection problem (Definitions 3.1 to 3.3).

A world instance is the tuple <G=(V, E), F, {F_v}>: sampled poses with metric
coordinates, an undirected adjacency graph between them, a set of features and, for
every pose v, its visibility set F_v. The visibility relation is stored as a sparse
boolean matrix (``scipy.sparse`` CSR, shape ``(n_poses, n_features)``, column j is
feature ``feature_ids[j]``), so that counts and intersections over thousands of poses
and features are matrix-vector products rather than Python set operations; a world
of 100,000 poses seeing about 100 features each takes about 50 MB.

Interchange JSON (fixed; other tools depend on it)::

    {
      "poses":   [[x, y], ...],            # metres ([x, y, heading], radians, in a
                                         # pose space with heading)
      "edges":   [[i, j], ...],            # undirected, indices into poses
      "visible": [[feature_id, ...], ...], # visible[i]: feature ids seen from pose i
      "spacing": 0.5,                      # optional, metres between grid poses
      "name":    "setting-2-seed-7"        # optional
    }

Feature ids are arbitrary non-negative integers; the world keeps them sorted and
unique in ``feature_ids``. Self-loop edges are accepted and ignored by the graph.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
import math
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from landmark_db.errors import LandmarkDbError
from vbn_common.jsonio import read_json_file, write_json_atomic

__all__ = [
    'WorldInstance',
    'grid_world',
    'load_world',
    'save_world',
    'world_from_dict',
    'world_to_dict',
]


@dataclass(eq=False)
class WorldInstance:
    """A world instance <G=(V, E), F, {F_v}> (Definition 3.3).

    Build one with :meth:`from_visibility`, :func:`world_from_dict`,
    :func:`load_world` or :func:`grid_world`; they validate their input.

    Attributes:
        poses: ``(n, 2)`` float pose coordinates, metres, or ``(n, 3)`` with a heading
            (radians) in a pose space with heading (a pose per position and
            heading sector for cameras that do not see all around).
        edges: ``(m, 2)`` int pose index pairs of the undirected graph G.
        feature_ids: ``(f,)`` int64 feature ids, sorted and unique.
        visible: ``(n, f)`` boolean ``scipy.sparse.csr_matrix``; ``visible[v, j]`` is
            true when feature ``feature_ids[j]`` is in F_v.
        spacing: grid spacing in metres, if the poses lie on a grid.
        name: free-form name of the world.
    """

    poses: np.ndarray
    edges: np.ndarray
    feature_ids: np.ndarray
    visible: sp.csr_matrix
    spacing: float | None = None
    name: str = ''

    @staticmethod
    def from_visibility(
        poses: Any,
        edges: Any,
        visible_bool: Any,
        feature_ids: Any = None,
        spacing: float | None = None,
        name: str = '',
    ) -> WorldInstance:
        """Build a validated world from a pose x feature visibility matrix.

        Args:
            poses: ``(n, 2)`` pose coordinates, metres.
            edges: ``(m, 2)`` pose index pairs (may be empty).
            visible_bool: ``(n, f)`` boolean matrix, dense numpy or scipy sparse.
            feature_ids: ``(f,)`` non-negative distinct ids of the columns, in any
                order (columns are reordered so that ids are sorted); default
                ``0 .. f-1``.
            spacing: optional grid spacing, metres.
            name: optional name.

        Returns:
            The world instance.

        Raises:
            LandmarkDbError: on inconsistent shapes, out-of-range edges, non-finite
                coordinates, negative or repeated feature ids.
        """
        poses_arr = _check_poses(poses)
        n = poses_arr.shape[0]
        edges_arr = _check_edges(edges, n)
        if sp.issparse(visible_bool):
            matrix = sp.csr_matrix(visible_bool, dtype=bool)
        else:
            dense = np.asarray(visible_bool)
            if dense.ndim != 2:
                raise LandmarkDbError(
                    f'visibility must be a 2-D (poses, features) matrix, got shape {dense.shape}')
            matrix = sp.csr_matrix(dense.astype(bool))
        if matrix.shape[0] != n:
            raise LandmarkDbError(
                f'visibility has {matrix.shape[0]} rows but there are {n} poses')
        f = matrix.shape[1]
        if feature_ids is None:
            ids = np.arange(f, dtype=np.int64)
        else:
            ids = _check_ids(feature_ids, 'feature_ids')
            if ids.shape != (f,):
                raise LandmarkDbError(
                    f'feature_ids has {ids.size} entries but visibility has {f} columns')
            if np.unique(ids).size != f:
                raise LandmarkDbError('feature_ids must be distinct')
            order = np.argsort(ids, kind='stable')
            if np.any(order != np.arange(f)):
                ids = ids[order]
                matrix = sp.csr_matrix(matrix[:, order])
        matrix.eliminate_zeros()
        matrix.sort_indices()
        return WorldInstance(poses_arr, edges_arr, ids, matrix,
                             _check_spacing(spacing), _check_name(name))

    @property
    def n_poses(self) -> int:
        """Number of poses |V|."""
        return int(self.poses.shape[0])

    @property
    def n_features(self) -> int:
        """Number of features |F|."""
        return int(self.feature_ids.shape[0])

    @cached_property
    def visible_csc(self) -> sp.csc_matrix:
        """The visibility matrix in CSC form (fast column access: who sees feature j)."""
        return sp.csc_matrix(self.visible)

    @cached_property
    def adjacency(self) -> sp.csr_matrix:
        """Symmetric ``(n, n)`` boolean adjacency of G without self-loops."""
        return adjacency_matrix(self.edges, self.n_poses)

    @cached_property
    def visible_counts(self) -> np.ndarray:
        """``(n,)`` int |F_v| for every pose."""
        return np.diff(self.visible.indptr).astype(np.int64)

    def visible_dense(self) -> np.ndarray:
        """Return the visibility as a dense ``(n, f)`` bool array (small worlds only)."""
        return self.visible.toarray()

    def features_of(self, pose: int) -> np.ndarray:
        """Return the sorted feature ids F_v of one pose."""
        row = self.visible.indices[self.visible.indptr[pose]:self.visible.indptr[pose + 1]]
        return self.feature_ids[np.sort(row)]

    def columns_of(self, ids: Any) -> np.ndarray:
        """Map feature ids to column indices of :attr:`visible`.

        Raises:
            LandmarkDbError: if an id is not a feature of this world.
        """
        ids_arr = np.asarray(ids, dtype=np.int64).reshape(-1)
        cols = np.searchsorted(self.feature_ids, ids_arr)
        cols = np.minimum(cols, max(self.n_features - 1, 0))
        if self.n_features == 0 or np.any(self.feature_ids[cols] != ids_arr):
            missing = ids_arr if self.n_features == 0 else ids_arr[
                self.feature_ids[cols] != ids_arr]
            raise LandmarkDbError(f'feature id {int(missing[0])} is not in the world')
        return cols


def adjacency_matrix(edges: np.ndarray, n: int) -> sp.csr_matrix:
    """Return the symmetric boolean adjacency matrix of an undirected edge list.

    Args:
        edges: ``(m, 2)`` int pose index pairs; self-loops are dropped.
        n: number of poses.

    Returns:
        ``(n, n)`` bool CSR matrix with sorted indices.
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    keep = edges[:, 0] != edges[:, 1]
    i, j = edges[keep, 0], edges[keep, 1]
    rows = np.concatenate([i, j])
    cols = np.concatenate([j, i])
    matrix = sp.csr_matrix((np.ones(rows.size, dtype=bool), (rows, cols)), shape=(n, n))
    matrix.sum_duplicates()
    matrix.sort_indices()
    return matrix


def grid_world(
    nx: int,
    ny: int,
    spacing: float,
    visible_bool: Any,
    free: Any = None,
    origin: tuple[float, float] = (0.0, 0.0),
    feature_ids: Any = None,
    name: str = '',
) -> WorldInstance:
    """Build a 4-connected grid world.

    Grid cell ``(ix, iy)`` lies at ``origin + spacing * (ix, iy)``. Poses are the free
    cells in row-major order (``iy`` major, ``ix`` minor); an edge joins every two
    free cells that are horizontally or vertically adjacent.

    Args:
        nx: number of grid columns (x).
        ny: number of grid rows (y).
        spacing: distance between adjacent grid poses, metres.
        visible_bool: ``(n_free, f)`` visibility of the free cells in pose order, or
            ``(ny * nx, f)`` / ``(ny, nx, f)`` for the whole grid (rows of blocked
            cells are then dropped).
        free: optional ``(ny, nx)`` bool mask of cells that are poses; default all.
        origin: coordinates of cell ``(0, 0)``, metres.
        feature_ids: ids of the visibility columns, default ``0 .. f-1``.
        name: optional world name.

    Returns:
        The grid world instance.

    Raises:
        LandmarkDbError: on inconsistent shapes or a non-positive spacing.
    """
    if nx < 0 or ny < 0:
        raise LandmarkDbError(f'grid size must be non-negative, got {nx} x {ny}')
    if not (isinstance(spacing, (int, float)) and math.isfinite(spacing) and spacing > 0):
        raise LandmarkDbError(f'grid spacing must be a positive number, got {spacing!r}')
    free_mask = np.ones((ny, nx), dtype=bool) if free is None else np.asarray(free, bool)
    if free_mask.shape != (ny, nx):
        raise LandmarkDbError(f'free mask has shape {free_mask.shape}, expected {(ny, nx)}')
    index = np.full((ny, nx), -1, dtype=np.int64)
    n = int(free_mask.sum())
    index[free_mask] = np.arange(n)
    iy, ix = np.nonzero(free_mask)
    poses = np.column_stack([origin[0] + spacing * ix, origin[1] + spacing * iy]).astype(float)
    pairs = []
    horizontal = free_mask[:, :-1] & free_mask[:, 1:]
    pairs.append(np.column_stack([index[:, :-1][horizontal], index[:, 1:][horizontal]]))
    vertical = free_mask[:-1, :] & free_mask[1:, :]
    pairs.append(np.column_stack([index[:-1, :][vertical], index[1:, :][vertical]]))
    edges = np.concatenate(pairs).reshape(-1, 2)
    if sp.issparse(visible_bool):
        matrix = sp.csr_matrix(visible_bool, dtype=bool)
        if matrix.shape[0] == nx * ny and n != nx * ny:
            matrix = matrix[np.flatnonzero(free_mask.reshape(-1))]
    else:
        dense = np.asarray(visible_bool, dtype=bool)
        if dense.ndim == 3:
            dense = dense.reshape(ny * nx, -1)
        if dense.ndim == 2 and dense.shape[0] == nx * ny and n != nx * ny:
            dense = dense[free_mask.reshape(-1)]
        matrix = dense
    return WorldInstance.from_visibility(poses, edges, matrix, feature_ids, spacing, name)


def world_from_dict(data: Any) -> WorldInstance:
    """Build a world from the interchange JSON structure.

    Args:
        data: the decoded JSON object.

    Returns:
        The validated world instance.

    Raises:
        LandmarkDbError: naming the first missing or invalid field.
    """
    if not isinstance(data, dict):
        raise LandmarkDbError('world must be a JSON object')
    for key in ('poses', 'edges', 'visible'):
        if key not in data:
            raise LandmarkDbError(f"world has no '{key}'")
    poses = _check_poses(data['poses'])
    n = poses.shape[0]
    edges = _check_edges(data['edges'], n)
    raw_visible = data['visible']
    if not isinstance(raw_visible, list):
        raise LandmarkDbError("world 'visible' must be a list of feature id lists")
    if len(raw_visible) != n:
        raise LandmarkDbError(
            f"world has {n} poses but 'visible' has {len(raw_visible)} entries")
    lengths = np.zeros(n, dtype=np.int64)
    flat: list[Any] = []
    for i, row in enumerate(raw_visible):
        if not isinstance(row, list):
            raise LandmarkDbError(f'visible[{i}] must be a list of feature ids')
        lengths[i] = len(row)
        flat.extend(row)
    all_ids = _check_ids(flat, 'visible')
    feature_ids = np.unique(all_ids)
    cols = np.searchsorted(feature_ids, all_ids)
    rows = np.repeat(np.arange(n), lengths)
    matrix = sp.csr_matrix((np.ones(cols.size, dtype=bool), (rows, cols)),
                           shape=(n, feature_ids.size))
    matrix.sum_duplicates()
    matrix.sort_indices()
    return WorldInstance(poses, edges, feature_ids, matrix,
                         _check_spacing(data.get('spacing')), _check_name(data.get('name', '')))


def world_to_dict(world: WorldInstance) -> dict[str, Any]:
    """Return the interchange JSON structure of a world (visible lists sorted by id)."""
    csr = world.visible
    ids = world.feature_ids[csr.indices]
    rows = np.split(ids, csr.indptr[1:-1]) if world.n_poses else []
    data: dict[str, Any] = {
        'poses': world.poses.tolist(),
        'edges': world.edges.tolist(),
        'visible': [np.sort(row).tolist() for row in rows],
    }
    if world.spacing is not None:
        data['spacing'] = world.spacing
    if world.name:
        data['name'] = world.name
    return data


def load_world(path: str | Path) -> WorldInstance:
    """Read a world instance from an interchange JSON file.

    Raises:
        LandmarkDbError: if the file is missing, not valid JSON or not a valid world.
    """
    return read_json_file(path, world_from_dict, LandmarkDbError)


def save_world(world: WorldInstance, path: str | Path) -> None:
    """Write a world as interchange JSON, atomically (temporary file, then rename)."""
    write_json_atomic(world_to_dict(world), path)


def _check_poses(raw: Any) -> np.ndarray:
    if isinstance(raw, np.ndarray):
        arr = raw
    else:
        if not isinstance(raw, (list, tuple)):
            raise LandmarkDbError("world 'poses' must be a list of [x, y] points")
        if len(raw) == 0:
            return np.zeros((0, 2), dtype=float)
        try:
            arr = np.asarray(raw)
        except (TypeError, ValueError) as error:
            raise LandmarkDbError("world 'poses' must be a list of [x, y] numbers") from error
        if arr.dtype.kind not in 'iuf':
            raise LandmarkDbError("world 'poses' must be a list of [x, y] numbers")
    if arr.size == 0:
        return np.zeros((0, 2), dtype=float)
    if arr.ndim != 2 or arr.shape[1] not in (2, 3) or arr.dtype == object:
        raise LandmarkDbError("world 'poses' must be a list of [x, y] (or [x, y, heading]) "
                              'points')
    try:
        arr = arr.astype(float)
    except (TypeError, ValueError) as error:
        raise LandmarkDbError("world 'poses' must be a list of [x, y] numbers") from error
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if bad.size:
        raise LandmarkDbError(f'pose {int(bad[0])} has non-finite coordinates')
    # One pose per place: a repeated pose would split one place's visibility in two
    # and count it twice in the service.
    _, first, counts = np.unique(arr, axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        twice = arr[first[np.argmax(counts > 1)]]
        same = np.flatnonzero((arr == twice).all(axis=1))
        place = ', '.join(f'{v:g}' for v in twice)
        raise LandmarkDbError(
            f'poses {int(same[0])} and {int(same[1])} are both at ({place}): a world has '
            'one pose per place (merge their visibility)')
    return arr


def _check_edges(raw: Any, n: int) -> np.ndarray:
    if not isinstance(raw, (list, tuple, np.ndarray)):
        raise LandmarkDbError("world 'edges' must be a list of [i, j] index pairs")
    if len(raw) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    try:
        arr = np.asarray(raw)
    except ValueError as error:
        raise LandmarkDbError("world 'edges' must be a list of [i, j] index pairs") from error
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise LandmarkDbError("world 'edges' must be a list of [i, j] index pairs")
    if arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
        if arr.dtype.kind == 'f' and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise LandmarkDbError("world 'edges' must hold integer pose indices")
    arr = arr.astype(np.int64)
    bad = np.flatnonzero(((arr < 0) | (arr >= n)).any(axis=1))
    if bad.size:
        i, j = arr[bad[0]]
        raise LandmarkDbError(
            f'edge {int(bad[0])} = [{int(i)}, {int(j)}] has a pose index out of range '
            f'(there are {n} poses)')
    return arr


def _check_ids(raw: Any, name: str) -> np.ndarray:
    if len(raw) == 0:
        return np.zeros(0, dtype=np.int64)
    if not isinstance(raw, np.ndarray) and any(
            isinstance(x, bool) or not isinstance(x, (int, np.integer)) for x in raw):
        bad = next(x for x in raw if isinstance(x, bool) or not isinstance(x, (int, np.integer)))
        raise LandmarkDbError(f'{name}: feature ids must be integers, got {bad!r}')
    try:
        arr = np.asarray(raw, dtype=np.int64)
    except (OverflowError, ValueError, TypeError) as error:
        raise LandmarkDbError(f'{name}: feature ids must be 64-bit integers') from error
    if arr.ndim != 1:
        raise LandmarkDbError(f'{name}: feature ids must be a flat list')
    if np.any(arr < 0):
        raise LandmarkDbError(f'{name}: negative feature id {int(arr[arr < 0][0])}')
    return arr


def _check_spacing(raw: Any) -> float | None:
    if raw is None:
        return None
    if (isinstance(raw, bool) or not isinstance(raw, (int, float, np.floating, np.integer))
            or not math.isfinite(raw) or raw <= 0):
        raise LandmarkDbError(f"world 'spacing' must be a positive number, got {raw!r}")
    return float(raw)


def _check_name(raw: Any) -> str:
    if not isinstance(raw, str):
        raise LandmarkDbError(f"world 'name' must be a string, got {raw!r}")
    return raw
