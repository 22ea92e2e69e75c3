"""Retain only good features: the visibility filters of Sections 6.2.2 and 8.3.2.

After Algorithm 6.3 (:mod:`visibility_builder.classes`) a class's visibility region
(the poses that see it) may be small, fragmented, thin or full of holes, and the
region decomposition inherits those defects (Section 5.3, last paragraph; Section
6.2.2). Section 8.3.2 keeps the classes that are widely and consistently visible and
trims each region to a fairly convex shape. The steps, each a parameter of
:class:`FilterConfig`, run in this order:

1. ``min_poses``: drop classes seen from fewer poses (thesis: 16).
2. ``largest_component``: keep only the largest connected component of each region,
   connectivity being the pose graph G (4-neighbours on a lattice).
3. ``convex_trim``: a pose stays if it, or one of its 8 lattice neighbours, is a
   *core* pose: a pose of the region with at least ``min_neighbours`` (7) of its 8
   lattice neighbours in the region. (The thesis says "a neighbour with at least 7 out
   of 8 of its neighbour poses in the region"; counting the pose itself as its own
   neighbour keeps the centre of a 3 x 3 block, which the literal reading would drop
   while keeping its rim.) Lattice cells without a pose (walls, obstacles) count as
   outside the region. The rule removes lines one or two poses wide and ragged edges.
4. ``min_block``: keep a class only if its region holds a full ``min_block`` x
   ``min_block`` block of lattice poses (thesis: 3 x 3).

Classes left with no pose disappear; :attr:`FilterResult.kept_classes` maps the kept
columns to the input's. The counts after every step and the region sizes before and
after (Figure 8.7) are reported.

Off-lattice poses (``grid`` row -1, e.g. poses sampled along a path) use the pose graph
instead: their neighbours are their G-neighbours, a core pose has at least
``min_neighbours / 8`` of them (and at least 3) in the region, and for ``min_block`` a
core off-lattice pose whose G-neighbours are all in the region stands for a block.

All steps are sparse matrix products over the ``(n_poses, n_classes)`` visibility
matrix, not loops over classes: O(nnz * neighbourhood) per step.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import logging

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from visibility_builder.errors import VisibilityBuilderError

__all__ = ['FilterConfig', 'FilterResult', 'FilterStep', 'retain_good_features']

logger = logging.getLogger(__name__)

# The 8 lattice neighbours of a pose, (dx, dy).
_RING = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)]


@dataclass(frozen=True)
class FilterConfig:
    """Parameters of the good-feature filters (Sections 6.2.2 and 8.3.2).

    Attributes:
        min_poses: drop classes seen from fewer poses (0 disables).
        largest_component: keep only each region's largest connected component.
        convex_trim: apply the 7-of-8 neighbour rule.
        min_neighbours: neighbours (of 8) a core pose has in the region.
        min_block: a kept region must hold a full ``min_block`` x ``min_block``
            block of lattice poses (0 or 1 disables).
    """

    min_poses: int = 16
    largest_component: bool = True
    convex_trim: bool = True
    min_neighbours: int = 7
    min_block: int = 3

    def __post_init__(self) -> None:
        for name in ('min_poses', 'min_neighbours', 'min_block'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                    or value < 0:
                raise VisibilityBuilderError(
                    f'{name} must be a non-negative integer, got {value!r}')
        if self.min_neighbours > 8:
            raise VisibilityBuilderError(
                f'min_neighbours must be at most 8, got {self.min_neighbours}')


@dataclass(frozen=True)
class FilterStep:
    """What remained after one filter step.

    Attributes:
        name: ``input``, ``min_poses``, ``largest_component``, ``convex_trim`` or
            ``min_block``.
        classes: classes seen from at least one pose.
        entries: total visibility entries (pose, class).
    """

    name: str
    classes: int
    entries: int


@dataclass
class FilterResult:
    """Visibility after the filters.

    Attributes:
        visibility: ``(n_poses, n_kept)`` bool CSR of the kept classes.
        kept_classes: ``(n_kept,)`` int64 input column of each kept class.
        steps: counts after each step, the input first.
        sizes_before: ``(n_input_classes,)`` poses per input class.
        sizes_after: ``(n_kept,)`` poses per kept class.
    """

    visibility: sp.csr_matrix
    kept_classes: np.ndarray
    steps: list[FilterStep] = field(default_factory=list)
    sizes_before: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    sizes_after: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def counts_dict(self) -> dict[str, int]:
        """``{'<step>_classes': n, '<step>_entries': m, ...}`` for logs and reports."""
        out: dict[str, int] = {}
        for step in self.steps:
            out[f'{step.name}_classes'] = step.classes
            out[f'{step.name}_entries'] = step.entries
        return out

    def size_histogram(self, bins: int | np.ndarray = 20
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Figure 8.7: region sizes before and after filtering on common bins.

        Args:
            bins: number of bins or bin edges (poses).

        Returns:
            ``(edges, counts_before, counts_after)``.
        """
        top = max(int(self.sizes_before.max(initial=1)), 1)
        edges = np.histogram_bin_edges([0, top], bins=bins) if np.isscalar(bins) \
            else np.asarray(bins, float)
        before, _ = np.histogram(self.sizes_before, bins=edges)
        after, _ = np.histogram(self.sizes_after, bins=edges)
        return edges, before, after


