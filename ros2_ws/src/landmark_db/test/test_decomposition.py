"""Decomposition algorithms on hand-checkable worlds, and the validator's verdicts."""
from __future__ import annotations

import json

import numpy as np
import pytest

from landmark_db.decomposition import (
    ALGORITHMS,
    Decomposition,
    Region,
    decompose,
    load_decomposition,
    save_decomposition,
    validate,
)
from landmark_db.decomposition.overlap import (
    covered_poses,
    neighbourhood_matrix,
    reduce_visibility,
)
from landmark_db.decomposition.problem import ZeroRegion, zero_problem
from landmark_db.decomposition.redundancy import eliminate_redundant
from landmark_db.errors import LandmarkDbError
from landmark_db.world import grid_world

HEURISTICS = ('A1', 'A2', 'A3', 'B1', 'B2', 'C', 'best')


def line_world(visible_rows):
    visible = np.array(visible_rows, dtype=bool)
    return grid_world(visible.shape[0], 1, 0.5, visible)


def regions_of(decomposition):
    return sorted((r.poses.tolist(), r.features.tolist()) for r in decomposition.regions)


def test_two_features_covering_halves_k1():
    # Feature 0 seen from poses 0-2, feature 1 from poses 2-4: two regions suffice.
    world = line_world([[1, 0], [1, 0], [1, 1], [0, 1], [0, 1]])
    for algorithm in ALGORITHMS:
        d = decompose(world, algorithm, k=1)
        assert validate(world, d) == [], algorithm
        assert len(d.regions) == 2, algorithm
        covered = np.zeros(5, bool)
        for r in d.regions:
            covered[r.poses] = True
        assert covered.all()


def test_b1_picks_the_most_widely_seen_feature_first():
    # Feature 2 is seen everywhere: B.x must choose it and make one region.
    world = line_world([[1, 0, 1], [1, 0, 1], [0, 1, 1], [0, 1, 1]])
    d = decompose(world, 'B1', k=1)
    assert regions_of(d) == [([0, 1, 2, 3], [2])]


def test_disconnected_visibility_gives_one_region_per_piece():
    # Feature 0 is seen at both ends of a line but not in the middle (pose 2 sees only 1).
    world = line_world([[1, 0], [1, 0], [0, 1], [1, 0], [1, 0]])
    for algorithm in ('B1', 'B2'):
        d = decompose(world, algorithm, k=1)
        assert validate(world, d) == []
        assert ([0, 1], [0]) in regions_of(d)
        assert ([3, 4], [0]) in regions_of(d)
        assert ([2], [1]) in regions_of(d)


def test_k2_requires_common_pairs():
    world = line_world([[1, 1, 0], [1, 1, 1], [0, 1, 1], [0, 0, 1]])
    d = decompose(world, 'B2', k=2)
    assert validate(world, d) == []
    # Pose 3 sees one feature: not 2-coverable, never required.
    assert regions_of(d) == [([0, 1], [0, 1]), ([1, 2], [1, 2])]
    assert d.uncovered.tolist() == []


def test_no_coverable_pose_gives_an_empty_valid_decomposition():
    world = line_world([[1, 0], [0, 1], [0, 0]])
    for algorithm in ALGORITHMS:
        d = decompose(world, algorithm, k=2, rho=1, sigma=3)
        assert d.regions == [] and d.uncovered.size == 0
        assert validate(world, d) == []


def test_sigma_rule_leaves_small_holes_uncovered():
    # Poses 0-5 see feature 0; poses 6-7 see only feature 1 (a hole of 2 poses).
    world = line_world([[1, 0]] * 6 + [[0, 1]] * 2)
    d = decompose(world, 'B1', k=1, sigma=2)
    assert regions_of(d) == [([0, 1, 2, 3, 4, 5], [0])]
    assert d.uncovered.tolist() == [6, 7]
    assert validate(world, d) == []
    d1 = decompose(world, 'B1', k=1, sigma=1)
    assert len(d1.regions) == 2 and d1.uncovered.size == 0


def test_rho_reduction_and_expansion_on_a_line():
    # Feature 0 seen from poses 0..5, feature 1 from 4..9 (line of 10).
    rows = [[i <= 5, i >= 4] for i in range(10)]
    world = line_world(rows)
    reduced = reduce_visibility(world.adjacency, world.visible, 1).toarray()
    assert reduced[:, 0].tolist() == [i <= 4 for i in range(10)]
    assert reduced[:, 1].tolist() == [i >= 5 for i in range(10)]
    hood = neighbourhood_matrix(world.adjacency, 2)
    assert hood[4].indices.tolist() == [2, 3, 4, 5, 6]
    for algorithm in ALGORITHMS:
        d = decompose(world, algorithm, k=1, rho=1)
        assert validate(world, d) == [], algorithm
        assert regions_of(d) == [([0, 1, 2, 3, 4, 5], [0]), ([4, 5, 6, 7, 8, 9], [1])]


