"""An exploration driven stop and go between its grid positions, with wheel odometry."""
from __future__ import annotations

import math

import numpy as np
import pytest

from landmark_db.scene import Scene
from landmark_db.scenes import resolve_scene
from vbn_common.geometry.frames import compose_poses, wrap_angle
from vbn_worlds.errors import WorldsError
from vbn_worlds.synthesis.bags import BagSpec, write_bag
from vbn_worlds.synthesis.exploration_drive import driven_exploration, visiting_order
from vbn_worlds.synthesis.grid import exploration_poses
from vbn_worlds.synthesis.odometry import OdometryNoise, simulate_odometry
from vbn_worlds.synthesis.trajectory import RunParameters


@pytest.fixture(scope='module')
def room():
    return resolve_scene('room')


def _square_with_wall() -> Scene:
    """A 4 m square with a wall from the bottom up to y = 3 at x = 2: legs must go round."""
    perimeter = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], float)
    wall = np.array([[1.95, -0.1], [2.05, -0.1], [2.05, 3.0], [1.95, 3.0]], float)
    return Scene(perimeter=perimeter, obstacles=(wall,))


def test_hand_checked_two_positions_one_heading() -> None:
    scene = Scene(perimeter=np.array([[0, 0], [3, 0], [3, 2], [0, 2]], float))
    driven = driven_exploration(scene, np.array([[1.0, 1.0], [1.0, 1.5]]), 1,
                                RunParameters(), 0.2)
    # the first image at the start, yaw 0; the robot then turns left by 90 degrees and
    # drives 0.5 m: the second image at the arrival heading
    expected = np.array([[1.0, 1.0, 0.0], [1.0, 1.5, math.pi / 2]])
    assert driven.image_poses == pytest.approx(expected)
    assert driven.image_positions.tolist() == [0, 1]
    traj = driven.trajectory
    # velocities integrate exactly to the sampled poses (pure turns and straight drives)
    dt = np.diff(traj.times)
    heading = traj.poses[:-1, 2]
    moved = np.stack([np.cos(heading), np.sin(heading)], axis=1) * \
        (traj.velocity[:-1, :1] * dt[:, None])
    assert np.cumsum(moved, axis=0)[-1] == pytest.approx(traj.poses[-1, :2] - traj.poses[0, :2])
    assert np.sum(traj.velocity[:-1, 1] * dt) == pytest.approx(math.pi / 2)
    assert np.abs(traj.velocity[:, 0]).max() <= RunParameters().max_speed + 1e-9
    assert np.abs(traj.velocity[:, 1]).max() <= RunParameters().max_turn_rate + 1e-9
    # standing at each image
    for t in driven.image_times:
        k = int(round(t / RunParameters().dt))
        assert np.all(traj.velocity[k - 5:k + 5] == 0)


def test_headings_turn_nearest_first_and_each_image_stands(room) -> None:
    positions = exploration_poses(room, 1.0)[:3]
    driven = driven_exploration(room, positions, 4, RunParameters(), 0.2)
    assert len(driven.image_times) == 12
    assert np.all(np.diff(driven.image_times) > 0)
    assert driven.image_positions.tolist() == [0] * 4 + [1] * 4 + [2] * 4
    yaws = np.degrees(driven.image_poses[:, 2]) % 360
    for i in range(3):
        assert sorted(np.round(yaws[4 * i:4 * i + 4]) % 360) == [0, 90, 180, 270]
    assert driven.image_poses[:, :2] == pytest.approx(np.repeat(positions, 4, axis=0))
    truth = driven.trajectory.pose_at(driven.image_times)
    assert truth[:, :2] == pytest.approx(driven.image_poses[:, :2])
    assert np.abs(wrap_angle(truth[:, 2] - driven.image_poses[:, 2])).max() < 1e-9


def test_legs_go_round_an_obstacle() -> None:
    scene = _square_with_wall()
    positions = np.array([[1.0, 0.5], [3.0, 0.5]])
    driven = driven_exploration(scene, positions, 1, RunParameters(), 0.2)
    path = driven.trajectory.poses[:, :2]
    assert scene.free_space(path).all()
    assert path[:, 1].max() > 3.0   # over the end of the wall
    assert driven.image_poses[-1, :2] == pytest.approx([3.0, 0.5])


