"""The odometry's wheels calibrated by the images' turns (``estimation/scale.py``).

A differential-drive robot with wheels of known scale errors drives a hand-made path
(straight legs and turns in place); its odometry is integrated from the wheels as a
robot's driver does, and the images' headings are the true ones.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from vbn_common.geometry.frames import wrap_angle
from visibility_builder.estimation.scale import (
    MAX_SCALE_STD,
    MAX_TURN_ERROR,
    calibrate_wheels,
    recalibrated_poses,
    signed_motion,
    turn_sigmas,
)

DT = 0.02
BASE = 0.35
T0 = 1_700_000_000 * 10**9


def _integrate(v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Return ``(m, 3)`` poses integrated from ``(x, y, yaw) = 0`` (exact arcs)."""
    turn = w * DT
    yaw = np.concatenate([[0.0], np.cumsum(turn)])
    mid = yaw[:-1] + turn / 2
    with np.errstate(invalid='ignore', divide='ignore'):
        chord = np.where(np.abs(turn) > 1e-12, np.sin(turn / 2) / (turn / 2), 1.0)
    x = np.concatenate([[0.0], np.cumsum(v * DT * chord * np.cos(mid))])
    y = np.concatenate([[0.0], np.cumsum(v * DT * chord * np.sin(mid))])
    return np.stack([x, y, yaw], axis=1)


