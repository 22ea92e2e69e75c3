"""Every algorithm's output passes the validator on many random worlds (hypothesis)."""
from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
import numpy as np

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


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
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
        counts[algorithm] = len(d.regions)
    assert counts['best'] <= counts['B2']


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
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
