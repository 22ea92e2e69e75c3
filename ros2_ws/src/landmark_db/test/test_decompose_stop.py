"""``decompose(..., check_stop=...)``: a shutdown ends a long ``best`` between its steps."""
from __future__ import annotations

import numpy as np
import pytest

from landmark_db.decomposition import decompose
from landmark_db.world import grid_world


class _StopRequestError(Exception):
    pass


def _world():
    """A 12 x 12 grid, 40 features each seen within a random disc."""
    rng = np.random.default_rng(3)
    gx, gy = np.meshgrid(np.arange(12), np.arange(12))
    cells = np.column_stack([gx.ravel(), gy.ravel()])
    centres = rng.uniform(0, 12, size=(40, 2))
    radius = rng.uniform(2.0, 6.0, size=40)
    visible = np.linalg.norm(cells[:, None] - centres[None], axis=2) < radius[None]
    return grid_world(12, 12, 0.5, visible)


def test_best_calls_check_stop_and_its_exception_ends_the_decomposition():
    world = _world()
    calls = []
    decomposition = decompose(world, 'best', k=4, check_stop=lambda: calls.append(1))
    # Before the search, before each of the six algorithms, and later steps.
    assert len(calls) >= 7
    plain = decompose(world, 'best', k=4)
    assert [r.poses.tolist() for r in plain.regions] == \
        [r.poses.tolist() for r in decomposition.regions]

    seen = []

    def stop_at_third():
        seen.append(1)
        if len(seen) == 3:
            raise _StopRequestError

    with pytest.raises(_StopRequestError):
        decompose(world, 'best', k=4, check_stop=stop_at_third)
    assert len(seen) == 3


@pytest.mark.parametrize('algorithm', ['A1', 'B2', 'exact'])
def test_every_algorithm_checks_once_before_it_runs(algorithm):
    def stop():
        raise _StopRequestError

    with pytest.raises(_StopRequestError):
        decompose(_world(), algorithm, k=4, check_stop=stop)
