"""The new heuristic ``best``: a pool of maximal candidate regions and an exact set cover.

The exact solver (:mod:`.exact`) shows that an optimum decomposition is a minimum set
cover by maximal candidate regions, the connected components of {v : L subset of F_v}.
Enumerating all of them is hopeless on large worlds, but a good *pool* of them plus a
set-cover solver beats one greedy pass:

1. **Reference and seed pool.** Run B.2, B.1 and C (Sections 5.3) on the same 0-MORDP
   instance; all their regions (each already a maximal component for its landmark)
   join the pool. The poses B.2 covers are the poses ``best`` must cover, so
   ``best`` never leaves more poses uncovered than B.2 (with sigma = 0 this is every
   k-coverable pose).
2. **Seeded greedy candidates.** Repeatedly take the required pose lying in the fewest
   pool candidates (ties: seeded priority) and grow candidates around it: for several
   radii t (a fraction, one and two times the typical radius of B.2's regions, and
   unbounded), restrict R to the required poses within graph distance t of the seed,
   choose k features of the seed greedily as in B.x (each most seen in the shrinking
   R), and add the connected component of {v : L subset of F_v} holding the seed.
   This continues until every required pose lies in at least ``multiplicity``
   candidates or ``max_seeds`` seeds were used.
3. **Set cover.** Minimum set cover of the required poses by the pool with HiGHS
   (``scipy.optimize.milp``, identical rows merged) within ``time_limit`` seconds; the
   best incumbent is used if optimality is not proven, and B.2's own solution if
   that were ever larger. The redundancy elimination of Section 5.4 finishes.

Every region is a connected component seeing its k landmark features, so the output
is valid by construction; the sigma rule acts through B.2's coverage (regions are
never added to cover B.2's sigma holes).
"""
from __future__ import annotations

from dataclasses import replace
import logging

import numpy as np

from landmark_db.decomposition.exact import solve_set_cover
from landmark_db.decomposition.neighbourhood_seeds import neighbourhood_seeds
from landmark_db.decomposition.problem import ZeroProblem, split_components
from landmark_db.decomposition.redundancy import eliminate_redundant
from landmark_db.decomposition.shrink_regions import shrink_regions
from landmark_db.errors import LandmarkDbError

__all__ = ['best_cover']

_LOG = logging.getLogger(__name__)


def best_cover(problem: ZeroProblem, alpha: float = 0.85, time_limit: float = 5.0,
               multiplicity: int = 3, max_seeds: int | None = None,
               ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Run the ``best`` heuristic on a 0-MORDP instance.

    Args:
        problem: the reduced instance.
        alpha: algorithm C's alpha (C's regions seed the pool).
        time_limit: seconds for the set-cover solver.
        multiplicity: stop seeding once every k-coverable pose lies in this many
            candidates.
        max_seeds: most seeds to grow candidates from; default ``n_poses // 4``.

    Returns:
        Regions as (sorted pose indices, k landmark columns).
    """
    n = problem.n_poses
    coverable = problem.coverable
    reference = shrink_regions(problem, 'B2')
    budget = _uncovered_count(reference, coverable)
    pool = _Pool(n)
    for region in reference:
        pool.add(*region)
    extra = shrink_regions(problem, 'B1') + neighbourhood_seeds(problem, alpha)
    if problem.sigma:
        extra += shrink_regions(replace(problem, sigma=0), 'B2')
    for region in extra:
        pool.add(*region)

    sizes = np.array([poses.size for poses, _ in pool.poses_landmarks()], dtype=float)
    typical = max(1, int(round(np.sqrt(np.median(sizes) / 2.0)))) if sizes.size else 1
    radii = sorted({max(1, typical // 2), typical, 2 * typical})
    seeds_left = max_seeds if max_seeds is not None else max(1, n // 4)
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
        for region in _grow_candidates(problem, seed, coverable, radii):
            pool.add(*region)

    required = np.flatnonzero(coverable)
    try:
        chosen, optimal = solve_set_cover(n, required, pool.poses, time_limit, budget)
    except LandmarkDbError as error:
        _LOG.warning('best: set cover failed (%s); keeping B.2', error)
        return reference
    regions = [(pool.poses[i], pool.landmarks[i]) for i in chosen]
    regions = _sigma_prune(eliminate_redundant(regions, n, problem.rng), problem, budget)
    _LOG.debug('best: %d candidates, %d regions (optimal %s, %d uncovered); B.2 %d (%d)',
               len(pool.poses), len(regions), optimal, _uncovered_count(regions, coverable),
               len(reference), budget)
    if (len(regions), _uncovered_count(regions, coverable)) > (len(reference), budget):
        return reference
    return regions


def _uncovered_count(regions: list[tuple[np.ndarray, np.ndarray]],
                     coverable: np.ndarray) -> int:
    covered = np.zeros(coverable.size, dtype=bool)
    for poses, _ in regions:
        covered[poses] = True
    return int(np.count_nonzero(coverable & ~covered))


def _sigma_prune(regions: list[tuple[np.ndarray, np.ndarray]], problem: ZeroProblem,
                 budget: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Drop regions uniquely covering at most sigma poses, fewest first, within budget.

    The k-coverable poses left uncovered never exceed ``budget`` (B.2's count).
    """
    if problem.sigma == 0 or not regions:
        return regions
    count = np.zeros(problem.n_poses, dtype=np.int64)
    for poses, _ in regions:
        count[poses] += 1
    lost = int(np.count_nonzero(problem.coverable & (count == 0)))
    alive = np.ones(len(regions), dtype=bool)
    tie = problem.rng.random(len(regions))
    while True:
        unique = np.array([np.count_nonzero(count[poses] == 1) if keep else np.iinfo(np.int64).max
                           for (poses, _), keep in zip(regions, alive)])
        low = unique.min()
        if low > problem.sigma or lost + low > budget:
            break
        lost += int(low)
        ties = np.flatnonzero(unique == low)
        drop = int(ties[np.argmax(tie[ties])])
        alive[drop] = False
        count[regions[drop][0]] -= 1
    return [region for region, keep in zip(regions, alive) if keep]


