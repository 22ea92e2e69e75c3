"""The new heuristic ``best``: a pool of maximal candidate regions and a set cover over it.

The exact solver (:mod:`.exact`) shows that an optimum decomposition is a minimum set
cover by maximal candidate regions, the connected components of {v : L subset of F_v}.
Enumerating all of them is hopeless on large worlds, but a good *pool* of them plus a
set-cover solver beats one greedy pass:

1. **Reference and pool.** Run A.1, A.2, A.3, B.1, B.2 and C (Sections 5.2, 5.3) on
   the same 0-MORDP instance (and B.2 with sigma = 0 when sigma > 0, so that every
   k-coverable pose lies in some candidate); every region they return, widened to its
   maximal candidate (the component of {v : L subset of F_v} holding it), starts the
   pool. The reference is, with sigma = 0, the algorithm with the fewest regions
   (all serve every pose), and under the sigma rule B.2: ``best`` leaves at most as
   many k-coverable poses unserved as the reference does.
2. **Seeded greedy candidates.** Repeatedly take the k-coverable pose lying in the
   fewest candidates (ties: seeded priority) and grow candidates around it: for radii
   t of one half, one and two times the typical radius of the pool's regions,
   restrict R to the k-coverable poses within graph distance t, choose k of
   the seed's features greedily as in B.x (each the most seen in the shrinking R) and
   add the connected component of {v : L subset of F_v} holding the seed. Seeding
   stops when every k-coverable pose lies in ``multiplicity`` candidates or after
   ``max_seeds`` seeds.
3. **Partial set cover.** The fewest pool regions leaving at most B.2's number of
   k-coverable poses uncovered. With sigma = 0 that is one exact set-cover MILP (HiGHS,
   identical rows merged). With sigma > 0 the budget constraint makes the MILP slow
   to find any solution, so the LP relaxation picks the poses worth giving up, a
   set-cover MILP covers the others, and a local search (drop, two-for-one and
   coverage-gaining swap moves) improves the result within the budget.
4. **Merge rounds.** For every two touching chosen regions, a candidate aimed at the
   poses only they cover is added, and the local search is repeated.
5. **Pricing** (sigma = 0, worlds up to ``PRICING_MAX_POSES`` poses): column
   generation (:mod:`.bound`) adds the candidates the cover's LP relaxation prices
   above 1 and a last set cover runs over the grown pool; the certified lower bound
   it proves is returned in ``certificate``.
6. The redundancy elimination of Section 5.4, then regions covering at most sigma
   poses alone are dropped while the budget allows (the sigma rule, Section 5.5, read
   on the final set). If any single algorithm's result serves as many poses with
   fewer regions, that result is returned.

Every region is a connected component seeing its k landmark features, so the output
is valid by construction; it never leaves more k-coverable poses unserved than the
reference, and never has more regions than any of A.1 to C that serves at least as
many poses as it does.
"""
from __future__ import annotations

from collections.abc import Callable
import copy
from dataclasses import replace
import logging
from typing import Any

import numpy as np
import scipy.sparse as sp

from landmark_db.decomposition.bound import lower_bound
from landmark_db.decomposition.local_search import local_search
from landmark_db.decomposition.problem import (
    ZeroProblem,
    ZeroRegion,
    gather_slices,
    graph_ball,
    split_components,
)
from landmark_db.decomposition.redundancy import eliminate_redundant
from landmark_db.decomposition.set_cover import (
    cover_matrix,
    greedy_partial_cover,
    merge_identical_rows,
    relaxed_uncovered,
    solve_set_cover,
)
from landmark_db.decomposition.shrink_regions import shrink_regions
from landmark_db.defaults import DECOMPOSITION
from landmark_db.errors import LandmarkDbError
from vbn_common.workers import available_cores, map_in_processes

__all__ = ['best_cover']

_LOG = logging.getLogger(__name__)

