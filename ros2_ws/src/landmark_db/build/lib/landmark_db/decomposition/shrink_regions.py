"""Algorithms B.1 and B.2: shrink regions until k features are seen (Sec. 5.3, Fig. 5.2).

While unassigned k-coverable poses remain: start from R = U and L = {}; k times pick
the feature not in L seen by the most poses of R (ties: seeded random priority),
shrink R to the poses seeing it and add it to L. The new region is every pose, assigned
or not, that sees all of L: {v : L subset of F_v}.

* **Disconnected pieces.** That set need not be connected (the thesis assumes convex
  visibility areas; Section 5.3, last paragraph). Each connected component that holds
  unassigned poses becomes its own region with the same landmark L (see
  :mod:`landmark_db.decomposition.problem`).
* **B.1** keeps D as it is and then runs the redundancy elimination of Section 5.4.
* **B.2** purges D after each addition, in the manner of Altgreedy: it repeatedly
  removes the region (other than the ones just added) that would leave the fewest
  poses unassigned, as long as the total count of poses that become unassigned stays
  strictly below the count of poses the new region(s) newly covered (footnote 1 of
  Section 5.3: the number of assigned poses strictly increases, so B.2 terminates).
  Poses a purge leaves unassigned return to U. Per-region counts of uniquely covered
  poses are maintained incrementally (a pose covered once knows its owner as the sum
  of the ids of the regions covering it), so a purge step costs O(|R|), not O(|D|).

:func:`shrink_pass` is reused by algorithm C for the poses it leaves unassigned.
"""
from __future__ import annotations

import numpy as np

from landmark_db.decomposition.problem import CoverState, ZeroProblem, ZeroRegion
from landmark_db.decomposition.redundancy import eliminate_redundant
from landmark_db.errors import LandmarkDbError

__all__ = ['choose_landmark', 'shrink_pass', 'shrink_regions']


def shrink_regions(problem: ZeroProblem, variant: str) -> list[ZeroRegion]:
    """Run algorithm B.1 or B.2 on a 0-MORDP instance.

    Args:
        problem: the reduced instance.
        variant: ``'B1'`` or ``'B2'``.

    Returns:
        The regions.

    Raises:
        LandmarkDbError: on an unknown ``variant``.
    """
    if variant not in ('B1', 'B2'):
        raise LandmarkDbError(f'unknown B.x variant {variant!r}; choose B1 or B2')
    state = CoverState(problem)
    if variant == 'B1':
        shrink_pass(problem, state)
        return eliminate_redundant(state.regions, problem.n_poses, problem.rng)
    return _shrink_with_purge(problem, state)


def choose_landmark(problem: ZeroProblem, region: np.ndarray, first_scores: np.ndarray,
                    allowed: np.ndarray | None = None) -> np.ndarray:
    """Greedy lines 4 to 8 of Figure 5.2: k features, each most seen in the shrinking R.

    Args:
        problem: the reduced instance.
        region: the starting R (sorted poses), normally U.
        first_scores: ``(f,)`` counts of ``region``'s poses seeing each feature (passed
            in because callers maintain it incrementally for R = U).
        allowed: optional feature columns to choose from (algorithm C's F); default all.

    Returns:
        The k chosen columns in choice order (fewer if R runs out of features).
    """
    chosen: list[int] = []
    scores = first_scores
    allowed_cols = None if allowed is None else np.asarray(allowed, dtype=np.int64)
    for _ in range(problem.k):
        if chosen:
            scores = problem.feature_counts(region)
            scores[chosen] = 0
        col = problem.best_feature(scores, allowed_cols)
        if col < 0:
            break
        chosen.append(col)
        region = problem.keep_seeing(region, col)
    return np.asarray(chosen, dtype=np.int64)


def shrink_pass(problem: ZeroProblem, state: CoverState) -> None:
    """Run the B.1 main loop on the current U of ``state`` until U is empty."""
    counts_u = problem.feature_counts(np.flatnonzero(state.unassigned))
    while True:
        unassigned = np.flatnonzero(state.unassigned)
        if unassigned.size == 0:
            return
        landmark = choose_landmark(problem, unassigned, counts_u)
        region = problem.poses_seeing_all(landmark)
        leaving = region[state.unassigned[region]]
        state.offer_components(region, np.sort(landmark))
        counts_u -= problem.feature_counts(leaving)