def _drive(legs: list[tuple[float, float]], scales: tuple[float, float],
           noise: float = 0.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drive ``legs`` (metres forward, then radians turned in place), an image after each.

    Returns the odometry track ``(stamp_ns, x, y, yaw)``, the image stamps and the
    images' true poses. ``scales`` are the (left, right) wheels' measured travel per
    true metre; ``noise`` the relative noise of each wheel's speed per sample.
    """
    v, w, image_at = [], [], []
    for metres, turn in legs:
        steps = max(int(round(abs(metres) / (0.3 * DT))), 1)       # 0.3 m/s
        v += [metres / (steps * DT)] * steps
        w += [0.0] * steps
        steps = max(int(round(abs(turn) / (1.0 * DT))), 1)         # 1 rad/s
        v += [0.0] * steps
        w += [turn / (steps * DT)] * steps
        v += [0.0] * 5                                   # standing for the image
        w += [0.0] * 5
        image_at.append(len(v))
    v_true, w_true = np.array(v), np.array(w)
    left, right = v_true - w_true * BASE / 2, v_true + w_true * BASE / 2
    rng = np.random.default_rng(seed)
    left = left * scales[0] * (1 + rng.normal(0, noise, len(left)))
    right = right * scales[1] * (1 + rng.normal(0, noise, len(right)))
    odometry = _integrate((left + right) / 2, (right - left) / BASE)
    truth = _integrate(v_true, w_true)
    stamps = T0 + np.arange(len(odometry), dtype=np.int64) * int(DT * 1e9)
    track = np.column_stack([stamps.astype(float), odometry[:, :2], wrap_angle(odometry[:, 2])])
    images = np.array([0] + image_at)
    truth[:, 2] = wrap_angle(truth[:, 2])
    return track, stamps[images], truth[images]


#: A tour of a room: legs of 0.25 to 1 m and turns either way, some beyond half a circle.
LEGS = [(1.0, math.pi / 2), (0.5, -math.pi / 2), (0.25, 3 * math.pi / 4), (0.75, -math.pi),
        (0.5, math.pi / 3), (1.0, -2 * math.pi / 3), (0.25, 1.3 * math.pi),
        (0.5, -math.pi / 4)] * 3


def _odometry_poses(track: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    at = np.searchsorted(track[:, 0].astype(np.int64), stamps, side='right') - 1
    return track[at, 1:].copy()


def _steps(motion: np.ndarray) -> np.ndarray:
    return np.abs(motion)


def test_signed_motion_keeps_the_sign_and_turns_beyond_half_a_circle() -> None:
    track, stamps, truth = _drive([(1.0, 0.0), (0.0, 1.3 * math.pi), (-0.5, 0.0)], (1, 1))
    motion = signed_motion(track, stamps)
    assert motion == pytest.approx(np.array([[1.0, 0.0], [0.0, 1.3 * math.pi],
                                             [-0.5, 0.0]]), abs=1e-9)
    # an image before the first sample has no motion to it
    early = signed_motion(track, np.concatenate([[T0 - 10**9], stamps]))
    assert np.isnan(early[0]).all() and np.isfinite(early[1:]).all()


@pytest.mark.parametrize('scales', [(1.0, 1.0), (1.004, 1.004), (0.997, 1.002),
                                    (1.01, 0.995)])
def test_exact_wheels_are_recovered_without_noise(scales) -> None:
    track, stamps, truth = _drive(LEGS, scales)
    motion = signed_motion(track, stamps)
    wheels = calibrate_wheels(truth[:, 2], motion, np.ones(len(motion), bool),
                              turn_sigmas(_steps(motion)))
    a, c = 1 / scales[1], 1 / scales[0]
    assert wheels.applied and wheels.rejected == 0 and wheels.note == ''
    assert wheels.distance_scale == pytest.approx((a + c) / 2, abs=1e-9)
    assert wheels.turn_per_metre == pytest.approx((a - c) / BASE, abs=1e-8)
    assert wheels.segments == len(LEGS)
    assert wheels.turned_rad == pytest.approx(sum(abs(t) for _, t in LEGS) * scales[0],
                                              rel=0.02)
    # integrated again, the odometry is the truth: exactly when both wheels err alike,
    # within the left-out q b^2 / 4 term (a fraction of a millimetre a turn) otherwise
    fixed = recalibrated_poses(track, stamps, _odometry_poses(track, stamps), wheels)
    error = np.linalg.norm(fixed[:, :2] - truth[:, :2], axis=1)
    before = np.linalg.norm(_odometry_poses(track, stamps)[:, :2] - truth[:, :2], axis=1)
    bound = 1e-9 + abs(a - c) * BASE / 4 * sum(abs(t) for _, t in LEGS)
    assert error.max() <= bound
    assert np.abs(wrap_angle(fixed[:, 2] - truth[:, 2])).max() < 1e-8 + 10 * abs(a - c)
    if scales != (1.0, 1.0):
        assert error.max() < before.max() / 5


def test_the_first_image_keeps_its_pose() -> None:
    track, stamps, truth = _drive(LEGS, (1.003, 0.998))
    odometry = _odometry_poses(track, stamps) + np.array([2.0, -1.0, 0.3])
    motion = signed_motion(track, stamps)
    wheels = calibrate_wheels(truth[:, 2], motion, np.ones(len(motion), bool),
                              turn_sigmas(_steps(motion)))
    fixed = recalibrated_poses(track, stamps, odometry, wheels)
    assert fixed[0] == pytest.approx(odometry[0], abs=1e-12)


def test_noisy_wheels_are_recovered_within_the_stated_deviation() -> None:
    """Twenty draws of 2 % speed noise per sample: the error stays within 4 stated stds."""
    scales = (0.994, 0.998)
    truth_p = (1 / scales[0] + 1 / scales[1]) / 2
    errors = []
    for seed in range(20):
        track, stamps, truth = _drive(LEGS, scales, noise=0.02, seed=seed)
        motion = signed_motion(track, stamps)
        yaw = truth[:, 2] + np.random.default_rng(100 + seed).normal(0, 1.7e-4, len(truth))
        wheels = calibrate_wheels(yaw, motion, np.ones(len(motion), bool),
                                  turn_sigmas(_steps(motion)))
        assert wheels.applied
        assert abs(wheels.distance_scale - truth_p) <= 4 * wheels.distance_scale_std
        errors.append(wheels.distance_scale - truth_p)
    # the wheels' own common error is 0.4 %; the calibration's a quarter of it at most
    # (24 segments; an exploration has hundreds)
    assert np.sqrt(np.mean(np.square(errors))) < 1e-3


def test_a_wrong_image_heading_is_left_out() -> None:
    track, stamps, truth = _drive(LEGS, (0.997, 1.002))
    motion = signed_motion(track, stamps)
    yaw = truth[:, 2].copy()
    yaw[7:] += math.radians(5)                         # one segment turns 5 degrees more
    wheels = calibrate_wheels(yaw, motion, np.ones(len(motion), bool),
                              turn_sigmas(_steps(motion)))
    assert wheels.rejected == 1 and wheels.applied
    assert wheels.distance_scale == pytest.approx((1 / 0.997 + 1 / 1.002) / 2, abs=1e-9)


def test_segments_between_pieces_do_not_count() -> None:
    track, stamps, truth = _drive(LEGS, (0.997, 1.002))
    motion = signed_motion(track, stamps)
    yaw = truth[:, 2] + np.arange(len(truth)) * 1.0     # headings of unrelated pieces
    wheels = calibrate_wheels(yaw, motion, np.zeros(len(motion), bool),
                              turn_sigmas(_steps(motion)))
    assert wheels.segments == 0 and not wheels.applied
    assert 'at least 360 deg over 10 needed' in wheels.note


def test_too_little_turning_is_not_used() -> None:
    track, stamps, truth = _drive([(0.5, 0.02), (0.5, -0.02)] * 8, (1.004, 1.0))
    motion = signed_motion(track, stamps)
    wheels = calibrate_wheels(truth[:, 2], motion, np.ones(len(motion), bool),
                              turn_sigmas(_steps(motion)))
    assert not wheels.applied and 'turn' in wheels.note
    assert wheels.line().startswith('wheels not calibrated (the images turn')


def test_turns_that_are_not_the_wheels_are_refused() -> None:
    """An odometry whose heading is a gyro's: its turns are right, its distances not."""
    track, stamps, truth = _drive(LEGS, (1.0, 1.0))
    motion = signed_motion(track, stamps)
    wheels = calibrate_wheels(truth[:, 2], motion * np.array([1.0, 0.9]),
                              np.ones(len(motion), bool), turn_sigmas(_steps(motion)))
    assert not wheels.applied
    assert wheels.distance_scale == pytest.approx(1 / 0.9, rel=1e-6)
    assert abs(wheels.distance_scale - 1) > MAX_TURN_ERROR
    assert 'gyro' in wheels.note and '-10.0 %' in wheels.note


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_loose_calibration_is_used_only_when_the_wheels_are_measurably_off(seed) -> None:
    """15 % speed noise, 12 segments: the scale to about 0.5 %, not good enough alone."""
    for scales, used in (((0.97, 0.975), True), ((1.0, 1.0), False)):
        track, stamps, truth = _drive(LEGS[:12], scales, noise=0.15, seed=seed)
        motion = signed_motion(track, stamps)
        wheels = calibrate_wheels(truth[:, 2], motion, np.ones(len(motion), bool),
                                  turn_sigmas(_steps(motion)))
        assert wheels.distance_scale_std > MAX_SCALE_STD
        assert wheels.applied == used
        if not used:
            assert 'its correction is within 3 of that' in wheels.note
