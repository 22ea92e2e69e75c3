"""Every algorithm's output passes the validator on many random worlds (hypothesis)."""
from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from landmark_db.decomposition import ALGORITHMS, decompose, validate
from landmark_db.decomposition.overlap import covered_poses, neighbourhood_matrix
from landmark_db.world import grid_world

HEURISTICS = tuple(a for a in ALGORITHMS if a != 'exact')


def random_world(seed: int, coherent: bool):
    """A small grid world with obstacles and random or disc-shaped visibility."""
    rng = np.random.default_rng(seed)
    nx, ny = int(rng.integers(1, 9)), int(rng.integers(1, 9))
    free = rng.random((ny, nx)) > 0.15
    n_features = int(rng.integers(1, 14))
    if coherent:
        centres = rng.uniform(0, [nx, ny], size=(n_features, 2))
        radius = rng.uniform(1.0, 5.0, size=n_features)
        gx, gy = np.meshgrid(np.arange(nx), np.arange(ny))
        cells = np.column_stack([gx.ravel(), gy.ravel()])
        distance = np.linalg.norm(cells[:, None, :] - centres[None], axis=2)
        visible = distance < radius[None]
        visible &= rng.random(visible.shape) > 0.05  # a few holes
    else:
        visible = rng.random((nx * ny, n_features)) < rng.uniform(0.2, 0.9)
    ids = rng.choice(10_000, size=n_features, replace=False)
    return grid_world(nx, ny, 0.5, visible, free=free, feature_ids=ids)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), coherent=st.booleans(), k=st.integers(1, 4),
       rho=st.integers(0, 2), sigma=st.integers(0, 3), algo_seed=st.integers(0, 1000))
def test_every_heuristic_is_valid_on_random_worlds(seed, coherent, k, rho, sigma, algo_seed):
    world = random_world(seed, coherent)
    hood = neighbourhood_matrix(world.adjacency, rho)
    counts = {}
    for algorithm in HEURISTICS:
        d = decompose(world, algorithm, k=k, rho=rho, sigma=sigma, rng=algo_seed)
        assert validate(world, d) == [], algorithm
        assert (d.k, d.rho, d.sigma, d.algorithm) == (k, rho, sigma, algorithm)
        if sigma == 0:
            assert d.uncovered.size == 0, algorithm
        # Independent re-check of coverage: uncovered == coverable minus covered.
        covered = covered_poses(hood, [r.poses for r in d.regions])
        listed = np.zeros(world.n_poses, bool)
        listed[d.uncovered] = True
        assert not (listed & covered).any()
        for region in d.regions:
            cols = world.columns_of(region.features)
            assert world.visible_dense()[np.ix_(region.poses, cols)].all()
        counts[algorithm] = (len(d.regions), d.uncovered.size)
    assert_best_never_worse(counts)


def assert_best_never_worse(counts):
    """best serves at least as many poses as B2, and has no more regions than any
    algorithm that serves at least as many poses as best."""
    regions, unserved = counts['best']
    assert unserved <= counts['B2'][1]
    for algorithm, (other_regions, other_unserved) in counts.items():
        if other_unserved <= unserved:
            assert regions <= other_regions, algorithm


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), coherent=st.booleans(), k=st.integers(1, 3),
       rho=st.integers(0, 1))
def test_exact_is_valid_and_never_beaten(seed, coherent, k, rho):
    world = random_world(seed, coherent)
    optimum = decompose(world, 'exact', k=k, rho=rho)
    assert validate(world, optimum) == []
    assert optimum.uncovered.size == 0
    for algorithm in HEURISTICS:
        d = decompose(world, algorithm, k=k, rho=rho, sigma=0)
        assert len(optimum.regions) <= len(d.regions), algorithm


def brute_neighbourhoods(world, rho):
    from scipy.sparse.csgraph import shortest_path
    if world.n_poses == 0:
        return np.zeros((0, 0), bool)
    distance = shortest_path(world.adjacency.astype(float), unweighted=True, directed=False)
    return distance <= rho


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), coherent=st.booleans(), rho=st.integers(0, 3))
def test_rho_reduction_matches_brute_force(seed, coherent, rho):
    from landmark_db.decomposition.overlap import reduce_visibility
    world = random_world(seed, coherent)
    hood = brute_neighbourhoods(world, rho)
    np.testing.assert_array_equal(neighbourhood_matrix(world.adjacency, rho).toarray() > 0,
                                  hood)
    dense = world.visible_dense()
    expected = np.array([dense[hood[v]].all(axis=0) for v in range(world.n_poses)]
                        ).reshape(dense.shape)
    np.testing.assert_array_equal(
        reduce_visibility(world.adjacency, world.visible, rho).toarray(), expected)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), coherent=st.booleans(), k=st.integers(1, 4))
def test_algorithm_c_radius_matches_its_definition(seed, coherent, k):
    from landmark_db.decomposition.neighbourhood_seeds import neighbourhood_radius
    from landmark_db.decomposition.problem import zero_problem
    world = random_world(seed, coherent)
    problem = zero_problem(world, k, 0, 0, np.random.default_rng(0))
    coverable = problem.coverable
    dense = world.visible_dense()

    def passes(r):
        hood = brute_neighbourhoods(world, r)
        good = 0
        for u in np.flatnonzero(coverable):
            members = hood[u] & coverable
            good += dense[members].all(axis=0).sum() >= k
        return 2 * good >= coverable.sum()

    radius = neighbourhood_radius(problem)
    if coverable.any():
        assert passes(radius)
        # Either the next radius fails, or the sets reached a fixed point (so every
        # larger radius passes too).
        if passes(radius + 1):
            assert all(passes(r) for r in range(radius + 2, radius + 5))
    else:
        assert radius == 0


def disc_world(seed: int, size: int = 24, n_features: int = 60):
    """A larger grid world with disc-shaped visibility areas and a few holes."""
    rng = np.random.default_rng(seed)
    free = rng.random((size, size)) > 0.08
    centres = rng.uniform(0, size, size=(n_features, 2))
    radius = rng.uniform(3.0, 9.0, size=n_features)
    gx, gy = np.meshgrid(np.arange(size), np.arange(size))
    cells = np.column_stack([gx.ravel(), gy.ravel()])
    visible = np.linalg.norm(cells[:, None, :] - centres[None], axis=2) < radius[None]
    visible &= rng.random(visible.shape) > 0.02
    return grid_world(size, size, 0.5, visible, free=free)


@pytest.mark.parametrize('seed', range(4))
def test_all_algorithms_on_larger_coherent_worlds(seed):
    world = disc_world(seed)
    k, rho, sigma = 3, 1, 4
    counts = {}
    for algorithm in HEURISTICS:
        d = decompose(world, algorithm, k=k, rho=rho, sigma=sigma, rng=seed)
        assert validate(world, d) == [], algorithm
        counts[algorithm] = (len(d.regions), d.uncovered.size)
        if algorithm == 'best':  # LP, MILP and local search: still reproducible
            again = decompose(world, algorithm, k=k, rho=rho, sigma=sigma, rng=seed)
            assert [r.poses.tolist() for r in again.regions] == \
                [r.poses.tolist() for r in d.regions]
    assert_best_never_worse(counts)
    complete = {a: decompose(world, a, k=k, rho=rho, sigma=0, rng=seed) for a in HEURISTICS}
    for d in complete.values():
        assert validate(world, d) == [] and d.uncovered.size == 0
    assert len(complete['best'].regions) == min(len(d.regions) for d in complete.values())
    bound = complete['best'].lower_bound
    assert bound is not None and bound <= len(complete['best'].regions)
