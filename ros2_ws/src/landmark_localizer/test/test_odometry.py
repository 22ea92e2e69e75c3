"""The odometry buffer: interpolation at image stamps; NaN, jumps and time going back."""
from __future__ import annotations

import math

import numpy as np
import pytest

from landmark_localizer.odometry import (
    ACCEPTED,
    JUMP,
    NOT_FINITE,
    TIME_BACK,
    OdometryBuffer,
)

MS = 1_000_000


def straight(buffer: OdometryBuffer, n: int = 6, speed: float = 0.5, t0: int = 0) -> None:
    """Messages every 20 ms along x at ``speed`` m/s."""
    for i in range(n):
        t = t0 + 20 * MS * i
        assert buffer.add(t, np.array([speed * t / 1e9, 0.0, 0.1])) == ACCEPTED


def test_interpolates_between_messages() -> None:
    buffer = OdometryBuffer()
    straight(buffer)
    np.testing.assert_allclose(buffer.at(50 * MS), [0.025, 0.0, 0.1], atol=1e-12)
    np.testing.assert_allclose(buffer.at(40 * MS), [0.02, 0.0, 0.1], atol=1e-12)


def test_yaw_takes_the_shorter_arc() -> None:
    buffer = OdometryBuffer()
    buffer.add(0, np.array([0.0, 0.0, math.pi - 0.1]))
    buffer.add(100 * MS, np.array([0.0, 0.0, -math.pi + 0.1]))
    assert abs(abs(buffer.at(50 * MS)[2]) - math.pi) < 1e-9


def test_extrapolates_only_a_little() -> None:
    buffer = OdometryBuffer(max_extrapolation_s=0.1)
    straight(buffer)  # last message at 100 ms, x = 0.05
    np.testing.assert_allclose(buffer.at(150 * MS)[:2], [0.075, 0.0], atol=1e-12)
    assert buffer.at(250 * MS) is None
    assert buffer.at(-150 * MS) is None
    np.testing.assert_allclose(buffer.at(-50 * MS), [0.0, 0.0, 0.1])


def test_one_message_is_not_yet_a_track() -> None:
    buffer = OdometryBuffer()
    assert buffer.add(0, np.zeros(3)) == ACCEPTED
    assert buffer.at(0) is None and len(buffer) == 0
    buffer.add(20 * MS, np.zeros(3))
    assert len(buffer) == 2 and buffer.latest_stamp == 20 * MS


def test_nan_empties_the_buffer() -> None:
    buffer = OdometryBuffer()
    straight(buffer)
    assert buffer.add(120 * MS, np.array([np.nan, 0.0, 0.0])) == NOT_FINITE
    assert buffer.at(100 * MS) is None
    straight(buffer, t0=140 * MS)
    assert buffer.at(160 * MS) is not None


def test_a_single_outlier_is_never_used() -> None:
    buffer = OdometryBuffer(max_jump_m=1.0)
    straight(buffer)
    assert buffer.add(120 * MS, np.array([5.0, 0.0, 0.1])) == JUMP
    assert buffer.at(120 * MS) is None  # the outlier alone is not a track
    assert buffer.add(140 * MS, np.array([0.07, 0.0, 0.1])) == JUMP
    assert buffer.add(160 * MS, np.array([0.08, 0.0, 0.1])) == ACCEPTED
    pose = buffer.at(150 * MS)
    assert pose is not None and pose[0] == pytest.approx(0.075)


def test_a_reset_odometry_starts_a_new_track() -> None:
    buffer = OdometryBuffer(max_jump_m=1.0)
    straight(buffer, t0=0)
    buffer.add(120 * MS, np.array([10.0, 0.0, 0.0]))
    buffer.add(140 * MS, np.array([10.01, 0.0, 0.0]))
    assert buffer.at(130 * MS)[0] == pytest.approx(10.005)


def test_time_going_back_restarts() -> None:
    buffer = OdometryBuffer()
    straight(buffer, t0=10_000 * MS)
    assert buffer.add(0, np.zeros(3)) == TIME_BACK
    assert buffer.at(10_050 * MS) is None
    buffer.add(20 * MS, np.zeros(3))
    assert buffer.at(10 * MS) is not None


def test_history_is_bounded() -> None:
    buffer = OdometryBuffer(horizon_s=1.0)
    straight(buffer, n=500, speed=0.01)  # 10 s at 50 Hz
    assert len(buffer) <= 52
