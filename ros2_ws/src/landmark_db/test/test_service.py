"""Service, the one coverage measure: hand-checked cases and a brute-force re-check."""
from __future__ import annotations

from collections import deque

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from landmark_db.decomposition import ALGORITHMS, decompose, service, validate
from landmark_db.world import grid_world

from .test_decomp_properties import random_world


def brute_force_service(world, regions, k, rho):
    """Served poses by breadth-first neighbourhoods and Python set intersections."""
    n = world.n_poses
    neighbours = [set() for _ in range(n)]
    for i, j in world.edges:
        neighbours[int(i)].add(int(j))
        neighbours[int(j)].add(int(i))
    dense = world.visible_dense()
    sees = [set(np.flatnonzero(dense[v]).tolist()) for v in range(n)]
    region_sets = [set(int(p) for p in r) for r in regions]
    coverable, served, member = set(), set(), set()
    for v in range(n):
        hood, queue = {v}, deque([(v, 0)])
        while queue:
            u, d = queue.popleft()
            if d == rho:
                continue
            for w in neighbours[u] - hood:
                hood.add(w)
                queue.append((w, d + 1))
        common = set.intersection(*(sees[u] for u in hood))
        if len(common) < k:
            continue
        coverable.add(v)
        if any(hood <= r for r in region_sets):
            served.add(v)
        if any(v in r for r in region_sets):
            member.add(v)
    return coverable, served, member


def test_a_line_of_three_poses_by_hand():
    # 0 - 1 - 2, every pose sees both features; one region {0, 1}.
    world = grid_world(3, 1, 0.5, np.ones((3, 2), bool))
    rho1 = service(world, [np.array([0, 1])], k=2, rho=1)
    # N_1(0) = {0, 1} lies in the region; N_1(1) = {0, 1, 2} does not; 2 is outside.
    assert (rho1.k_coverable, rho1.served, rho1.in_region) == (3, 1, 2)
    assert rho1.unserved.tolist() == [1, 2]
    assert rho1.share == pytest.approx(1 / 3)
    assert rho1.to_dict() == {'k_coverable': 3, 'served': 1, 'served_share': 0.333333,
                              'unserved': 2, 'in_region': 2}
    assert rho1.describe() == 'served 1 of 3 k-coverable poses (33.3 %)'
    rho0 = service(world, [np.array([0, 1])], k=2, rho=0)
    assert (rho0.k_coverable, rho0.served, rho0.in_region) == (3, 2, 2)


def test_rho_reduction_decides_who_is_k_coverable():
    # Pose 2 alone misses feature 1, so under rho = 1 poses 1 and 2 see one feature
    # throughout their neighbourhood and only pose 0 is 2-coverable.
    visible = np.array([[1, 1], [1, 1], [1, 0]], bool)
    world = grid_world(3, 1, 0.5, visible)
    s = service(world, [np.array([0, 1, 2])], k=2, rho=1)
    assert (s.k_coverable, s.served, s.unserved.tolist()) == (1, 1, [])
    assert service(world, [], k=2, rho=0).k_coverable == 2


def test_no_k_coverable_pose_counts_as_fully_served():
    world = grid_world(2, 1, 0.5, np.ones((2, 1), bool))
    s = service(world, [], k=3, rho=0)
    assert (s.k_coverable, s.served, s.share) == (0, 0, 1.0)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), coherent=st.booleans(), k=st.integers(1, 4),
       rho=st.integers(0, 2), sigma=st.integers(0, 3),
       algorithm=st.sampled_from([a for a in ALGORITHMS if a != 'exact']))
def test_service_and_validate_agree_with_a_brute_force_check(seed, coherent, k, rho, sigma,
                                                             algorithm):
    world = random_world(seed, coherent)
    d = decompose(world, algorithm, k=k, rho=rho, sigma=sigma, rng=seed % 97)
    regions = [r.poses for r in d.regions]
    coverable, served, member = brute_force_service(world, regions, k, rho)
    s = service(world, regions, k, rho)
    assert s.k_coverable == len(coverable)
    assert s.served == len(served)
    assert s.in_region == len(member)
    assert set(s.unserved.tolist()) == coverable - served
    assert validate(world, d) == []
    assert set(d.uncovered.tolist()) == coverable - served