# The local search refines the start, so its MILP need not be solved to optimality; a
# node limit (not a time limit) keeps results reproducible on any machine.
START_GAP = 0.05
START_NODES = 100
COVER_NODES = 2000  # the complete cover (sigma = 0): usually solved at the root
# The budgeted LP relaxation is degenerate; on the simulator's worlds HiGHS's dual
# simplex, without presolve, reaches an optimal vertex in about half the interior-point
# method's time (with crossover). Which optimal vertex changes the start, not the
# quality on average. Past GREEDY_START_NONZEROS entries of the (merged) cover matrix
# the LP is slow whatever the method (102k poses x 6.7k candidates, 517k entries: dual
# simplex 43 s, interior point 9 s), so the start is Chvatal's greedy cover instead:
# after the local search and the merge rounds 634 regions against the LP start's 617.
LP_METHOD = 'highs-ds'
GREEDY_START_NONZEROS = 100_000
# Column generation: rounds and branch-and-bound nodes per pricing round.
PRICING_ROUNDS = 40
PRICING_NODES = 600_000  # over all rounds
# Pricing searches bitsets over every pose; past this many poses a round costs
# seconds and proves little, so best skips it (vbn decompose --bound still runs it).
PRICING_MAX_POSES = 1000
# Seeded candidates: at most a quarter of the poses and MAX_SEEDS seeds (on 102k poses
# 8.4k seeds cost 8 s and saved 4 of 621 regions).
MAX_SEEDS = 2000
# From this many poses the algorithms run in worker processes (below it, starting the
# processes costs more than it saves).
PARALLEL_MIN_POSES = 20_000


def best_cover(problem: ZeroProblem, alpha: float = DECOMPOSITION.alpha,
               time_limit: float = DECOMPOSITION.best_time_limit, multiplicity: int = 5,
               max_seeds: int | None = None, merge_rounds: int = 3,
               pricing_rounds: int = PRICING_ROUNDS, pricing_nodes: int = PRICING_NODES,
               certificate: dict[str, Any] | None = None,
               check_stop: Callable[[], None] | None = None) -> list[ZeroRegion]:
    """Run the ``best`` heuristic on a 0-MORDP instance.

    Args:
        problem: the reduced instance.
        alpha: algorithm C's alpha (C's regions join the pool).
        time_limit: seconds for each set-cover MILP.
        multiplicity: stop seeding once every k-coverable pose lies in this many
            candidates.
        max_seeds: most seeds to grow candidates from; default ``n_poses // 4``
            and at most ``MAX_SEEDS``.
        merge_rounds: rounds of merge candidates plus local search after the cover.
        pricing_rounds: column-generation rounds (:mod:`.bound`) that grow the pool
            with the candidates the cover's LP relaxation prices best, before a last
            set cover (sigma = 0 only; 0 skips them).
        pricing_nodes: branch-and-bound nodes over all pricing rounds.
        certificate: if given, receives ``'bound'``, the certified
            :class:`~.bound.LowerBound` the pricing proved (sigma = 0 only).
        check_stop: Called between the steps (each algorithm, each batch of seeds,
            each merge round, each pricing round and every 1,024 of its nodes); what
            it raises ends the search (a builder that is shut down).

    Returns:
        The regions.
    """
    n = problem.n_poses
    coverable = problem.coverable
    cache = _ComponentCache(problem)
    stop = check_stop if check_stop is not None else _no_stop
    results = _every_algorithm(problem, alpha, stop)
    widest = results.pop(_WIDEST, [])
    # The reference: with sigma = 0 the algorithm with the fewest regions (all serve
    # every pose); under the sigma rule B.2, whose service best keeps (at least).
    reference = min(results.values(), key=len) if problem.sigma == 0 else results['B2']
    budget = _uncovered_count(reference, coverable)
    pool = _Pool(n)
    pool.reference = [pool.add(cache.maximal(region)) for region in reference]
    for regions in results.values():
        for region in regions:
            pool.add(cache.maximal(region))
    for region in widest:  # B.2 with sigma = 0: every k-coverable pose in a candidate
        pool.add(region)
    _add_seeded_candidates(problem, pool, cache, multiplicity, max_seeds, stop)

    required = np.flatnonzero(coverable)
    try:
        chosen = _partial_cover(problem, pool, required, budget, time_limit)
        for _ in range(merge_rounds):
            stop()
            if chosen is None:
                break
            added = _add_merge_candidates(problem, pool, cache, chosen)
            if not added:
                break
            matrix, weight = _merged_rows(n, required, pool.poses)
            start = np.zeros(len(pool.poses), dtype=bool)
            start[chosen] = True
            improved = np.flatnonzero(local_search(matrix, weight, start, budget))
            if improved.size >= chosen.size:
                break
            chosen = improved
    except LandmarkDbError as error:
        _LOG.warning('best: set cover failed (%s); keeping the reference', error)
        return reference
    if chosen is None:
        return reference
    if problem.sigma == 0 and pricing_rounds > 0 and n <= PRICING_MAX_POSES:
        chosen = _priced_cover(problem, pool, required, chosen, time_limit, pricing_rounds,
                               pricing_nodes, certificate, stop)
    regions = [ZeroRegion(pool.poses[i], pool.landmarks[i]) for i in chosen]
    regions = _sigma_prune(eliminate_redundant(regions, n, problem.rng), problem, budget)
    _LOG.debug('best: %d candidates, %d regions (%d uncovered); B.2 %d (%d)', len(pool.poses),
               len(regions), _uncovered_count(regions, coverable), len(reference), budget)
    if _uncovered_count(regions, coverable) > budget:
        regions = reference
    # Never worse than any algorithm serving as many poses (the pool holds their regions,
    # so this only guards against a set cover stopped at its node limit).
    unserved = _uncovered_count(regions, coverable)
    for regions_of in results.values():
        if _uncovered_count(regions_of, coverable) <= unserved and \
                len(regions_of) < len(regions):
            regions, unserved = regions_of, _uncovered_count(regions_of, coverable)
    return regions


