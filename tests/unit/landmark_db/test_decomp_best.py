"""The speed-ups inside ``best`` compute exactly what the plain formulations compute."""
from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
import numpy as np
from scipy.sparse import csgraph

from landmark_db.decomposition import best as best_module
from landmark_db.decomposition.problem import component_of, zero_problem
from landmark_db.world import grid_world


def _world(seed: int):
    rng = np.random.default_rng(seed)
    nx, ny = int(rng.integers(2, 10)), int(rng.integers(2, 10))
    visible = rng.random((nx * ny, int(rng.integers(4, 16)))) < rng.uniform(0.3, 0.9)
    return grid_world(nx, ny, 0.5, visible, free=rng.random((ny, nx)) > 0.1)


def _plain_grow(problem, seed, radii):
    """Seeded growth written directly: boolean masks and column sums."""
    distance = csgraph.dijkstra(problem.adjacency, indices=seed, unweighted=True)
    dense = problem.visible.toarray().astype(bool)
    allowed = problem.row_features(seed)
    out = []
    for t in radii:
        members = (distance <= t) & problem.coverable
        chosen: list[int] = []
        for _ in range(problem.k):
            scores = dense[members][:, allowed].sum(axis=0)
            scores[chosen] = 0
            if not scores.any():
                break
            keys = np.where(scores > 0, scores * (problem.n_features + 1)
                            + problem.feature_priority[allowed], -1)
            j = int(np.argmax(keys))
            chosen.append(j)
            members &= dense[:, allowed[j]]
        if len(chosen) == problem.k:
            landmark = np.sort(allowed[chosen])
            out.append((component_of(problem.adjacency, problem.poses_seeing_all(landmark),
                                     seed), landmark))
    return out


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(1, 3), rho=st.integers(0, 1),
       algo_seed=st.integers(0, 100))
def test_seeded_growth_matches_the_plain_greedy(seed, k, rho, algo_seed):
    problem = zero_problem(_world(seed), k, rho, 0, np.random.default_rng(algo_seed))
    cache = best_module._ComponentCache(problem)
    radii = [1, 2, 4]
    for pose in np.flatnonzero(problem.coverable)[:12]:
        fast = best_module._grow_candidates(problem, int(pose), problem.coverable, cache, radii)
        plain = _plain_grow(problem, int(pose), radii)
        assert len(fast) == len(plain)
        for region, (poses_b, cols_b) in zip(fast, plain):
            assert np.array_equal(region.columns, cols_b)
            assert np.array_equal(region.poses, poses_b)
            assert int(pose) in region.poses


def test_component_cache_returns_the_seed_component():
    # Two 3-pose corridors joined by a pose that does not see feature 1: L = {0, 1}
    # has two components, and the cache must return the one holding the seed.
    visible = np.array([[1, 1]] * 3 + [[1, 0]] + [[1, 1]] * 3, dtype=bool)
    problem = zero_problem(grid_world(7, 1, 0.5, visible), 2, 0, 0, np.random.default_rng(0))
    cache = best_module._ComponentCache(problem)
    landmark = np.array([0, 1])
    assert cache.component(landmark, 1).tolist() == [0, 1, 2]
    assert cache.component(landmark, 5).tolist() == [4, 5, 6]
    assert cache.component(landmark, 0).tolist() == [0, 1, 2]


def test_gather_slices_concatenates_the_selected_columns_in_order():
    import scipy.sparse as sp

    from landmark_db.decomposition.problem import gather_slices

    # 3 poses x 3 features; column 0 seen by poses 0 and 2, column 1 by none, column 2 by 1.
    csc = sp.csc_matrix(np.array([[1, 0, 0], [0, 0, 1], [1, 0, 0]], dtype=bool))
    entries, lengths = gather_slices(csc.indptr, csc.indices, np.array([2, 1, 0]))
    assert entries.tolist() == [1, 0, 2]
    assert lengths.tolist() == [1, 0, 2]
