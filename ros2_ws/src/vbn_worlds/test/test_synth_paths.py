"""Exploration grids, run trajectories and the kidnapped variant."""
from __future__ import annotations

import math

import numpy as np
import pytest

from landmark_db.scene import Scene
from landmark_db.scenes import resolve_scene
from vbn_worlds.errors import WorldsError
from vbn_worlds.synthesis.grid import exploration_poses
from vbn_worlds.synthesis.trajectory import (
    RunParameters,
    kidnapped_trajectory,
    run_trajectory,
)

SQUARE = Scene(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]))


@pytest.fixture(scope='module')
def room():
    return resolve_scene('room')


@pytest.fixture(scope='module')
def room_run(room):
    return run_trajectory(room)


def test_grid_of_an_empty_rectangle_is_hand_checkable():
    poses = exploration_poses(SQUARE, 0.5, clearance=0.2)
    # x: 1.6 m usable -> 4 poses centred (0.25, 0.75, 1.25, 1.75); y: 0.6 m -> 2 (0.25, 0.75)
    assert len(poses) == 8
    assert sorted(set(np.round(poses[:, 0], 6))) == [0.25, 0.75, 1.25, 1.75]
    assert sorted(set(np.round(poses[:, 1], 6))) == [0.25, 0.75]
    # boustrophedon: the second row runs backwards, consecutive poses are neighbours
    assert poses[:4, 0] == pytest.approx([0.25, 0.75, 1.25, 1.75])
    assert poses[4:, 0] == pytest.approx([1.75, 1.25, 0.75, 0.25])
    steps = np.linalg.norm(np.diff(poses, axis=0), axis=1)
    assert steps == pytest.approx(0.5)


def test_room_grid_is_free_with_clearance(room):
    poses = exploration_poses(room, 0.25)
    assert 150 < len(poses) < 300
    assert room.free_space(poses).all()
    assert room.wall_distance(poses).min() >= 0.2 - 1e-9
    # lattice spacing: every pose has a neighbour 0.25 m away
    d = np.linalg.norm(poses[:, None] - poses[None], axis=2)
    np.fill_diagonal(d, np.inf)
    assert d.min(axis=1) == pytest.approx(0.25)


def test_wall_distance_hand_checked():
    d = SQUARE.wall_distance(np.array([[1.0, 0.5], [0.1, 0.5], [1.9, 0.95]]))
    assert d == pytest.approx([0.5, 0.1, 0.05])


def test_bad_spacing_is_refused(room):
    with pytest.raises(WorldsError):
        exploration_poses(room, 0.0)
    with pytest.raises(WorldsError):
        exploration_poses(room, float('nan'))
    with pytest.raises(WorldsError):
        exploration_poses(SQUARE, 0.5, clearance=0.6)


def test_run_is_smooth_collision_free_and_within_limits(room, room_run):
    params = RunParameters()
    run = room_run
    assert 30 < run.duration < 80
    assert room.free_space(run.poses[:, :2]).all()
    clearance = room.wall_distance(run.poses[::5, :2])
    assert clearance.min() >= 0.8 * params.clearance
    # a pass near the walls and a pass through the open middle
    assert clearance.min() < 0.6
    assert clearance.max() > 0.9
    v, w = run.velocity[:, 0], run.velocity[:, 1]
    assert v.max() <= params.max_speed + 1e-6 and v.min() >= -1e-9
    assert np.abs(w).max() <= params.max_turn_rate + 1e-6
    assert np.abs(v[0]) < 0.15 and np.abs(v[-2]) < 0.15  # starts and stops (nearly) at rest
    # turns: the heading sweeps more than a full circle in total
    assert np.sum(np.abs(np.diff(run.poses[:, 2]))) > 2 * math.pi
    # positions are continuous (no jumps)
    assert np.linalg.norm(np.diff(run.poses[:, :2], axis=0), axis=1).max() < 0.01
    # the heading follows the direction of motion
    d = np.diff(run.poses[:, :2], axis=0)
    moving = np.linalg.norm(d, axis=1) > 1e-4
    heading = np.arctan2(d[moving, 1], d[moving, 0])
    err = np.abs(np.remainder(heading - run.poses[:-1][moving, 2] + math.pi, 2 * math.pi)
                 - math.pi)
    assert err.max() < 0.05


def test_run_is_deterministic_and_duration_cut(room, room_run):
    again = run_trajectory(room)
    assert np.array_equal(again.poses, room_run.poses)
    short = run_trajectory(room, duration=10.0)
    assert short.duration <= 10.0
    assert short.poses == pytest.approx(room_run.poses[:len(short.times)])


def test_kidnapped_run_teleports_once_halfway(room_run):
    kid = kidnapped_trajectory(room_run)
    assert len(kid.times) == len(room_run.times)
    steps = np.linalg.norm(np.diff(kid.poses[:, :2], axis=0), axis=1)
    jumps = np.flatnonzero(steps > 0.05)
    assert len(jumps) == 1
    assert kid.times[jumps[0] + 1] == pytest.approx(kid.teleport_time)
    assert kid.teleport_time == pytest.approx(room_run.duration / 2, abs=0.05)
    assert steps[jumps[0]] > 1.0
    assert np.all(kid.velocity[jumps[0]] == 0)  # carried: the wheels did not turn
    # pose_at never interpolates across the jump
    before = kid.pose_at(kid.teleport_time - 1e-4)
    assert np.linalg.norm(before[0, :2] - kid.poses[jumps[0], :2]) < 0.01


def test_pose_at_interpolates_and_wraps(room_run):
    t = room_run.times[100] + 0.5 * (room_run.times[101] - room_run.times[100])
    pose = room_run.pose_at(t)[0]
    assert pose[:2] == pytest.approx(0.5 * (room_run.poses[100, :2] + room_run.poses[101, :2]))
    assert -math.pi <= pose[2] < math.pi
