"""The certified lower bound (column generation): never above the exact optimum."""
from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np

from landmark_db.decomposition import certify, decompose
from landmark_db.errors import LandmarkDbError
from landmark_db.world import grid_world

from .test_decomp_properties import random_world


def test_two_disjoint_areas_need_two_regions():
    # Poses 0-1 see features {0, 1}, poses 2-3 see {2, 3}: with k = 2 no region can
    # hold both halves, so the bound is 2, the optimum.
    visible = np.array([[1, 1, 0, 0], [1, 1, 0, 0], [0, 0, 1, 1], [0, 0, 1, 1]], bool)
    world = grid_world(4, 1, 0.5, visible)
    d = decompose(world, 'best', k=2)
    assert len(d.regions) == 2 and d.lower_bound == 2
    bound = certify(world, decompose(world, 'B1', k=2))
    assert bound.regions == 2 and bound.proven and bound.ratio(2) == 1.0


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), coherent=st.booleans(), k=st.integers(1, 3),
       rho=st.integers(0, 1))
def test_bound_never_exceeds_the_exact_optimum(seed, coherent, k, rho):
    world = random_world(seed, coherent)
    try:
        exact = decompose(world, 'exact', k=k, rho=rho)
    except LandmarkDbError:
        return  # too large to enumerate
    best = decompose(world, 'best', k=k, rho=rho)
    bound = certify(world, best)
    assert bound.regions <= len(exact.regions) <= len(best.regions)
    if best.lower_bound is not None:
        assert best.lower_bound <= len(exact.regions)
    if bound.proven:
        assert bound.lp_bound <= len(exact.regions) + 1e-6


def _every_candidate(problem):
    """All maximal candidates by brute force: components of each k-subset's support."""
    from itertools import combinations

    from landmark_db.decomposition.problem import split_components
    found = {}
    for landmark in combinations(range(problem.n_features), problem.k):
        poses = problem.poses_seeing_all(np.array(landmark))
        if poses.size:
            for piece in split_components(problem.adjacency, poses):
                found[piece.tobytes()] = piece
    return list(found.values())


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), coherent=st.booleans(), k=st.integers(1, 3),
       dual_seed=st.integers(0, 1000), scale=st.floats(0.05, 1.5))
def test_anchored_pricing_bounds_every_candidate(seed, coherent, k, dual_seed, scale):
    from math import comb

    from landmark_db.decomposition.pricing import SLACK, AnchoredPricing
    from landmark_db.decomposition.problem import zero_problem
    world = random_world(seed, coherent)
    problem = zero_problem(world, k, 0, 0, np.random.default_rng(0))
    if comb(problem.n_features, k) > 3000:
        return
    rng = np.random.default_rng(dual_seed)
    duals = np.where(rng.random(problem.n_poses) < 0.6,
                     rng.random(problem.n_poses) * scale, 0.0)
    candidates = _every_candidate(problem)
    heaviest = max((float(duals[c].sum()) for c in candidates), default=0.0)
    # An unlimited search and one cut short: U bounds every candidate either way.
    for limit, anchor_limit in ((10**6, 10**6), (3, 2)):
        priced = AnchoredPricing(problem).price(duals, limit, anchor_limit=anchor_limit)
        assert priced.upper >= heaviest - 1e-9
        if priced.proven:
            assert heaviest <= 1.0 + SLACK
        keys = {c.tobytes() for c in candidates}
        for region in priced.regions:
            assert region.poses.tobytes() in keys          # maximal candidates
            assert float(duals[region.poses].sum()) > 1.0
            assert problem.visible_csc[region.poses][:, region.columns].toarray().all()
    exact = AnchoredPricing(problem).price(duals, 10**6, anchor_limit=10**6)
    if heaviest > 1.0 + 1e-6:
        assert exact.regions and not exact.proven
