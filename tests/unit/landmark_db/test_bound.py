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