def test_visiting_order_goes_to_the_nearest_reachable_position() -> None:
    scene = _square_with_wall()
    grid = np.array([[x, y] for y in (0.5, 1.5, 2.5, 3.5) for x in (0.5, 1.5, 2.5, 3.5)])
    grid = grid[scene.free_space(grid)]
    order = visiting_order(scene, grid, 0.2)
    assert sorted(order.tolist()) == list(range(len(grid)))
    assert order[0] == 0
    steps = np.linalg.norm(np.diff(grid[order], axis=0), axis=1)
    assert np.count_nonzero(steps > 1.0 + 1e-9) <= 1 and steps.max() <= 2.0 + 1e-9
    # the left room (x < 2) is done before the robot crosses over the wall's end
    left = grid[order, 0] < 2.0
    switches = np.count_nonzero(np.diff(left.astype(int)))
    assert switches == 1


def test_noise_free_odometry_reproduces_the_ground_truth(room) -> None:
    positions = exploration_poses(room, 0.75)
    driven = driven_exploration(room, positions, 1, RunParameters(), 0.2)
    odom = simulate_odometry(driven.trajectory, 50.0, OdometryNoise.none())
    truth = driven.trajectory.pose_at(odom.times)
    estimate = compose_poses(odom.odom_origin, odom.poses)
    assert np.linalg.norm(estimate[:, :2] - truth[:, :2], axis=1).max() < 1e-6
    assert np.abs(wrap_angle(estimate[:, 2] - truth[:, 2])).max() < 1e-6


def test_driven_exploration_bag(tmp_path, room) -> None:
    from vbn_bench.localization.pose_bags import read_run_bag

    spec = BagSpec(kind='exploration', camera='panoramic', width=128, height=32,
                   spacing=1.0, odometry=True, drift=3.0, seed=2)
    summary = write_bag(room, spec, tmp_path / 'driven')
    n = len(exploration_poses(room, 1.0))
    assert summary.images == n
    assert summary.counts['/odom'] == summary.counts['/tf'] > 20 * n
    run = read_run_bag(tmp_path / 'driven')
    grid = exploration_poses(room, 1.0)
    order = visiting_order(room, grid, 0.2)
    assert run.truth_poses[:, :2] == pytest.approx(grid[order])
    assert set(np.diff(run.odom_stamps_ns)) == {20_000_000}
    assert np.isin(run.stamps_ns, run.odom_stamps_ns).all()   # images on odometry ticks
    # odometry starts where the robot starts and drifts from the truth with the path
    at_images = run.odom_poses[np.searchsorted(run.odom_stamps_ns, run.stamps_ns)]
    placed = compose_poses(run.truth_poses[0], at_images)
    error = np.linalg.norm(placed[:, :2] - run.truth_poses[:, :2], axis=1)
    assert error[0] == pytest.approx(0.0, abs=1e-9)
    assert error[-1] > 0.01
    # the same bag without drift: odometry is the truth
    spec0 = BagSpec(kind='exploration', camera='panoramic', width=128, height=32,
                    spacing=1.0, odometry=True, drift=0.0, seed=2)
    write_bag(room, spec0, tmp_path / 'exact')
    run0 = read_run_bag(tmp_path / 'exact')
    at_images = run0.odom_poses[np.searchsorted(run0.odom_stamps_ns, run0.stamps_ns)]
    placed = compose_poses(run0.truth_poses[0], at_images)
    assert np.abs(placed[:, :2] - run0.truth_poses[:, :2]).max() < 1e-6


def test_bad_driven_specs_are_refused(tmp_path, room) -> None:
    with pytest.raises(WorldsError, match='odometry is for explorations'):
        write_bag(room, BagSpec(kind='run', odometry=True), tmp_path / 'a')
    with pytest.raises(WorldsError, match='drift must be'):
        write_bag(room, BagSpec(kind='exploration', odometry=True, drift=-1.0),
                  tmp_path / 'b')
    assert not (tmp_path / 'a').exists() and not (tmp_path / 'b').exists()