class _Pool:
    """Distinct candidate regions and how many contain each pose."""

    def __init__(self, n_poses: int) -> None:
        self.poses: list[np.ndarray] = []
        self.landmarks: list[np.ndarray] = []
        self.counts = np.zeros(n_poses, dtype=np.int64)
        self._seen: set[bytes] = set()

    def add(self, poses: np.ndarray, landmark: np.ndarray) -> None:
        key = poses.tobytes()
        if key in self._seen:
            return
        self._seen.add(key)
        self.poses.append(poses)
        self.landmarks.append(np.sort(landmark))
        self.counts[poses] += 1

    def poses_landmarks(self) -> list[tuple[np.ndarray, np.ndarray]]:
        return list(zip(self.poses, self.landmarks))


def _grow_candidates(problem: ZeroProblem, seed: int, required: np.ndarray,
                     radii: list[int]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Return candidate regions around ``seed``, one per radius plus an unbounded one."""
    layers = _bfs_layers(problem, seed, max(radii))
    allowed = problem.row_features(seed)
    out = []
    balls = [np.concatenate(layers[:t + 1]) for t in radii] + [np.flatnonzero(required)]
    for ball in balls:
        region = ball[required[ball]]
        chosen: list[int] = []
        for _ in range(problem.k):
            scores = problem.feature_counts(region)
            scores[chosen] = 0
            col = problem.best_feature(scores, allowed)
            if col < 0:
                break
            chosen.append(col)
            region = region[np.isin(region, problem.column_poses(col), assume_unique=True)]
        if len(chosen) < problem.k:
            continue
        landmark = np.asarray(chosen, dtype=np.int64)
        full = problem.poses_seeing_all(landmark)
        for piece in split_components(problem.adjacency, full):
            if np.any(piece == seed):
                out.append((piece, landmark))
                break
    return out


def _bfs_layers(problem: ZeroProblem, seed: int, depth: int) -> list[np.ndarray]:
    """Return the poses at graph distance 0, 1, ..., depth from ``seed``."""
    adjacency = problem.adjacency
    visited = np.zeros(problem.n_poses, dtype=bool)
    visited[seed] = True
    frontier = np.array([seed], dtype=np.int64)
    layers = [frontier]
    for _ in range(depth):
        starts, stops = adjacency.indptr[frontier], adjacency.indptr[frontier + 1]
        lengths = stops - starts
        if lengths.sum() == 0:
            layers.append(np.zeros(0, dtype=np.int64))
            continue
        offsets = np.repeat(starts - np.concatenate([[0], np.cumsum(lengths)[:-1]]), lengths)
        nb = np.unique(adjacency.indices[np.arange(int(lengths.sum())) + offsets])
        nb = nb[~visited[nb]]
        visited[nb] = True
        frontier = nb.astype(np.int64)
        layers.append(frontier)
    return layers
