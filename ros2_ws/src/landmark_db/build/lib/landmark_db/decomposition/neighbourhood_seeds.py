"""Algorithm C: regions seeded by well-covered neighbourhoods (Section 5.3, Figure 5.3).

1. r is the largest radius such that at least half of the k-coverable poses u have
   |intersection of F_w over w in N_r(u) & U| >= k.
2. For every pose v (in pose index order): C = N_r(v) & U and F = intersection of F_u
   over C. If |C| / |N_r(v)| >= alpha and |F| >= k, choose k features greedily as in
   B.x but only from F, and add the region {v : L subset of F_v}.
3. The poses still unassigned are covered by a B.1 pass (the process the thesis
   describes but does not show), then redundancy is eliminated (Section 5.4).

Implementation notes and departures:

* The radius test is evaluated for r = 1, 2, ... with a recursion instead of
  explicit neighbourhoods: with E_r(u) = intersection of F_w over N_r(u) & U
  (the universe when that set is empty), E_r(u) = intersection of E_{r-1}(x) over
  x in N_1(u); each step is one sparse product. The search stops at a fixed point
  of that recursion (every larger r would pass too; we keep the first such r) or at
  r = 64.
* |N_r(v) & U| is kept up to date incrementally as U shrinks.
* Disconnected pieces, the sigma rule and ties follow :mod:`problem`.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from landmark_db.decomposition.overlap import neighbourhood_matrix
from landmark_db.decomposition.problem import CoverState, ZeroProblem, ZeroRegion
from landmark_db.decomposition.redundancy import eliminate_redundant
from landmark_db.decomposition.shrink_regions import choose_landmark, shrink_pass

__all__ = ['neighbourhood_radius', 'neighbourhood_seeds']

_MAX_RADIUS = 64


def neighbourhood_radius(problem: ZeroProblem) -> int:
    """Return r of line 2 of Figure 5.3 for the k-coverable poses of ``problem``."""
    unassigned = problem.coverable
    n_u = int(unassigned.sum())
    if n_u == 0:
        return 0
    one = (problem.adjacency.astype(np.int32)
           + sp.identity(problem.n_poses, dtype=np.int32, format='csr')).tocsr()
    one.data[:] = 1
    rows_u = sp.diags(unassigned.astype(np.int32), dtype=np.int32)
    sets = (rows_u @ problem.visible.astype(np.int32)).tocsr()  # E_0, zero rows off U
    sets.eliminate_zeros()
    finite = unassigned.copy()  # E_r(u) is a finite set (not the universe)
    radius = 0
    while radius < _MAX_RADIUS:
        finite_count = one @ finite.astype(np.int32)
        counts = (one @ sets).tocsr()
        counts.sort_indices()
        row_of = np.repeat(np.arange(problem.n_poses), np.diff(counts.indptr))
        keep = counts.data == finite_count[row_of]
        new_sets = sp.csr_matrix(
            (np.ones(int(keep.sum()), dtype=np.int32), (row_of[keep], counts.indices[keep])),
            shape=sets.shape)
        sizes = np.diff(new_sets.indptr)
        good = int(np.count_nonzero(unassigned & (sizes >= problem.k)))
        if 2 * good < n_u:
            break
        radius += 1
        new_finite = finite_count > 0
        if new_sets.nnz == sets.nnz and np.array_equal(new_finite, finite):
            break  # a fixed point: every larger radius gives the same sets
        sets, finite = new_sets, new_finite
    return radius


def neighbourhood_seeds(problem: ZeroProblem, alpha: float) -> list[ZeroRegion]:
    """Run algorithm C on a 0-MORDP instance.

    Args:
        problem: the reduced instance.
        alpha: the least fraction of unassigned poses in N_r(v) for v to seed a region.

    Returns:
        The regions, redundancy eliminated.
    """
    state = CoverState(problem)
    radius = neighbourhood_radius(problem)
    hood = neighbourhood_matrix(problem.adjacency, radius)
    hood_size = np.diff(hood.indptr)
    in_u = hood @ state.unassigned.astype(np.int64)
    counts_u = problem.feature_counts(np.flatnonzero(state.unassigned))
    v = 0
    n = problem.n_poses
    while v < n:
        ready = np.flatnonzero(in_u[v:] >= alpha * hood_size[v:])
        if ready.size == 0:
            break
        v += int(ready[0])
        members = hood.indices[hood.indptr[v]:hood.indptr[v + 1]]
        members = members[state.unassigned[members]]
        common = np.flatnonzero(problem.feature_counts(members) == members.size) \
            if members.size else np.zeros(0, dtype=np.int64)
        if members.size and common.size >= problem.k:
            unassigned = np.flatnonzero(state.unassigned)
            landmark = choose_landmark(problem, unassigned, counts_u, allowed=common)
            region = problem.poses_seeing_all(landmark)
            leaving = region[state.unassigned[region]]
            state.offer_components(region, np.sort(landmark))
            counts_u -= problem.feature_counts(leaving)
            if leaving.size:
                in_u -= np.bincount(hood[leaving].indices, minlength=n)
        v += 1
    shrink_pass(problem, state)
    return eliminate_redundant(state.regions, n, problem.rng)