def _priced_cover(problem: ZeroProblem, pool: _Pool, required: np.ndarray,
                  chosen: np.ndarray, time_limit: float, rounds: int, nodes: int,
                  certificate: dict[str, Any] | None,
                  stop: Callable[[], None]) -> np.ndarray:
    """Grow the pool by column generation, then cover again; keep the smaller cover."""
    columns: list[ZeroRegion] = []
    bound = lower_bound(problem, [ZeroRegion(poses, landmark) for poses, landmark
                                  in zip(pool.poses, pool.landmarks)],
                        max_rounds=rounds, node_limit=min(nodes, 50_000), total_nodes=nodes,
                        columns_out=columns, check_stop=stop)
    if certificate is not None:
        certificate['bound'] = bound
    before = len(pool.poses)
    for region in columns:
        pool.add(region)
    if len(pool.poses) == before or chosen.size <= bound.regions:
        return chosen
    try:
        again, _ = solve_set_cover(problem.n_poses, required, pool.poses, time_limit,
                                   node_limit=COVER_NODES)
    except LandmarkDbError:
        return chosen
    return again if again.size < chosen.size else chosen


def _no_stop() -> None:
    return None


def _every_algorithm(problem: ZeroProblem, alpha: float,
                     stop: Callable[[], None] = _no_stop) -> dict[str, list[ZeroRegion]]:
    """Run A.1, A.2, A.3, B.1, B.2 and C on the instance (and B.2 with sigma = 0).

    Each gets its own copy of the tie-breaking generator, so that each gives what it
    gives alone with that seed. From ``PARALLEL_MIN_POSES`` poses on they run in
    worker processes, one per core (the results are the same: 102k poses, six
    algorithms and B.2 with sigma = 0 in 10.9 s on two cores instead of 18.8 s).
    """
    names = [name for name in _RUN_ORDER if name != _WIDEST or problem.sigma]
    workers = min(len(names), available_cores())
    if problem.n_poses >= PARALLEL_MIN_POSES and workers > 1:
        runs = dict(zip(names, map_in_processes(_run_held, names, workers, initializer=_hold,
                                                initargs=(problem, alpha), check_stop=stop)))
    else:
        runs = {}
        for name in names:
            stop()
            runs[name] = _run_algorithm(problem, alpha, name)
    # In this order ties go to B.2, B.1, A.1, A.2, A.3 and C.
    return {name: runs[name] for name in _RESULT_ORDER if name in runs}


# Longest first, so that the processes finish together (times on 102k poses).
_WIDEST = 'B2 sigma 0'
_RUN_ORDER = ('A2', 'A3', _WIDEST, 'C', 'A1', 'B2', 'B1')
_RESULT_ORDER = ('B2', 'B1', 'A1', 'A2', 'A3', 'C', _WIDEST)
_HELD: dict[str, Any] = {}