def retain_good_features(visibility: sp.spmatrix | np.ndarray, grid: np.ndarray,
                         edges: np.ndarray, config: FilterConfig | None = None
                         ) -> FilterResult:
    """Filter feature visibility regions (Sections 6.2.2 and 8.3.2).

    Args:
        visibility: ``(n_poses, n_classes)`` bool, pose v sees class c.
        grid: ``(n_poses, 2)`` int lattice index ``(ix, iy)`` of each pose, or
            ``(-1, -1)`` for a pose off the lattice.
        edges: ``(m, 2)`` int pose graph G (undirected).
        config: the filter parameters; defaults of :class:`FilterConfig`.

    Returns:
        The :class:`FilterResult`.

    Raises:
        VisibilityBuilderError: on inconsistent shapes, duplicate lattice indices or
            edges outside the pose range.

    Example:
        >>> block = np.ones((9, 1), bool)
        >>> grid = np.array([(x, y) for y in range(3) for x in range(3)])
        >>> edges = [(i, i + 1) for i in (0, 1, 3, 4, 6, 7)] + [(i, i + 3) for i in range(6)]
        >>> r = retain_good_features(block, grid, np.array(edges), FilterConfig(min_poses=9))
        >>> r.kept_classes.tolist(), int(r.visibility.sum())
        ([0], 9)
    """
    config = config if config is not None else FilterConfig()
    vis = sp.csr_matrix(visibility, dtype=bool)
    vis.sum_duplicates()
    vis.eliminate_zeros()
    n_poses, n_classes = vis.shape
    grid = _check_grid(grid, n_poses)
    edges = _check_edges(edges, n_poses)
    sizes_before = _sizes(vis)
    steps = [_step('input', vis)]

    if config.min_poses > 0:
        vis = _keep_columns_mask(vis, sizes_before >= config.min_poses)
        steps.append(_step('min_poses', vis))
    adjacency = _adjacency(edges, n_poses)
    if config.largest_component:
        vis = _largest_components(vis, adjacency)
        steps.append(_step('largest_component', vis))
    ring, on_lattice, ring_size = _lattice_ring(grid, adjacency)
    if config.convex_trim:
        vis = _convex_trim(vis, ring, on_lattice, ring_size, config.min_neighbours)
        steps.append(_step('convex_trim', vis))
    if config.min_block > 1:
        has_block = _has_block(vis, grid, ring, on_lattice, ring_size, config.min_block)
        vis = _keep_columns_mask(vis, has_block)
        steps.append(_step('min_block', vis))

    sizes = _sizes(vis)
    kept = np.flatnonzero(sizes > 0).astype(np.int64)
    out = sp.csr_matrix(vis[:, kept], dtype=bool)
    out.sort_indices()
    result = FilterResult(out, kept, steps, sizes_before, sizes[kept])
    logger.info('filters %s: %s', config, result.counts_dict())
    return result


# -- steps -------------------------------------------------------------------------------

