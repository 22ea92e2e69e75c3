"""The speed-ups inside ``best`` compute exactly what the plain formulations compute."""
from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
import numpy as np
from scipy.sparse import csc_matrix, csgraph

from landmark_db.decomposition import best as best_module
from landmark_db.decomposition import local_search as local_search_module
from landmark_db.decomposition.problem import component_of, graph_ball, zero_problem
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


def _dense_local_search(matrix, weight, chosen, budget):
    """The local search scored densely: every candidate against every chosen region."""
    chosen = chosen.copy()
    dense = matrix.toarray()
    while True:
        idx = np.flatnonzero(chosen)
        sub = dense[:, idx]
        count = sub.sum(axis=1)
        uncovered = weight[count == 0].sum()
        single = sub * ((count == 1) * weight)[:, None]
        loss = single.sum(axis=0)
        if idx.size and uncovered + loss.min() <= budget:
            chosen[idx[int(np.argmin(loss))]] = False
            continue
        if idx.size < 2:
            return chosen
        gain = dense.T @ single
        gain_free = dense.T @ ((count == 0) * weight)
        gain[idx, :] = -np.inf
        gain_free[idx] = -np.inf
        both = sub.T @ (sub * ((count == 2) * weight)[:, None])
        useful = (gain > 0).astype(float)
        pairs = np.triu(useful.T @ useful > 0, k=1)
        move = None
        for i in np.flatnonzero(pairs.any(axis=1)):  # the largest slack, smallest i first
            js = np.flatnonzero(pairs[i])
            need = uncovered + loss[i] + loss[js] + both[i, js] - budget
            slack = gain[:, [i]] + gain[:, js] + gain_free[:, None] - need[None, :]
            c, j = np.unravel_index(int(np.argmax(slack)), slack.shape)
            if slack[c, j] >= 0 and (move is None or slack[c, j] > move[0]):
                move = (slack[c, j], c, i, int(js[j]))
        if move is not None:
            chosen[idx[move[2]]] = chosen[idx[move[3]]] = False
            chosen[move[1]] = True
            continue
        improvement = gain + gain_free[:, None] - loss[None, :]
        c, i = np.unravel_index(int(np.argmax(improvement)), improvement.shape)
        if improvement[c, i] <= 0.5:
            return chosen
        chosen[idx[i]] = False
        chosen[c] = True


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_local_search_makes_the_moves_of_a_dense_scan(seed):
    rng = np.random.default_rng(seed)
    rows, sets = int(rng.integers(1, 40)), int(rng.integers(1, 25))
    matrix = csc_matrix((rng.random((rows, sets)) < rng.uniform(0.05, 0.5)).astype(float))
    weight = rng.integers(1, 4, rows).astype(float)
    chosen = rng.random(sets) < rng.uniform(0.1, 1.0)
    budget = float(rng.integers(0, 10))
    got = local_search_module.local_search(matrix, weight, chosen, budget)
    np.testing.assert_array_equal(got, _dense_local_search(matrix, weight, chosen, budget))
    count = matrix[:, np.flatnonzero(got)].toarray().sum(axis=1)
    start = matrix[:, np.flatnonzero(chosen)].toarray().sum(axis=1)
    if weight[start == 0].sum() <= budget:  # a start within budget stays within it
        assert weight[count == 0].sum() <= budget
        assert got.sum() <= chosen.sum()


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), radius=st.integers(0, 6))
def test_graph_ball_holds_the_poses_dijkstra_finds_within_the_radius(seed, radius):
    world = _world(seed)
    start = int(np.random.default_rng(seed).integers(world.n_poses))
    poses, steps = graph_ball(world.adjacency, start, radius)
    distance = csgraph.dijkstra(world.adjacency, indices=start, unweighted=True)
    expected = np.flatnonzero(distance <= radius)
    np.testing.assert_array_equal(poses, expected)
    np.testing.assert_array_equal(steps, distance[expected].astype(int))


def test_algorithms_in_worker_processes_give_what_they_give_in_process(monkeypatch):
    problem = zero_problem(_world(10), 2, 1, 1, np.random.default_rng(3))  # 63 poses
    alone = best_module._every_algorithm(problem, 0.85)
    assert min(len(regions) for regions in alone.values()) >= 8
    monkeypatch.setattr(best_module, 'PARALLEL_MIN_POSES', 0)
    monkeypatch.setattr(best_module, 'available_cores', lambda: 2)
    parallel = best_module._every_algorithm(problem, 0.85)
    assert list(parallel) == list(alone) == ['B2', 'B1', 'A1', 'A2', 'A3', 'C', 'B2 sigma 0']
    for name, regions in alone.items():
        assert [(r.poses.tolist(), r.columns.tolist()) for r in parallel[name]] == \
            [(r.poses.tolist(), r.columns.tolist()) for r in regions], name
