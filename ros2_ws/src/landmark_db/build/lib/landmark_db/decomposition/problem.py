"""The 0-MORDP instance every algorithm works on, and the bookkeeping they share.

Every algorithm solves rho-MORDP through 0-MORDP (Section 4.1): :func:`zero_problem`
replaces each visibility set F_v by the reduced set F~_v (Theorem 4.1) and marks the
k-coverable poses (Section 5.1) on the reduced sets; the algorithms decompose that
instance; :mod:`landmark_db.decomposition.overlap` expands the regions back
(Theorem 4.2).

Shared rules, implemented once here:

* **Sigma rule (Section 5.5).** :meth:`CoverState.offer` adds a region only if the
  number of still-unassigned poses it covers is greater than sigma. Either way those
  poses leave the unassigned set U (line "U = U - R" of Figures 5.1 to 5.3 precedes the
  addition), so an algorithm always makes progress; poses left out this way are
  reported as ``uncovered`` unless a later region happens to cover them.
* **Disconnected pieces (Definition 3.4).** When a rule like R = {v : L subset of F_v}
  yields several connected components, :meth:`CoverState.offer_components` keeps
  *each component that contains unassigned poses* as its own region with the same
  landmark L (each judged separately by the sigma rule); components holding no
  unassigned pose are dropped as redundant. Keeping all useful components costs one
  region per piece, exactly what covering the other pieces later with the same L
  would cost, and saves the repeated search.
* **Ties** are broken by a random priority per pose and per feature drawn once from
  the seeded generator, so equal scores resolve uniformly at random and every run
  with the same seed is identical.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from landmark_db.decomposition.coverable import coverable_poses
from landmark_db.decomposition.overlap import reduce_visibility
from landmark_db.world import WorldInstance

__all__ = ['CoverState', 'ZeroProblem', 'ZeroRegion', 'component_of', 'gather_slices',
           'graph_ball', 'induced_subgraph', 'split_components', 'zero_problem']


@dataclass(frozen=True, eq=False)
class ZeroRegion:
    """One region of a 0-MORDP decomposition, as every algorithm returns it.

    Unlike :class:`~landmark_db.decomposition.model.Region` (the output: poses
    expanded back under rho, landmark as feature *ids*), this is the region on the
    reduced instance with its landmark as *columns* of ``ZeroProblem.visible``;
    :func:`~landmark_db.decomposition.decompose` turns one into the other.

    Attributes:
        poses: sorted unique int64 pose indices, a connected set.
        columns: the landmark: k sorted int64 feature columns seen (in the reduced
            sets F~_v) from every pose of ``poses``.
    """

    poses: np.ndarray
    columns: np.ndarray


@dataclass(eq=False)
class ZeroProblem:
    """A 0-MORDP instance: the graph, reduced visibility and the k-coverable poses.

    Attributes:
        adjacency: ``(n, n)`` bool CSR adjacency of G (no self-loops).
        visible: ``(n, f)`` bool CSR reduced visibility F~_v (F_v when rho = 0).
        visible_csc: the same matrix in CSC form.
        counts: ``(n,)`` int |F~_v|.
        coverable: ``(n,)`` bool, |F~_v| >= k.
        k: landmark size.
        sigma: sigma of the sigma rule.
        rng: the seeded generator.
        pose_priority: ``(n,)`` int64 random permutation used to break ties.
        feature_priority: ``(f,)`` int64 random permutation used to break ties.
    """

    adjacency: sp.csr_matrix
    visible: sp.csr_matrix
    visible_csc: sp.csc_matrix
    counts: np.ndarray
    coverable: np.ndarray
    k: int
    sigma: int
    rng: np.random.Generator
    pose_priority: np.ndarray
    feature_priority: np.ndarray
    _scratch: np.ndarray | None = None
    _visible_t: sp.csr_matrix | None = None

    @property
    def n_poses(self) -> int:
        """Number of poses."""
        return int(self.counts.size)

    @property
    def n_features(self) -> int:
        """Number of features (columns)."""
        return int(self.visible.shape[1])

    def column_poses(self, col: int) -> np.ndarray:
        """Return the sorted poses whose (reduced) visibility set holds column ``col``."""
        csc = self.visible_csc
        return csc.indices[csc.indptr[col]:csc.indptr[col + 1]]

    def row_features(self, pose: int) -> np.ndarray:
        """Return the sorted feature columns of F~_v for one pose."""
        csr = self.visible
        return csr.indices[csr.indptr[pose]:csr.indptr[pose + 1]]

    def feature_counts(self, poses: np.ndarray) -> np.ndarray:
        """Return ``(f,)`` counts of how many of ``poses`` see each feature column."""
        csr = self.visible
        if poses.size == 0:
            return np.zeros(self.n_features, dtype=np.int64)
        starts = csr.indptr[poses]
        stops = csr.indptr[poses + 1]
        lengths = stops - starts
        total = int(lengths.sum())
        if total == 0:
            return np.zeros(self.n_features, dtype=np.int64)
        if 4 * total > csr.nnz:
            # Many poses: one sparse product over all of F~ beats gathering their rows
            # (exact: float64 sums of 0/1 values).
            if self._visible_t is None:
                self._visible_t = sp.csr_matrix(csr.T, dtype=np.float64)
            weight = np.bincount(poses, minlength=self.n_poses).astype(np.float64)
            return (self._visible_t @ weight).astype(np.int64)
        cols, _ = gather_slices(csr.indptr, csr.indices, poses)
        return np.bincount(cols, minlength=self.n_features)

    def keep_seeing(self, poses: np.ndarray, col: int) -> np.ndarray:
        """Return the poses of ``poses`` whose (reduced) visibility set holds ``col``."""
        if self._scratch is None:
            self._scratch = np.zeros(self.n_poses, dtype=bool)
        seen = self.column_poses(col)
        self._scratch[seen] = True
        kept = poses[self._scratch[poses]]
        self._scratch[seen] = False
        return kept

    def poses_seeing_all(self, cols: np.ndarray) -> np.ndarray:
        """Return the sorted poses v with every column of ``cols`` in F~_v."""
        sizes = [self.column_poses(int(c)).size for c in cols]
        order = np.argsort(sizes)
        poses = self.column_poses(int(cols[order[0]]))
        for j in order[1:]:
            if poses.size == 0:
                break
            poses = self.keep_seeing(poses, int(cols[j]))
        return poses

    def best_feature(self, scores: np.ndarray, allowed: np.ndarray | None = None) -> int:
        """Return the column with the largest score (random tie-break), or -1.

        Args:
            scores: ``(f,)`` non-negative integer scores; columns with score 0 are
                never chosen.
            allowed: optional candidate columns; default all.
        """
        if allowed is None:
            allowed = np.flatnonzero(scores > 0)
        else:
            allowed = allowed[scores[allowed] > 0]
        if allowed.size == 0:
            return -1
        keys = scores[allowed].astype(np.int64) * (self.n_features + 1) + \
            self.feature_priority[allowed]
        return int(allowed[np.argmax(keys)])


def zero_problem(world: WorldInstance, k: int, rho: int, sigma: int,
                 rng: np.random.Generator) -> ZeroProblem:
    """Build the 0-MORDP instance of a rho-MORDP instance (Theorem 4.1).

    Args:
        world: the world instance.
        k: landmark size (>= 1).
        rho: overlap (>= 0); the visibility sets are replaced by their rho-reduction.
        sigma: sigma of the sigma rule (>= 0).
        rng: seeded generator.

    Returns:
        The reduced instance.
    """
    visible = world.visible if rho == 0 else reduce_visibility(world.adjacency, world.visible,
                                                               rho)
    counts = np.diff(visible.indptr).astype(np.int64)
    return ZeroProblem(
        adjacency=world.adjacency,
        visible=visible,
        visible_csc=world.visible_csc if rho == 0 else sp.csc_matrix(visible),
        counts=counts,
        coverable=coverable_poses(visible, k),
        k=int(k),
        sigma=int(sigma),
        rng=rng,
        pose_priority=rng.permutation(world.n_poses).astype(np.int64),
        feature_priority=rng.permutation(world.n_features).astype(np.int64),
    )


def gather_slices(indptr: np.ndarray, indices: np.ndarray,
                  selected: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate the index slices of selected rows (CSR) or columns (CSC), vectorised.

    Args:
        indptr: the sparse matrix's ``indptr``.
        indices: the sparse matrix's ``indices``.
        selected: the rows (CSR) or columns (CSC) to gather, in the order wanted.

    Returns:
        ``(entries, lengths)``: the indices of every selected slice, one after the other,
        and each slice's length (``np.repeat(np.arange(len(selected)), lengths)`` says
        which selected slice each entry came from).

    Example:
        For a CSC visibility matrix, ``gather_slices(csc.indptr, csc.indices, cols)``
        gives the poses seeing each feature column of ``cols``.
    """
    starts = indptr[selected]
    lengths = indptr[selected + 1] - starts
    offsets = np.repeat(starts - np.concatenate([[0], np.cumsum(lengths)[:-1]]), lengths)
    return indices[np.arange(int(lengths.sum())) + offsets], lengths