def test_rho_overlap_is_checked_by_the_validator():
    rows = [[i <= 5, i >= 4] for i in range(10)]
    world = line_world(rows)
    # Regions meeting without overlap: pose 5's N_1 = {4, 5, 6} lies in neither.
    d = Decomposition('B1', 1, 1, 0, 0.0, [Region(range(0, 6), [0]), Region(range(6, 10), [1])])
    problems = validate(world, d)
    assert any('N_1' in p for p in problems)
    hood = neighbourhood_matrix(world.adjacency, 1)
    covered = covered_poses(hood, [np.arange(0, 6), np.arange(6, 10)])
    assert covered.tolist() == [True] * 5 + [False, False] + [True] * 3


def test_validator_reports_each_kind_of_problem():
    world = line_world([[1, 0], [1, 0], [0, 1], [1, 0], [1, 0]])
    good = Decomposition('B1', 1, 0, 0, 0.0, [Region([0, 1], [0]), Region([3, 4], [0]),
                                              Region([2], [1])])
    assert validate(world, good) == []
    split = Decomposition('B1', 1, 0, 0, 0.0, [Region([0, 1, 3, 4], [0]), Region([2], [1])])
    assert any('not connected' in p for p in validate(world, split))
    blind = Decomposition('B1', 1, 0, 0, 0.0, [Region([0, 1, 2], [0]), Region([3, 4], [0])])
    assert any('not visible from pose 2' in p for p in validate(world, blind))
    too_many = Decomposition('B1', 1, 0, 0, 0.0, [Region([0, 1], [0, 1]), Region([3, 4], [0]),
                                                  Region([2], [1])])
    assert any('expected k = 1' in p for p in validate(world, too_many))
    missing = Decomposition('B1', 1, 0, 0, 0.0, [Region([0, 1], [0]), Region([2], [1])])
    assert any('not listed as uncovered' in p for p in validate(world, missing))
    listed = Decomposition('B1', 1, 0, 0, 0.0, [Region([0, 1], [0]), Region([2], [1])], [3, 4])
    assert any('sigma = 0' in p for p in validate(world, listed))
    listed.sigma = 2
    assert validate(world, listed) == []
    wrong_list = Decomposition('B1', 1, 0, 2, 0.0, good.regions, [3])
    assert any('covered' in p for p in validate(world, wrong_list))
    unknown = Decomposition('B1', 1, 0, 0, 0.0, [Region([0, 1], [7])] + good.regions[1:])
    assert any('not in the world' in p for p in validate(world, unknown))
    out_of_range = Decomposition('B1', 1, 0, 0, 0.0, good.regions + [Region([9], [0])])
    assert any('out of range' in p for p in validate(world, out_of_range))


def test_redundancy_elimination_leaves_a_minimal_cover():
    # Poses 0..1 are in A, B, C (omega 3 each); D = {1, 2} and E = {2} have omega 2.
    pieces = [[0, 1], [0, 1], [0, 1], [1, 2], [2]]
    regions = [ZeroRegion(np.array(p), np.array([i])) for i, p in enumerate(pieces)]
    for seed in range(5):
        kept = eliminate_redundant(regions, 3, np.random.default_rng(seed))
        assert len(kept) == 2
        count = np.zeros(3, int)
        for region in kept:
            count[region.poses] += 1
        assert (count >= 1).all()
        assert all((count[region.poses] == 1).any() for region in kept)  # minimal
    # Nothing to drop: each region has a pose of its own.
    alone = [ZeroRegion(np.array([0]), np.array([0])), ZeroRegion(np.array([1]), np.array([1]))]
    assert len(eliminate_redundant(alone, 2, np.random.default_rng(0))) == 2


@pytest.mark.parametrize('module, function, variants', [
    ('grow_regions', 'grow_regions', ('A1', 'A2', 'A3')),
    ('shrink_regions', 'shrink_regions', ('B1', 'B2')),
])
def test_algorithms_return_typed_regions_and_reject_unknown_variants(module, function,
                                                                     variants):
    import importlib

    run = getattr(importlib.import_module(f'landmark_db.decomposition.{module}'), function)
    # Feature 0 seen from poses 0-2, feature 1 from poses 2-4.
    world = line_world([[1, 0], [1, 0], [1, 1], [0, 1], [0, 1]])
    for variant in variants:
        problem = zero_problem(world, 1, 0, 0, np.random.default_rng(0))
        regions = run(problem, variant)
        assert all(isinstance(r, ZeroRegion) for r in regions)
        assert sorted((r.poses.tolist(), r.columns.tolist()) for r in regions) == \
            [([0, 1, 2], [0]), ([2, 3, 4], [1])]
    problem = zero_problem(world, 1, 0, 0, np.random.default_rng(0))
    with pytest.raises(LandmarkDbError, match="unknown .* variant 'Z9'"):
        run(problem, 'Z9')