def _hold(problem: ZeroProblem, alpha: float) -> None:
    """Keep the instance in a worker (sent once per worker, not once per algorithm)."""
    _HELD.update(problem=problem, alpha=alpha)


def _run_held(name: str) -> list[ZeroRegion]:
    return _run_algorithm(_HELD['problem'], _HELD['alpha'], name)


def _run_algorithm(problem: ZeroProblem, alpha: float, name: str) -> list[ZeroRegion]:
    """Run one algorithm on a copy of the instance's generator."""
    from landmark_db.decomposition.grow_regions import grow_regions
    from landmark_db.decomposition.neighbourhood_seeds import neighbourhood_seeds

    own = replace(problem, rng=copy.deepcopy(problem.rng))
    if name == _WIDEST:
        return shrink_regions(replace(own, sigma=0), 'B2')
    if name in ('B1', 'B2'):
        return shrink_regions(own, name)
    if name == 'C':
        return neighbourhood_seeds(own, alpha)
    return grow_regions(own, name)


def _partial_cover(problem: ZeroProblem, pool: _Pool, required: np.ndarray, budget: int,
                   time_limit: float) -> np.ndarray | None:
    """Fewest pool regions leaving at most ``budget`` required poses uncovered.

    With budget 0 this is one exact set-cover MILP. Otherwise the budgeted MILP is
    hard for HiGHS, so: the LP relaxation marks the poses worth giving up (relaxed
    "uncovered" value y > 1/2), the rest are covered by a MILP over the LP's support
    (on a large pool, past ``GREEDY_START_NONZEROS``, the greedy partial cover starts
    instead), and a local search on the budgeted problem improves that start (or
    B.2's own solution, if the start leaves too much uncovered): drop a region while
    the budget allows, replace two regions by one candidate, or swap one region for a
    candidate that covers more (creating slack for drops).
    """
    n = problem.n_poses
    if budget == 0:
        return solve_set_cover(n, required, pool.poses, time_limit, node_limit=COVER_NODES)[0]
    matrix, weight = _merged_rows(n, required, pool.poses)
    if matrix.nnz > GREEDY_START_NONZEROS:
        start = greedy_partial_cover(matrix, weight, budget)
    else:
        start = _relaxed_start(problem, pool, required, budget, time_limit)
    if not start.any() or _uncovered_weight(matrix, weight, start) > budget:
        start[:] = False
        start[pool.reference] = True  # B.2's own solution is always within budget
    return np.flatnonzero(local_search(matrix, weight, start, budget))


def _relaxed_start(problem: ZeroProblem, pool: _Pool, required: np.ndarray, budget: int,
                   time_limit: float) -> np.ndarray:
    """Cover the poses the LP relaxation keeps, with the LP's support and B.2's regions."""
    y, x = relaxed_uncovered(problem.n_poses, required, pool.poses, budget, method=LP_METHOD,
                             presolve=False)
    start = np.zeros(len(pool.poses), dtype=bool)
    support = np.union1d(np.flatnonzero(x > 1e-6), pool.reference).astype(np.int64)
    try:
        chosen, _ = solve_set_cover(problem.n_poses, required[y <= 0.5],
                                    [pool.poses[i] for i in support], time_limit,
                                    relative_gap=START_GAP, node_limit=START_NODES)
        start[support[chosen]] = True
    except LandmarkDbError:
        pass
    return start