def _largest_components(vis: sp.csr_matrix, adjacency: sp.csr_matrix) -> sp.csr_matrix:
    """Keep, per class, the poses of its largest connected component in G."""
    coo = vis.tocoo()
    if coo.nnz == 0:
        return vis
    n_poses, n_classes = vis.shape
    # One node per visibility entry (pose, class); entries of the same class at two
    # adjacent poses are joined. Entries are sorted by key = pose * n_classes + class.
    key = coo.row.astype(np.int64) * n_classes + coo.col
    order = np.argsort(key)
    key_sorted = key[order]
    edge_rows, edge_cols = sp.triu(adjacency, k=1).nonzero()
    shared = vis[edge_rows].multiply(vis[edge_cols]).tocoo()   # (edge, class)
    a = np.searchsorted(key_sorted, edge_rows[shared.row].astype(np.int64) * n_classes
                        + shared.col)
    b = np.searchsorted(key_sorted, edge_cols[shared.row].astype(np.int64) * n_classes
                        + shared.col)
    n_nodes = len(key_sorted)
    graph = sp.coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(n_nodes, n_nodes))
    n_comp, comp = connected_components(graph, directed=False)
    node_class = key_sorted % n_classes
    node_pose = key_sorted // n_classes
    comp_size = np.bincount(comp, minlength=n_comp)
    comp_class = np.zeros(n_comp, np.int64)
    comp_class[comp] = node_class
    # Largest component per class; ties go to the component with the smallest pose.
    comp_first = np.full(n_comp, n_poses, np.int64)
    np.minimum.at(comp_first, comp, node_pose)
    rank = np.lexsort((comp_first, -comp_size, comp_class))
    first_of_class = np.r_[True, comp_class[rank][1:] != comp_class[rank][:-1]]
    winner = np.zeros(n_comp, bool)
    winner[rank[first_of_class]] = True
    keep = winner[comp]
    return _from_entries(node_pose[keep], node_class[keep], vis.shape)


def _convex_trim(vis: sp.csr_matrix, ring: sp.csr_matrix, on_lattice: np.ndarray,
                 ring_size: np.ndarray, min_neighbours: int) -> sp.csr_matrix:
    """Keep poses that are core poses or ring neighbours of one (the 7-of-8 rule)."""
    core = _core(vis, ring, on_lattice, ring_size, min_neighbours)
    closed = ring + sp.identity(vis.shape[0], dtype=np.float32, format='csr')
    near_core = _clean(closed @ core.astype(np.float32))
    return _clean(vis.multiply(near_core))


def _core(vis: sp.csr_matrix, ring: sp.csr_matrix, on_lattice: np.ndarray,
          ring_size: np.ndarray, min_neighbours: int) -> sp.csr_matrix:
    """Poses of a region with enough of their 8 neighbours in the region."""
    counts = (ring @ vis.astype(np.float32)).tocsr()        # neighbours in the region
    # Lattice poses need min_neighbours of 8 ring cells; off-lattice poses the same
    # fraction of their graph neighbours, and at least 3 of them.
    off_need = np.maximum(np.ceil(min_neighbours / 8.0 * ring_size), 3.0)
    need = np.where(on_lattice, float(min_neighbours), off_need)
    counts = counts.multiply(vis).tocsr()
    counts.data = (counts.data >= need[np.repeat(np.arange(counts.shape[0]),
                                                 np.diff(counts.indptr))]).astype(np.float32)
    counts.eliminate_zeros()
    if min_neighbours == 0:
        return _clean(vis)
    return _clean(counts)


def _has_block(vis: sp.csr_matrix, grid: np.ndarray, ring: sp.csr_matrix,
               on_lattice: np.ndarray, ring_size: np.ndarray, size: int) -> np.ndarray:
    """Classes whose region holds a full size x size block of lattice poses."""
    n_poses, n_classes = vis.shape
    has = np.zeros(n_classes, bool)
    lattice = np.flatnonzero(on_lattice)
    if lattice.size:
        lookup = {(int(x), int(y)): int(p) for p, (x, y) in zip(lattice, grid[lattice])}
        rows, cols = [], []
        for p in lattice:
            x, y = int(grid[p, 0]), int(grid[p, 1])
            block = [lookup.get((x + dx, y + dy)) for dy in range(size) for dx in range(size)]
            if all(q is not None for q in block):
                rows.extend([p] * len(block))
                cols.extend(block)
        if rows:
            corner = sp.csr_matrix((np.ones(len(rows), np.float32), (rows, cols)),
                                   shape=(n_poses, n_poses))
            full = (corner @ vis.astype(np.float32)).tocsr()
            full.data = (full.data >= size * size - 0.5).astype(np.float32)
            full.eliminate_zeros()
            has |= np.asarray(full.sum(axis=0)).ravel() > 0
    off = ~on_lattice
    if off.any():
        # An off-lattice pose whose G-neighbours (at least 3) all see the class.
        counts = (ring @ vis.astype(np.float32)).multiply(vis).tocsr()
        row = np.repeat(np.arange(n_poses), np.diff(counts.indptr))
        good = off[row] & (ring_size[row] >= 3) & (counts.data >= ring_size[row] - 0.5)
        has[np.unique(counts.indices[good])] = True
    return has


# -- helpers -------------------------------------------------------------------------------