def test_runs_are_reproducible_and_seed_dependent():
    rng = np.random.default_rng(3)
    world = grid_world(8, 8, 0.5, rng.random((64, 12)) < 0.6)
    for algorithm in HEURISTICS:
        a = decompose(world, algorithm, k=2, rho=0, sigma=1, rng=5)
        b = decompose(world, algorithm, k=2, rho=0, sigma=1, rng=5)
        assert regions_of(a) == regions_of(b)
        assert validate(world, a) == []


def test_b2_is_never_worse_than_its_purge_free_twin_on_a_ring():
    # Figure 3.1 flavour: a ring of 8 poses, 8 features each visible from 3 poses.
    n = 8
    visible = np.zeros((n, n), bool)
    for f in range(n):
        visible[[(f - 1) % n, f, (f + 1) % n], f] = True
    edges = [[i, (i + 1) % n] for i in range(n)]
    from landmark_db.world import WorldInstance
    world = WorldInstance.from_visibility(np.c_[np.cos(np.arange(n)), np.sin(np.arange(n))],
                                          edges, visible)
    for algorithm in ALGORITHMS:
        d = decompose(world, algorithm, k=1)
        assert validate(world, d) == []
    assert len(decompose(world, 'exact', k=1).regions) == 3
    assert len(decompose(world, 'B2', k=1).regions) <= len(decompose(world, 'B1', k=1).regions)


@pytest.mark.parametrize('kwargs, message', [
    ({'algorithm': 'Z9', 'k': 1}, 'unknown algorithm'),
    ({'algorithm': 'B1', 'k': 0}, 'k must be'),
    ({'algorithm': 'B1', 'k': 1, 'rho': -1}, 'rho must be'),
    ({'algorithm': 'B1', 'k': 1, 'sigma': -2}, 'sigma must be'),
    ({'algorithm': 'C', 'k': 1, 'alpha': 1.5}, 'alpha must be'),
])
def test_bad_parameters_are_refused(kwargs, message):
    world = line_world([[1], [1]])
    with pytest.raises(LandmarkDbError, match=message):
        decompose(world, **kwargs)


def test_decomposition_json_round_trip(tmp_path):
    world = line_world([[1, 0], [1, 0], [0, 1], [1, 0], [1, 0]])
    d = decompose(world, 'B2', k=1, sigma=0)
    path = tmp_path / 'd.json'
    save_decomposition(d, path)
    data = json.loads(path.read_text())
    assert set(data) == {'algorithm', 'k', 'rho', 'sigma', 'seconds', 'regions', 'uncovered'}
    back = load_decomposition(path)
    assert regions_of(back) == regions_of(d)
    assert validate(world, back) == []
    path.write_text('{"algorithm": "B2", "k": 1}')
    with pytest.raises(LandmarkDbError, match="no 'rho'"):
        load_decomposition(path)
    path.write_text(json.dumps({**data, 'regions': [{'poses': [0, 'a'], 'features': [0]}]}))
    with pytest.raises(LandmarkDbError, match='regions\\[0\\].poses'):
        load_decomposition(path)


def test_b2_purges_a_region_the_later_ones_make_redundant():
    # Hub pose 0 joined to poses 1..6; features: S1 = {1,2,3}, S2 = {4,5,6},
    # S3 = {1,2,4,5} (each plus the hub). B.x takes S3 first (5 poses), then S1 and S2;
    # after S2 the purge drops S3, which no longer covers any pose alone.
    subsets = [{1, 2, 3}, {4, 5, 6}, {1, 2, 4, 5}]
    visible = np.zeros((7, 3), bool)
    visible[0] = True
    for j, subset in enumerate(subsets):
        visible[sorted(subset), j] = True
    from landmark_db.world import WorldInstance
    world = WorldInstance.from_visibility(np.random.default_rng(0).random((7, 2)),
                                          [[0, i] for i in range(1, 7)], visible)
    b2 = decompose(world, 'B2', k=1)
    assert validate(world, b2) == []
    assert sorted(r.features.tolist() for r in b2.regions) == [[0], [1]]