def _add_merge_candidates(problem: ZeroProblem, pool: _Pool, cache: _ComponentCache,
                          chosen: np.ndarray) -> int:
    """Add candidates aimed at replacing two neighbouring chosen regions by one.

    For every pair of chosen regions that touch (share or neighbour a pose), the poses
    only they cover form R; k features are chosen greedily by how many poses of R see
    them (as in B.x), and the component of {v : L subset of F_v} meeting R most is
    added to the pool.

    Returns:
        The number of new candidates.
    """
    n = problem.n_poses
    d = chosen.size
    if d < 2:
        return 0
    membership = np.zeros(n, dtype=np.int64)
    for i in chosen:
        membership[pool.poses[i]] += 1
    owner = np.full(n, -1, dtype=np.int64)
    label_rows, label_cols = [], []
    for slot, i in enumerate(chosen):
        poses = pool.poses[i]
        owner[poses[membership[poses] == 1]] = slot
        label_rows.append(poses)
        label_cols.append(np.full(poses.size, slot))
    member = sp.csr_matrix((np.ones(sum(p.size for p in label_rows)),
                            (np.concatenate(label_rows), np.concatenate(label_cols))),
                           shape=(n, d))
    hood = (problem.adjacency.astype(np.float64) + sp.identity(n, format='csr')) @ member
    touch = (member.T @ hood).tocoo()
    pairs = {(min(a, b), max(a, b)) for a, b in zip(touch.row, touch.col) if a != b}
    before = len(pool.poses)
    for a, b in sorted(pairs):
        area = np.flatnonzero((owner == a) | (owner == b))
        if area.size == 0:
            continue
        region = area
        chosen_cols: list[int] = []
        for _ in range(problem.k):
            scores = problem.feature_counts(region)
            scores[chosen_cols] = 0
            col = problem.best_feature(scores)
            if col < 0:
                break
            chosen_cols.append(col)
            region = problem.keep_seeing(region, col)
        if len(chosen_cols) < problem.k or region.size == 0:
            continue
        landmark = np.sort(np.asarray(chosen_cols, dtype=np.int64))
        pool.add(ZeroRegion(cache.component(landmark, int(region[0])), landmark))
    return len(pool.poses) - before


def _merged_rows(n_poses: int, required: np.ndarray,
                 sets: list[np.ndarray]) -> tuple[sp.csc_matrix, np.ndarray]:
    """Return the (merged rows x sets) cover matrix and each merged row's pose count."""
    merged, members = merge_identical_rows(cover_matrix(n_poses, required, sets))
    weight = np.array([m.size for m in members], dtype=float)
    return sp.csc_matrix(merged), weight


def _uncovered_weight(matrix: sp.csc_matrix, weight: np.ndarray, chosen: np.ndarray) -> float:
    count = np.asarray(matrix[:, np.flatnonzero(chosen)].sum(axis=1)).ravel()
    return float(weight[count == 0].sum())