def graph_ball(adjacency: sp.csr_matrix, seed: int,
               radius: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the poses within ``radius`` graph steps of ``seed`` and their distances.

    A breadth-first search level by level, costing the size of the ball (not of the
    graph, as a full-length distance array would).

    Returns:
        ``(poses, steps)``: sorted pose indices and each one's distance in steps.
    """
    seen = np.zeros(adjacency.shape[0], dtype=bool)  # calloc'd: no O(n) pass
    seen[seed] = True
    found = [np.array([seed], dtype=np.int64)]
    steps = [np.zeros(1, dtype=np.int64)]
    frontier = found[0]
    for level in range(1, radius + 1):
        neighbours = gather_slices(adjacency.indptr, adjacency.indices, frontier)[0]
        frontier = np.unique(neighbours[~seen[neighbours]])
        if frontier.size == 0:
            break
        seen[frontier] = True
        found.append(frontier)
        steps.append(np.full(frontier.size, level, dtype=np.int64))
    poses, distance = np.concatenate(found), np.concatenate(steps)
    order = np.argsort(poses)
    return poses[order], distance[order]


def induced_subgraph(adjacency: sp.csr_matrix, poses: np.ndarray) -> sp.csr_matrix:
    """Return the adjacency (float64 CSR) of the subgraph induced by sorted ``poses``."""
    # Local indices by binary search: no (n,) scratch array per call (a seeded search
    # on 100k poses calls this tens of thousands of times).
    neighbours, lengths = gather_slices(adjacency.indptr, adjacency.indices, poses)
    targets = np.minimum(np.searchsorted(poses, neighbours), poses.size - 1)
    keep = poses[targets] == neighbours
    sources = np.repeat(np.arange(poses.size), lengths)
    kept_per_row = np.bincount(sources[keep], minlength=poses.size)
    indptr = np.concatenate([[0], np.cumsum(kept_per_row)]).astype(np.int32)
    return sp.csr_matrix((np.ones(int(indptr[-1])), targets[keep], indptr),
                         shape=(poses.size, poses.size))


def split_components(adjacency: sp.csr_matrix, poses: np.ndarray) -> list[np.ndarray]:
    """Split a pose set into the connected components of its induced subgraph.

    Args:
        adjacency: ``(n, n)`` adjacency of G.
        poses: sorted unique pose indices.

    Returns:
        One sorted pose index array per component, largest first.
    """
    if poses.size <= 1:
        return [poses] if poses.size else []
    n_comp, labels = csgraph.connected_components(induced_subgraph(adjacency, poses),
                                                  directed=False)
    if n_comp == 1:
        return [poses]
    order = np.argsort(labels, kind='stable')
    bounds = np.flatnonzero(np.diff(labels[order])) + 1
    pieces = [poses[np.sort(chunk)] for chunk in np.split(order, bounds)]
    pieces.sort(key=lambda piece: -piece.size)
    return pieces


def component_of(adjacency: sp.csr_matrix, poses: np.ndarray, seed: int) -> np.ndarray:
    """Return the connected component of ``seed`` in the subgraph induced by ``poses``."""
    sub = induced_subgraph(adjacency, poses)
    start = int(np.searchsorted(poses, seed))
    order = csgraph.breadth_first_order(sub, start, directed=False, return_predecessors=False)
    return poses[np.sort(order)]


@dataclass(eq=False)
class CoverState:
    """Unassigned poses U, the kept regions and the sigma rule (Section 5.5).

    Attributes:
        problem: the 0-MORDP instance.
        unassigned: ``(n,)`` bool, the set U.
        regions: the kept regions.
    """

    problem: ZeroProblem
    unassigned: np.ndarray = field(init=False)
    regions: list[ZeroRegion] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        self.unassigned = self.problem.coverable.copy()

    def offer(self, poses: np.ndarray, cols: np.ndarray) -> bool:
        """Offer one connected region; keep it if it covers more than sigma of U.

        The region's poses leave U whether or not it is kept.

        Returns:
            Whether the region was kept.
        """
        gain = int(np.count_nonzero(self.unassigned[poses]))
        self.unassigned[poses] = False
        if gain > self.problem.sigma and gain > 0:
            self.regions.append(ZeroRegion(poses, np.asarray(cols, dtype=np.int64)))
            return True
        return False

    def offer_components(self, poses: np.ndarray, cols: np.ndarray) -> list[int]:
        """Offer every connected component of ``poses`` holding unassigned poses.

        Returns:
            The indices in :attr:`regions` of the components that were kept.
        """
        kept = []
        for piece in split_components(self.problem.adjacency, poses):
            if not self.unassigned[piece].any():
                continue
            if self.offer(piece, cols):
                kept.append(len(self.regions) - 1)
        return kept
