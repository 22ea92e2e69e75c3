"""Wheel odometry with seeded drift."""
from __future__ import annotations

import numpy as np
import pytest

from landmark_db.scenes import resolve_scene
from vbn_common.geometry.frames import compose_poses, wrap_angle
from vbn_worlds.synthesis.odometry import OdometryNoise, simulate_odometry
from vbn_worlds.synthesis.trajectory import kidnapped_trajectory, run_trajectory


@pytest.fixture(scope='module')
def run():
    return run_trajectory(resolve_scene('room'))


def _errors(run, odom):
    truth = run.pose_at(odom.times)
    estimate = compose_poses(odom.odom_origin, odom.poses)
    return (np.linalg.norm(estimate[:, :2] - truth[:, :2], axis=1),
            np.abs(wrap_angle(estimate[:, 2] - truth[:, 2])))


def test_noise_free_odometry_follows_ground_truth(run):
    odom = simulate_odometry(run, 50.0, OdometryNoise.none())
    assert odom.times[1] - odom.times[0] == pytest.approx(0.02)
    assert odom.poses[0] == pytest.approx([0, 0, 0])
    position, yaw = _errors(run, odom)
    assert position.max() < 1e-3
    assert yaw.max() < 1e-6
    # the measured twist is the true body velocity
    assert np.abs(odom.twist[:, 0]).max() == pytest.approx(np.abs(run.velocity[:, 0]).max(),
                                                           rel=0.05)


def test_odometry_is_seeded(run):
    a = simulate_odometry(run, rng=3)
    b = simulate_odometry(run, rng=3)
    c = simulate_odometry(run, rng=4)
    assert np.array_equal(a.poses, b.poses)
    assert not np.array_equal(a.poses, c.poses)


def test_drift_grows_with_distance_and_stays_realistic(run):
    quarter, half, end = [], [], []
    for seed in range(24):
        position, _ = _errors(run, simulate_odometry(run, rng=seed))
        n = len(position)
        quarter.append(position[n // 4])
        half.append(position[n // 2])
        end.append(position[-1])
    assert np.mean(quarter) < np.mean(end)
    assert np.mean(half) < np.mean(end)
    assert np.mean(end) > 0.05  # there is drift
    travelled = np.sum(np.abs(run.velocity[:-1, 0]) * np.diff(run.times))
    assert np.mean(end) < 0.1 * travelled  # a few percent of the distance driven
    # the reported variance grows along the run
    odom = simulate_odometry(run, rng=0)
    assert np.all(np.diff(odom.pose_variance[:, 0]) >= 0)
    assert odom.pose_variance[-1, 0] > odom.pose_variance[10, 0]


def test_kidnapping_leaves_no_trace_in_odometry(run):
    kid = kidnapped_trajectory(run)
    odom = simulate_odometry(kid, rng=0)
    steps = np.linalg.norm(np.diff(odom.poses[:, :2], axis=0), axis=1)
    assert steps.max() < 0.02  # 50 Hz at <= 0.4 m/s: continuous, even across the teleport
    position, _ = _errors(kid, odom)
    at = np.searchsorted(odom.times, kid.teleport_time)
    assert position[at + 5] > position[at - 5] + 1.0  # the ground truth jumped away


def test_a_slipping_wheel_runs_ahead_by_a_fifth_of_the_path_in_its_window(run):
    from dataclasses import replace

    clean = simulate_odometry(run, noise=OdometryNoise.none())
    slipping = simulate_odometry(run, noise=replace(OdometryNoise.none(), slip=((10.0, 11.0),)))
    step = np.linalg.norm(np.diff(clean.poses[:, :2], axis=0), axis=1)
    slipped = np.linalg.norm(np.diff(slipping.poses[:, :2], axis=0), axis=1)
    inside = (clean.times[:-1] + 0.01 >= 10.0) & (clean.times[:-1] + 0.01 < 11.0)
    assert step[inside].sum() > 0.1
    np.testing.assert_allclose(slipped[inside], 1.2 * step[inside], rtol=1e-5)  # arcs: chords
    np.testing.assert_allclose(slipped[~inside], step[~inside], rtol=1e-9, atol=1e-12)


def test_run_rates_and_faults_are_checked():
    from vbn_worlds.errors import WorldsError
    from vbn_worlds.synthesis.bags import BagSpec

    BagSpec(kind='run', rate_hz=2.0, slip_bursts=3, odom_dropouts=3).check()
    for bad in (dict(kind='run', rate_hz=3.0), dict(kind='run', rate_hz=100.0),
                dict(kind='exploration', slip_bursts=1), dict(kind='run', odom_dropouts=-1)):
        with pytest.raises(WorldsError):
            BagSpec(**bad).check()
