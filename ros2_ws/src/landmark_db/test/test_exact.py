"""The exact 0-MORDP solver (set cover over maximal candidate regions, HiGHS MILP)."""
from __future__ import annotations

import itertools

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
import scipy.sparse as sp

from landmark_db.decomposition import decompose, validate
from landmark_db.decomposition.exact import candidate_regions
from landmark_db.decomposition.problem import zero_problem
from landmark_db.decomposition.set_cover import (
    greedy_partial_cover,
    reduce_by_dominance,
    solve_set_cover,
)
from landmark_db.errors import LandmarkDbError
from landmark_db.world import WorldInstance


def figure_3_2_world(with_feature_6: bool) -> WorldInstance:
    """Four poses A, B, C, D on a cycle; k = 2 (the example of thesis Section 3.1.5)."""
    sets = [{1, 2}, {2, 3}, {3, 5, 6}, {1, 5, 6}]
    if not with_feature_6:
        sets = [s - {6} for s in sets]
    ids = sorted(set().union(*sets))
    visible = np.array([[f in s for f in ids] for s in sets])
    edges = [[0, 1], [1, 2], [2, 3], [3, 0]]
    poses = [[0, 0], [1, 0], [1, 1], [0, 1]]
    return WorldInstance.from_visibility(poses, edges, visible, ids)


def test_figure_3_2_fewer_regions_need_more_features():
    with6 = decompose(figure_3_2_world(True), 'exact', k=2)
    assert validate(figure_3_2_world(True), with6) == []
    assert len(with6.regions) == 3
    assert ([2, 3], [5, 6]) in [(r.poses.tolist(), r.features.tolist()) for r in with6.regions]
    without6 = decompose(figure_3_2_world(False), 'exact', k=2)
    assert len(without6.regions) == 4
    used_with6 = set(np.concatenate([r.features for r in with6.regions]).tolist())
    used_without6 = set(np.concatenate([r.features for r in without6.regions]).tolist())
    assert len(used_with6) > len(used_without6)


def set_cover_world() -> WorldInstance:
    """Theorem 4.3's reduction of a set-cover instance where greedy needs 3 sets, not 2.

    Elements 1..14 form two rows (1..7 and 8..14, the optimum); T1 = columns 1-4,
    T2 = columns 5-6, T3 = column 7 of both rows. Pose 0 is the hub v*, joined to every
    element pose; feature j is subset j plus v*.
    """
    rows = [set(range(1, 8)), set(range(8, 15))]
    columns = [{1, 2, 3, 4, 8, 9, 10, 11}, {5, 6, 12, 13}, {7, 14}]
    subsets = rows + columns
    visible = np.zeros((15, len(subsets)), bool)
    visible[0] = True
    for j, subset in enumerate(subsets):
        visible[sorted(subset), j] = True
    angles = np.linspace(0, 2 * np.pi, 14, endpoint=False)
    poses = np.vstack([[0, 0], np.c_[np.cos(angles), np.sin(angles)]])
    return WorldInstance.from_visibility(poses, [[0, i] for i in range(1, 15)], visible)


def test_exact_beats_greedy_on_a_set_cover_trap():
    world = set_cover_world()
    exact = decompose(world, 'exact', k=1)
    assert validate(world, exact) == []
    assert sorted(r.features.tolist() for r in exact.regions) == [[0], [1]]
    for algorithm in ('B1', 'B2'):
        greedy = decompose(world, algorithm, k=1)
        assert validate(world, greedy) == []
        # T1 (9 poses with the hub) first, then T2, then T3: each needed, none purged.
        assert sorted(r.features.tolist() for r in greedy.regions) == [[2], [3], [4]]
    assert len(decompose(world, 'best', k=1).regions) <= 3


def test_candidates_are_the_maximal_components():
    world = figure_3_2_world(True)
    problem = zero_problem(world, 2, 0, 0, np.random.default_rng(0))
    found = sorted((r.poses.tolist(), sorted(world.feature_ids[r.columns].tolist()))
                   for r in candidate_regions(problem))
    # {5, 6} is seen from C and D; every other pair is seen from one pose only.
    assert ([2, 3], [5, 6]) in found
    assert all(len(p) == 1 for p, _ in found if p != [2, 3])
    # Landmarks with the same pose set give one candidate.
    assert sorted(p for p, _ in found) == [[0], [1], [2], [2, 3], [3]]


def test_refusal_when_the_candidate_count_is_too_large():
    rng = np.random.default_rng(0)
    visible = rng.random((10, 30)) < 0.9
    world = WorldInstance.from_visibility(np.c_[np.arange(10), np.zeros(10)],
                                          [[i, i + 1] for i in range(9)], visible)
    with pytest.raises(LandmarkDbError, match='exact solver refused'):
        decompose(world, 'exact', k=4, max_subsets=1000)
    with pytest.raises(LandmarkDbError, match='candidate regions'):
        decompose(world, 'exact', k=1, max_candidates=3)


