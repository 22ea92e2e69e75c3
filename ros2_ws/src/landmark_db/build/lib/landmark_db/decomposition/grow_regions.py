"""Algorithms A.1, A.2 and A.3: growing regions from seeds (Section 5.2, Figure 5.1).

While unassigned k-coverable poses remain, a seed v in U starts a region R = {v};
the region repeatedly absorbs the boundary pose u (a pose outside R adjacent to R)
whose visibility set shares the most features with the region's common set, as long
as at least k remain; boundary poses still in U are preferred. The seed is the pose
of U seeing the fewest features (A.1), the most (A.2), or a random one (A.3).

Implementation notes and departures:

* Only poses sharing at least k features with the seed can ever join its region, so
  each growth works on that candidate set with a dense local (poses x seed features)
  boolean matrix. Boundary scores are recomputed (vectorised) only when the common
  set shrinks; otherwise only the new boundary poses are scored.
* The figure leaves open which k of the region's common features form the landmark;
  we take the k common features visible from the most poses of the (reduced) world,
  ties by the seeded feature priority.
* Ties (seed choice, growth choice) use the seeded random priorities of
  :mod:`problem`. Regions are connected by construction. The sigma rule and the
  redundancy elimination of Section 5.4 are applied as for every algorithm.
"""
from __future__ import annotations

import heapq

import numpy as np

from landmark_db.decomposition.problem import CoverState, ZeroProblem, ZeroRegion, gather_slices
from landmark_db.decomposition.redundancy import eliminate_redundant
from landmark_db.errors import LandmarkDbError

__all__ = ['grow_regions']

_SEED_RULES = ('A1', 'A2', 'A3')


def grow_regions(problem: ZeroProblem, variant: str) -> list[ZeroRegion]:
    """Run algorithm A.1, A.2 or A.3 on a 0-MORDP instance.

    Args:
        problem: the reduced instance.
        variant: ``'A1'`` (fewest features first), ``'A2'`` (most) or ``'A3'`` (random).

    Returns:
        The regions, redundancy eliminated.

    Raises:
        LandmarkDbError: on an unknown ``variant``.
    """
    if variant not in _SEED_RULES:
        raise LandmarkDbError(f'unknown A.x variant {variant!r}; choose A1, A2 or A3')
    n = problem.n_poses
    state = CoverState(problem)
    candidates = np.flatnonzero(problem.coverable)
    if variant == 'A3':
        order = candidates[problem.rng.permutation(candidates.size)]
    else:
        sign = 1 if variant == 'A1' else -1
        keys = sign * problem.counts[candidates] * (n + 1) + problem.pose_priority[candidates]
        order = candidates[np.argsort(keys, kind='stable')]
    column_sizes = np.diff(problem.visible_csc.indptr)
    local_index = np.full(n, -1, dtype=np.int64)
    for seed in order:
        if not state.unassigned[seed]:
            continue
        poses, common = _grow(problem, int(seed), state.unassigned, local_index)
        keys = column_sizes[common].astype(np.int64) * (problem.n_features + 1) + \
            problem.feature_priority[common]
        landmark = np.sort(common[np.argsort(-keys, kind='stable')[:problem.k]])
        state.offer(poses, landmark)
    return eliminate_redundant(state.regions, n, problem.rng)


def _grow(problem: ZeroProblem, seed: int, unassigned: np.ndarray,
          local_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grow one region from ``seed`` (lines 4 to 14 of Figure 5.1).

    Returns:
        The region's sorted poses and its common feature columns (at least k).
    """
    k = problem.k
    seed_cols = problem.row_features(seed)
    csc = problem.visible_csc
    # Poses sharing >= k features with the seed, and their local feature matrix.
    rows, lengths = gather_slices(csc.indptr, csc.indices, seed_cols)
    col_local = np.repeat(np.arange(seed_cols.size), lengths)
    shared = np.bincount(rows, minlength=problem.n_poses)
    cand = np.flatnonzero(shared >= k)
    m = cand.size
    local_index[cand] = np.arange(m)
    keep = local_index[rows] >= 0
    local = np.zeros((m, seed_cols.size), dtype=bool)
    local[local_index[rows[keep]], col_local[keep]] = True
    sub = problem.adjacency[cand][:, cand].tocsr()
    local_unassigned = unassigned[cand]
    priority = problem.pose_priority[cand]

    start = int(local_index[seed])
    local_index[cand] = -1
    in_region = np.zeros(m, dtype=bool)
    seen = np.zeros(m, dtype=bool)  # in the region or ever on its boundary
    common = local[start].copy()
    n_common = int(common.sum())
    in_region[start] = seen[start] = True
    # Max-heap of usable boundary poses (score >= k), keyed by (still unassigned, score,
    # tie priority): exactly lines 6 to 11 of Figure 5.1. Scores only change when the
    # common set shrinks; the heap is then rebuilt from the live boundary.
    heap: list[tuple[int, int, int, int]] = []
    live: set[int] = set()

    def push(poses: np.ndarray) -> None:
        scores = np.count_nonzero(local[poses] & common, axis=1)
        for u, sc in zip(poses[scores >= k].tolist(), scores[scores >= k].tolist()):
            live.add(u)
            heapq.heappush(heap, (-int(local_unassigned[u]), -sc, -int(priority[u]), u))

    def extend_boundary(u: int) -> None:
        nb = sub.indices[sub.indptr[u]:sub.indptr[u + 1]]
        nb = nb[~seen[nb]]
        if nb.size:
            seen[nb] = True
            push(nb)

    extend_boundary(start)
    while heap:
        _, neg_score, _, u = heapq.heappop(heap)
        live.discard(u)
        in_region[u] = True
        if -neg_score < n_common:
            common &= local[u]
            n_common = -neg_score
            survivors = np.fromiter(live, dtype=np.int64, count=len(live))
            heap.clear()
            live.clear()
            if survivors.size:
                push(survivors)
        extend_boundary(u)
    return cand[np.flatnonzero(in_region)], seed_cols[common]