def _lattice_ring(grid: np.ndarray, adjacency: sp.csr_matrix
                  ) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """Build the 8-neighbour matrix: lattice ring on the lattice, G-neighbours off it.

    Returns:
        ``(ring, on_lattice, ring_size)``: ``(n, n)`` float32 CSR, ``(n,)`` bool and
        ``(n,)`` the number of possible neighbours (8 on the lattice).
    """
    n = len(grid)
    on_lattice = (grid >= 0).all(axis=1)
    lattice = np.flatnonzero(on_lattice)
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    if lattice.size:
        lo = grid[lattice].min(axis=0)
        shape = grid[lattice].max(axis=0) - lo + 3
        index = np.full((shape[1], shape[0]), -1, np.int64)  # (y, x), one-cell margin
        gx = grid[lattice, 0] - lo[0] + 1
        gy = grid[lattice, 1] - lo[1] + 1
        index[gy, gx] = lattice
        for dx, dy in _RING:
            q = index[gy + dy, gx + dx]
            ok = q >= 0
            rows.append(lattice[ok])
            cols.append(q[ok])
    off = np.flatnonzero(~on_lattice)
    if off.size:
        sub = adjacency[off].tocoo()
        rows.append(off[sub.row])
        cols.append(sub.col)
    r = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    c = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    ring = sp.csr_matrix((np.ones(len(r), np.float32), (r, c)), shape=(n, n))
    ring.sum_duplicates()
    ring.data[:] = 1.0
    ring_size = np.where(on_lattice, 8.0, np.diff(ring.indptr).astype(float))
    return ring, on_lattice, ring_size


def _adjacency(edges: np.ndarray, n: int) -> sp.csr_matrix:
    keep = edges[:, 0] != edges[:, 1]
    i, j = edges[keep, 0], edges[keep, 1]
    adj = sp.csr_matrix((np.ones(2 * len(i), np.float32), (np.r_[i, j], np.r_[j, i])),
                        shape=(n, n))
    adj.sum_duplicates()
    adj.data[:] = 1.0
    return adj


def _sizes(vis: sp.csr_matrix) -> np.ndarray:
    return np.bincount(vis.indices, minlength=vis.shape[1]).astype(np.int64)


def _step(name: str, vis: sp.csr_matrix) -> FilterStep:
    return FilterStep(name, int(np.count_nonzero(_sizes(vis))), int(vis.nnz))


def _keep_columns_mask(vis: sp.csr_matrix, keep: np.ndarray) -> sp.csr_matrix:
    return _clean(vis.multiply(keep[None, :].astype(bool)))


def _clean(matrix: sp.spmatrix) -> sp.csr_matrix:
    """CSR bool without explicit zeros (sparse products and masks may leave them)."""
    out = sp.csr_matrix(matrix, dtype=bool)
    out.eliminate_zeros()
    out.sort_indices()
    return out


def _from_entries(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> sp.csr_matrix:
    out = sp.csr_matrix((np.ones(len(rows), bool), (rows, cols)), shape=shape)
    out.sort_indices()
    return out


def _check_grid(grid: np.ndarray, n_poses: int) -> np.ndarray:
    arr = np.asarray(grid)
    if arr.size == 0 and n_poses == 0:
        return np.zeros((0, 2), np.int64)
    if arr.shape != (n_poses, 2) or not np.issubdtype(arr.dtype, np.integer):
        raise VisibilityBuilderError(
            f'grid must be an ({n_poses}, 2) integer array, got shape {arr.shape} '
            f'and dtype {arr.dtype}')
    arr = arr.astype(np.int64)
    on = (arr >= 0).all(axis=1)
    if on.any():
        _, counts = np.unique(arr[on], axis=0, return_counts=True)
        if counts.max() > 1:
            raise VisibilityBuilderError(
                f'{int(np.sum(counts > 1))} lattice cell(s) hold more than one pose')
    return arr


def _check_edges(edges: np.ndarray, n_poses: int) -> np.ndarray:
    arr = np.asarray(edges)
    if arr.size == 0:
        return np.zeros((0, 2), np.int64)
    if arr.ndim != 2 or arr.shape[1] != 2 or not np.issubdtype(arr.dtype, np.integer):
        raise VisibilityBuilderError(
            f'edges must be an (m, 2) integer array, got shape {arr.shape}, {arr.dtype}')
    if arr.min() < 0 or arr.max() >= n_poses:
        bad = int(arr.max() if arr.max() >= n_poses else arr.min())
        raise VisibilityBuilderError(f'edge pose index {bad} is outside 0 .. {n_poses - 1}')
    return arr.astype(np.int64)