def _shrink_with_purge(problem: ZeroProblem, state: CoverState) -> list[ZeroRegion]:
    tracker = _UniqueCover(problem.n_poses, problem.rng)
    counts_u = problem.feature_counts(np.flatnonzero(state.unassigned))
    while True:
        unassigned = np.flatnonzero(state.unassigned)
        if unassigned.size == 0:
            break
        landmark = choose_landmark(problem, unassigned, counts_u)
        region = problem.poses_seeing_all(landmark)
        leaving = region[state.unassigned[region]]
        kept = state.offer_components(region, np.sort(landmark))
        counts_u -= problem.feature_counts(leaving)
        if not kept:
            continue
        gain = 0
        for index in kept:
            poses = state.regions[index].poses
            gain += int(np.count_nonzero(tracker.cover[poses] == 0))
            tracker.add(index, poses)
        # Purge (Altgreedy): drop the cheapest older regions while the poses they
        # leave uncovered stay strictly fewer than the poses just newly covered.
        lost = 0
        while True:
            drop, cost = tracker.cheapest(exclude=kept)
            if drop < 0 or lost + cost >= gain:
                break
            lost += cost
            freed = tracker.remove(drop, state.regions[drop].poses)
            if freed.size:
                state.unassigned[freed] = True
                counts_u += problem.feature_counts(freed)
    return [region for index, region in enumerate(state.regions) if tracker.is_alive(index)]


class _UniqueCover:
    """Cover counts and per-region counts of uniquely covered poses, kept incrementally.

    A pose covered by exactly one region finds that region as ``owner_sum`` (the sum
    of the ids of the regions covering it).
    """

    def __init__(self, n_poses: int, rng: np.random.Generator) -> None:
        self.cover = np.zeros(n_poses, dtype=np.int64)
        self.owner_sum = np.zeros(n_poses, dtype=np.int64)
        self.unique = np.zeros(0, dtype=np.int64)
        self.alive = np.zeros(0, dtype=bool)
        self.tie_key = np.zeros(0)
        self.rng = rng

    def _grow(self, index: int) -> None:
        if index < self.unique.size:
            return
        extra = max(64, index + 1 - self.unique.size, self.unique.size)
        self.unique = np.concatenate([self.unique, np.zeros(extra, dtype=np.int64)])
        self.alive = np.concatenate([self.alive, np.zeros(extra, dtype=bool)])
        self.tie_key = np.concatenate([self.tie_key, self.rng.random(extra)])

    def is_alive(self, index: int) -> bool:
        return index < self.alive.size and bool(self.alive[index])

    def add(self, index: int, poses: np.ndarray) -> None:
        self._grow(index)
        was_single = poses[self.cover[poses] == 1]
        if was_single.size:
            np.subtract.at(self.unique, self.owner_sum[was_single], 1)
        self.cover[poses] += 1
        self.owner_sum[poses] += index
        self.unique[index] = int(np.count_nonzero(self.cover[poses] == 1))
        self.alive[index] = True

    def remove(self, index: int, poses: np.ndarray) -> np.ndarray:
        """Remove a region; return the poses it leaves uncovered."""
        self.cover[poses] -= 1
        self.owner_sum[poses] -= index
        now_single = poses[self.cover[poses] == 1]
        if now_single.size:
            np.add.at(self.unique, self.owner_sum[now_single], 1)
        self.alive[index] = False
        self.unique[index] = 0
        return poses[self.cover[poses] == 0]

    def cheapest(self, exclude: list[int]) -> tuple[int, int]:
        """Return (region, unique count) of the live region losing the fewest poses."""
        alive = self.alive.copy()
        alive[exclude] = False
        active = np.flatnonzero(alive)
        if active.size == 0:
            return -1, 0
        costs = self.unique[active]
        ties = active[costs == costs.min()]
        drop = int(ties[np.argmax(self.tie_key[ties])])
        return drop, int(self.unique[drop])
