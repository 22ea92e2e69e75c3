"""World instance model, interchange JSON I/O and validation."""
from __future__ import annotations

import json
import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from landmark_db.errors import LandmarkDbError
from landmark_db.world import (
    WorldInstance,
    grid_world,
    load_world,
    save_world,
    world_from_dict,
    world_to_dict,
)


def test_grid_world_3x2_edges_and_positions():
    visible = np.eye(6, 2, dtype=bool)
    world = grid_world(3, 2, 0.5, visible)
    assert world.n_poses == 6
    assert world.poses.tolist() == [[0, 0], [0.5, 0], [1.0, 0], [0, 0.5], [0.5, 0.5], [1.0, 0.5]]
    pairs = {tuple(sorted(e)) for e in world.edges.tolist()}
    assert pairs == {(0, 1), (1, 2), (3, 4), (4, 5), (0, 3), (1, 4), (2, 5)}
    assert world.adjacency.nnz == 14
    assert world.spacing == 0.5


def test_grid_world_free_mask_drops_blocked_cells_and_their_edges():
    free = np.array([[True, False, True], [True, True, True]])
    world = grid_world(3, 2, 1.0, np.ones((6, 1), bool), free=free)
    assert world.n_poses == 5
    assert world.poses.tolist() == [[0, 0], [2, 0], [0, 1], [1, 1], [2, 1]]
    pairs = {tuple(sorted(e)) for e in world.edges.tolist()}
    assert pairs == {(2, 3), (3, 4), (0, 2), (1, 4)}


def test_from_visibility_sorts_feature_columns():
    visible = np.array([[1, 0, 0], [0, 1, 1]], bool)
    world = WorldInstance.from_visibility([[0, 0], [1, 0]], [[0, 1]], visible, [30, 10, 20])
    assert world.feature_ids.tolist() == [10, 20, 30]
    assert world.features_of(0).tolist() == [30]
    assert world.features_of(1).tolist() == [10, 20]
    assert world.visible_counts.tolist() == [1, 2]
    assert world.columns_of([20, 30]).tolist() == [1, 2]
    with pytest.raises(LandmarkDbError, match='feature id 99'):
        world.columns_of([99])


def test_round_trip_through_file(tmp_path):
    data = {'poses': [[0, 0], [1, 0], [2, 0]], 'edges': [[0, 1], [1, 2]],
            'visible': [[5, 7], [7], []], 'spacing': 1.0, 'name': 'line'}
    path = tmp_path / 'w.json'
    path.write_text(json.dumps(data))
    world = load_world(path)
    assert world.feature_ids.tolist() == [5, 7]
    assert world.visible_counts.tolist() == [2, 1, 0]
    out = tmp_path / 'out.json'
    save_world(world, out)
    assert json.loads(out.read_text()) == {**data, 'poses': [[0.0, 0.0], [1.0, 0.0],
                                                             [2.0, 0.0]]}
    assert not list(tmp_path.glob('.*.tmp'))


def test_duplicate_ids_in_a_pose_are_merged():
    world = world_from_dict({'poses': [[0, 0]], 'edges': [], 'visible': [[3, 3, 1]]})
    assert world.features_of(0).tolist() == [1, 3]


@pytest.mark.parametrize('data, message', [
    ([], 'JSON object'),
    ({'poses': [], 'edges': []}, "no 'visible'"),
    ({'edges': [], 'visible': []}, "no 'poses'"),
    ({'poses': [[0, 0]], 'visible': [[]]}, "no 'edges'"),
    ({'poses': [[0, 0], [1, 0]], 'edges': [[0, 2]], 'visible': [[], []]}, 'out of range'),
    ({'poses': [[0, 0], [1, 0]], 'edges': [[-1, 0]], 'visible': [[], []]}, 'out of range'),
    ({'poses': [[0, 'x']], 'edges': [], 'visible': [[]]}, 'numbers'),
    ({'poses': [[0, float('nan')]], 'edges': [], 'visible': [[]]}, 'non-finite'),
    ({'poses': [[0, float('inf')]], 'edges': [], 'visible': [[]]}, 'non-finite'),
    ({'poses': [[0, 0, 0, 0]], 'edges': [], 'visible': [[]]}, r'\[x, y\]'),
    ({'poses': [[0, 0]], 'edges': [], 'visible': [[-3]]}, 'negative feature id -3'),
    ({'poses': [[0, 0]], 'edges': [], 'visible': [[1.5]]}, 'integers'),
    ({'poses': [[0, 0]], 'edges': [], 'visible': [[], []]}, '1 poses but'),
    ({'poses': [[0, 0]], 'edges': [], 'visible': [3]}, r'visible\[0\]'),
    ({'poses': [[0, 0]], 'edges': [[0.5, 0]], 'visible': [[]]}, 'integer'),
    ({'poses': [[0, 0]], 'edges': [], 'visible': [[]], 'spacing': -1}, 'spacing'),
])
def test_invalid_worlds_are_refused_with_a_named_problem(data, message):
    with pytest.raises(LandmarkDbError, match=message):
        world_from_dict(data)


def test_load_world_malformed_and_missing(tmp_path):
    bad = tmp_path / 'bad.json'
    bad.write_text('{"poses": [')
    with pytest.raises(LandmarkDbError, match='not valid JSON'):
        load_world(bad)
    with pytest.raises(LandmarkDbError, match='no such file'):
        load_world(tmp_path / 'missing.json')


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 6), st.integers(1, 6), st.integers(0, 8), st.integers(0, 2**32 - 1))
def test_dict_round_trip_preserves_visibility(nx, ny, f, seed):
    rng = np.random.default_rng(seed)
    ids = rng.choice(1000, size=f, replace=False)
    visible = rng.random((nx * ny, f)) < 0.4
    world = grid_world(nx, ny, 0.5, visible, feature_ids=ids)
    back = world_from_dict(json.loads(json.dumps(world_to_dict(world))))
    assert back.n_poses == world.n_poses
    np.testing.assert_array_equal(back.edges, world.edges)
    for v in range(world.n_poses):
        expected = np.sort(ids[visible[v]])
        assert back.features_of(v).tolist() == expected.tolist()


def test_a_pose_space_with_heading_has_one_pose_per_position_and_heading() -> None:
    visible = np.eye(3, dtype=bool)
    # Two headings at one position are two poses (the heading pose space).
    world = WorldInstance.from_visibility([[0, 0, 0], [0, 0, math.pi / 4], [0.25, 0, 0]],
                                          [[0, 1], [0, 2]], visible)
    assert world.poses.shape == (3, 3)
    with pytest.raises(LandmarkDbError, match=r'poses 0 and 1 are both at \(0, 0, 0\)'):
        WorldInstance.from_visibility([[0, 0, 0], [0, 0, 0], [0.25, 0, 0]], [[0, 1]], visible)
    with pytest.raises(LandmarkDbError, match=r'\[x, y\] \(or \[x, y, heading\]\)'):
        WorldInstance.from_visibility([[0, 0, 0, 1]] * 3, [], visible)