def _add_seeded_candidates(problem: ZeroProblem, pool: _Pool, cache: _ComponentCache,
                           multiplicity: int, max_seeds: int | None,
                           stop: Callable[[], None] = _no_stop) -> None:
    """Grow candidates around the k-coverable poses lying in the fewest candidates."""
    n = problem.n_poses
    coverable = problem.coverable
    sizes = np.array([poses.size for poses in pool.poses], dtype=float)
    typical = max(1, int(round(np.sqrt(np.median(sizes) / 2.0)))) if sizes.size else 1
    radii = sorted({max(1, typical // 2), typical, 2 * typical})
    seeds_left = max_seeds if max_seeds is not None else max(1, min(n // 4, MAX_SEEDS))
    seeded = np.zeros(n, dtype=bool)
    while seeds_left > 0:
        counts = pool.counts
        open_mask = coverable & ~seeded & (counts < multiplicity)
        if not open_mask.any():
            break
        candidates = np.flatnonzero(open_mask)
        keys = counts[candidates] * (n + 1) + problem.pose_priority[candidates]
        seed = int(candidates[np.argmin(keys)])
        seeded[seed] = True
        seeds_left -= 1
        if seeds_left % 32 == 0:
            stop()
        for region in _grow_candidates(problem, seed, coverable, cache, radii):
            pool.add(region)


def _uncovered_count(regions: list[ZeroRegion], coverable: np.ndarray) -> int:
    covered = np.zeros(coverable.size, dtype=bool)
    for region in regions:
        covered[region.poses] = True
    return int(np.count_nonzero(coverable & ~covered))


def _sigma_prune(regions: list[ZeroRegion], problem: ZeroProblem,
                 budget: int) -> list[ZeroRegion]:
    """Drop regions uniquely covering at most sigma poses, fewest first, within budget.

    The k-coverable poses left uncovered never exceed ``budget`` (B.2's count).
    """
    if problem.sigma == 0 or not regions:
        return regions
    count = np.zeros(problem.n_poses, dtype=np.int64)
    for region in regions:
        count[region.poses] += 1
    lost = int(np.count_nonzero(problem.coverable & (count == 0)))
    alive = np.ones(len(regions), dtype=bool)
    tie = problem.rng.random(len(regions))
    while True:
        unique = np.array([np.count_nonzero(count[region.poses] == 1) if keep
                           else np.iinfo(np.int64).max
                           for region, keep in zip(regions, alive)])
        low = unique.min()
        if low > problem.sigma or lost + low > budget:
            break
        lost += int(low)
        ties = np.flatnonzero(unique == low)
        drop = int(ties[np.argmax(tie[ties])])
        alive[drop] = False
        count[regions[drop].poses] -= 1
    return [region for region, keep in zip(regions, alive) if keep]


class _Pool:
    """Distinct candidate regions and how many contain each pose."""

    def __init__(self, n_poses: int) -> None:
        self.poses: list[np.ndarray] = []
        self.landmarks: list[np.ndarray] = []
        self.counts = np.zeros(n_poses, dtype=np.int64)
        self.reference: list[int] = []
        self._seen: dict[bytes, int] = {}

    def add(self, region: ZeroRegion) -> int:
        """Add a candidate (ignored if already present); return its index."""
        poses, landmark = region.poses, region.columns
        key = poses.tobytes()
        if key in self._seen:
            return self._seen[key]
        self._seen[key] = len(self.poses)
        self.poses.append(poses)
        self.landmarks.append(np.sort(landmark))
        self.counts[poses] += 1
        return len(self.poses) - 1


def _grow_candidates(problem: ZeroProblem, seed: int, coverable: np.ndarray,
                     cache: _ComponentCache,
                     radii: list[int]) -> list[ZeroRegion]:
    """Return candidate regions around ``seed``, one per ball radius."""
    ball, distance = graph_ball(problem.adjacency, seed, max(radii))
    near, near_distance = ball[coverable[ball]], distance[coverable[ball]]
    allowed = problem.row_features(seed)
    # Dense (near poses x seed features) visibility: the ball variants' greedy steps
    # become column sums of a small boolean matrix.
    csc = problem.visible_csc
    rows, lengths = gather_slices(csc.indptr, csc.indices, allowed)
    cols = np.repeat(np.arange(allowed.size), lengths)
    local_index = np.full(problem.n_poses, -1, dtype=np.int64)
    local_index[near] = np.arange(near.size)
    keep = local_index[rows] >= 0
    # float64 0/1 entries: a (members @ local) product counts exactly, through BLAS.
    local = np.zeros((near.size, allowed.size))
    local[local_index[rows[keep]], cols[keep]] = 1.0
    keys_base = problem.feature_priority[allowed]
    scale = problem.n_features + 1
    out = []
    for t in radii:
        members = (near_distance <= t).astype(np.float64)
        chosen: list[int] = []
        for _ in range(problem.k):
            scores = members @ local
            scores[chosen] = 0
            if not scores.any():
                break
            keys = np.where(scores > 0, scores.astype(np.int64) * scale + keys_base, -1)
            j = int(np.argmax(keys))
            chosen.append(j)
            members *= local[:, j]
        if len(chosen) == problem.k:
            landmark = np.sort(allowed[chosen])
            out.append(ZeroRegion(cache.component(landmark, seed), landmark))
    return out


class _ComponentCache:
    """Connected components of {v : L subset of F_v}, computed once per landmark L."""

    def __init__(self, problem: ZeroProblem) -> None:
        self.problem = problem
        self._pieces: dict[bytes, list[np.ndarray]] = {}

    def maximal(self, region: ZeroRegion) -> ZeroRegion:
        """Return the maximal candidate holding ``region``.

        Same landmark, all of its component of {v : L subset of F_v}.
        """
        landmark = np.sort(np.asarray(region.columns, dtype=np.int64))
        return ZeroRegion(self.component(landmark, int(region.poses[0])), landmark)

    def component(self, landmark: np.ndarray, seed: int) -> np.ndarray:
        """Return the component holding ``seed`` (which must see all of ``landmark``)."""
        key = landmark.tobytes()
        pieces = self._pieces.get(key)
        if pieces is None:
            pieces = split_components(self.problem.adjacency,
                                      self.problem.poses_seeing_all(landmark))
            self._pieces[key] = pieces
        for piece in pieces:
            at = int(np.searchsorted(piece, seed))
            if at < piece.size and piece[at] == seed:
                return piece
        raise AssertionError('seed does not see its landmark')
