"""The shipped scenes and how --scene resolves names and paths."""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from landmark_db.errors import LandmarkDbError
from landmark_db.scenes import resolve_scene, shipped_scene_names
from vbn_worlds.synthesis.grid import exploration_poses


def test_shipped_scene_names():
    assert {'room', 'floor'} <= set(shipped_scene_names())


def test_room_is_six_by_three_metres_with_obstacles():
    room = resolve_scene('room')
    assert room.name == 'room'
    assert room.bounds() == (0.0, 0.0, 6.0, 3.0)
    assert 2 <= len(room.obstacles) <= 5
    assert room.camera_height < room.wall_height


def test_floor_is_twenty_by_ten_with_connected_rooms():
    floor = resolve_scene('floor')
    assert floor.bounds() == (0.0, 0.0, 20.0, 10.0)
    # every free grid pose is reachable from every other (doors connect the rooms)
    poses = exploration_poses(floor, 0.25)
    pairs = cKDTree(poses).query_pairs(0.25 * 1.01, output_type='ndarray')
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                       shape=(len(poses), len(poses)))
    n_components, _ = connected_components(graph, directed=False)
    assert n_components == 1
    assert len(poses) > 1500


def test_scene_path_and_errors(tmp_path):
    path = tmp_path / 'mine.json'
    path.write_text(json.dumps({'perimeter': [[0, 0], [2, 0], [2, 2], [0, 2]],
                                'texture_seed': 3}))
    scene = resolve_scene(str(path))
    assert scene.texture_seed == 3
    with pytest.raises(LandmarkDbError, match='unknown scene'):
        resolve_scene('atlantis')
    path.write_text('{not json')
    with pytest.raises(LandmarkDbError, match='invalid scene'):
        resolve_scene(path)
    path.write_text(json.dumps({'perimeter': [[0, 0], [2, 0], [2, 2]], 'wall_height': -1}))
    with pytest.raises(LandmarkDbError, match='wall_height'):
        resolve_scene(path)
    with pytest.raises(LandmarkDbError, match='directory'):
        resolve_scene(tmp_path)