def test_set_cover_infeasible_and_budgeted():
    sets = [np.array([0, 1]), np.array([1, 2]), np.array([3])]
    chosen, optimal = solve_set_cover(4, np.arange(4), sets)
    assert optimal and sorted(chosen.tolist()) == [0, 1, 2]
    chosen, optimal = solve_set_cover(4, np.arange(4), sets, budget=1)
    assert optimal and len(chosen) == 2
    with pytest.raises(LandmarkDbError, match='pose 3 lies in no candidate'):
        solve_set_cover(4, np.arange(4), sets[:2])


def test_greedy_partial_cover_takes_the_heaviest_set_until_the_budget_is_met():
    # Rows (weights 3, 1, 1, 2); sets {0, 1}, {1, 2}, {2, 3}, {3}.
    matrix = sp.csc_matrix(np.array([[1, 0, 0, 0],
                                     [1, 1, 0, 0],
                                     [0, 1, 1, 0],
                                     [0, 0, 1, 1]], dtype=float))
    weight = np.array([3.0, 1.0, 1.0, 2.0])
    # Set 0 covers 4; then set 2 covers rows 2 and 3 (3) where set 1 covers row 2 (1).
    assert greedy_partial_cover(matrix, weight, 0.0).tolist() == [True, False, True, False]
    assert greedy_partial_cover(matrix, weight, 3.0).tolist() == [True, False, False, False]
    assert not greedy_partial_cover(matrix, weight, 7.0).any()


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_greedy_partial_cover_stays_within_its_budget(seed):
    rng = np.random.default_rng(seed)
    rows, sets = int(rng.integers(1, 30)), int(rng.integers(1, 20))
    dense = rng.random((rows, sets)) < rng.uniform(0.05, 0.6)
    weight = rng.integers(1, 5, rows).astype(float)
    budget = float(rng.integers(0, 8))
    chosen = greedy_partial_cover(sp.csc_matrix(dense.astype(float)), weight, budget)
    uncovered = weight[~dense[:, chosen].any(axis=1)].sum()
    coverable = weight[dense.any(axis=1)].sum()
    assert uncovered <= max(budget, weight.sum() - coverable)
    # Each set taken covered weight no earlier choice did.
    assert chosen.sum() <= np.count_nonzero(dense[:, chosen].any(axis=1))


def test_dominated_sets_and_implied_poses_are_removed():
    # Rows are poses 0..3; sets {0, 1}, {0}, {1, 2, 3}, {2, 3}, {1, 2, 3} (a copy).
    dense = np.array([[1, 1, 0, 0, 0],
                      [1, 0, 1, 0, 1],
                      [0, 0, 1, 1, 1],
                      [0, 0, 1, 1, 1]])
    reduced, columns, rows = reduce_by_dominance(sp.csr_matrix(dense))
    # {0} lies in {0, 1}, {2, 3} in {1, 2, 3}, the copy goes (the lower index stays).
    # Then pose 1 (sets 0 and 2) and pose 3 (set 2, like pose 2) are implied: covering
    # pose 0 takes set 0, covering pose 2 set 2.
    assert columns.tolist() == [0, 2] and rows.tolist() == [0, 2]
    assert reduced.toarray().tolist() == [[1, 0], [0, 1]]
    # A budgeted cover keeps every pose (any may be one of those left out).
    _, columns, rows = reduce_by_dominance(sp.csr_matrix(dense), rows=False)
    assert columns.tolist() == [0, 2] and rows.tolist() == [0, 1, 2, 3]


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_reductions_keep_the_optimum_cover(seed):
    rng = np.random.default_rng(seed)
    rows, sets = int(rng.integers(1, 14)), int(rng.integers(1, 12))
    dense = rng.random((rows, sets)) < rng.uniform(0.1, 0.6)
    dense[np.arange(rows), rng.integers(0, sets, rows)] = True    # every pose coverable
    reduced, columns, kept = reduce_by_dominance(sp.csr_matrix(dense.astype(float)))
    # The reduced problem keeps every remaining pose coverable and lists only original sets.
    assert np.all(np.diff(reduced.indptr) > 0) and np.all(np.diff(columns) > 0)
    assert np.array_equal(reduced.toarray() > 0, dense[np.ix_(kept, columns)])
    # Brute force: the fewest sets covering every pose, before and after the reduction.
    def fewest(matrix: np.ndarray) -> int:
        for size in range(matrix.shape[1] + 1):
            for combo in itertools.combinations(range(matrix.shape[1]), size):
                if matrix[:, list(combo)].any(axis=1).all():
                    return size
        raise AssertionError('no cover')
    assert fewest(reduced.toarray() > 0) == fewest(dense)
    # solve_set_cover (which reduces) returns an optimum cover of the original.
    chosen, optimal = solve_set_cover(rows, np.arange(rows),
                                      [np.flatnonzero(dense[:, j]) for j in range(sets)])
    assert optimal and dense[:, chosen].any(axis=1).all() and chosen.size == fewest(dense)
