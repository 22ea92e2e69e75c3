"""Wheel odometry with seeded drift for the synthetic run bags.

A differential-drive robot measures its wheel speeds; odometry integrates them.
The true body velocity ``(v, omega)`` of a :class:`~.trajectory.Trajectory` gives
the true wheel speeds ``v -/+ omega * b / 2`` (``b`` the wheel base). Each wheel's
measurement carries a constant calibration error (a scale factor drawn once per
run: the systematic part of the drift) and white noise per sample, proportional to
the wheel's speed plus a small floor. Integrating the measured speeds (exact arc
per step) gives the pose in ``odom``, which starts at the identity where the robot
starts, so ``map -> odom`` is the first ground-truth pose. The error therefore grows
with the distance driven, as real odometry does. A teleport (kidnapped robot) does
not turn the wheels and leaves no trace in the odometry.

Wheel slip (``slip`` windows): in each, both wheels' measured speeds are ``1 +
slip_scale`` times what the robot moves (the wheels spin on a smooth floor), so the
odometry runs ahead by that share of the path driven in the window.

The covariance reported with each pose is a simple model of that growth, not a
propagated estimate: per step the variance in ``x`` and ``y`` grows by
``(k_trans * ds)^2`` and in yaw by ``(k_rot * |dtheta| + k_drift * ds)^2``.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from vbn_common.geometry.frames import wrap_angle
from vbn_worlds.errors import WorldsError
from vbn_worlds.synthesis.trajectory import Trajectory

__all__ = ['OdometryNoise', 'OdometryTrack', 'simulate_odometry']


@dataclass(frozen=True)
class OdometryNoise:
    """Wheel-odometry error model (all fractions are of the wheel speed).

    Attributes:
        wheel_base: distance between the wheels, metres.
        scale_error: standard deviation of each wheel's constant scale error.
        speed_noise: standard deviation of the per-sample relative speed noise.
        speed_noise_floor: standard deviation of additive speed noise, m/s.
        slip: ``(start, end)`` seconds of the windows where the wheels slip.
        slip_scale: how much faster the slipping wheels turn than the robot moves.
    """

    wheel_base: float = 0.35
    scale_error: float = 0.003
    speed_noise: float = 0.02
    speed_noise_floor: float = 0.002
    slip: tuple[tuple[float, float], ...] = ()
    slip_scale: float = 0.2

    @staticmethod
    def none() -> OdometryNoise:
        """Return a noise-free model (odometry equals ground truth)."""
        return OdometryNoise(scale_error=0.0, speed_noise=0.0, speed_noise_floor=0.0)


@dataclass(frozen=True)
class OdometryTrack:
    """Odometry samples.

    Attributes:
        times: ``(n,)`` seconds from the start of the trajectory.
        poses: ``(n, 3)`` ``base_link`` pose ``(x, y, yaw)`` in ``odom`` (yaw wrapped).
        twist: ``(n, 2)`` measured ``(v, omega)`` in ``base_link``.
        pose_variance: ``(n, 3)`` modelled variances of ``x``, ``y``, ``yaw``.
        twist_variance: ``(2,)`` variances of the measured ``v`` and ``omega``
            (at top speed).
        odom_origin: ``(3,)`` ground-truth pose where ``odom`` starts (``map -> odom``).
    """

    times: np.ndarray
    poses: np.ndarray
    twist: np.ndarray
    pose_variance: np.ndarray
    twist_variance: np.ndarray
    odom_origin: np.ndarray


def simulate_odometry(trajectory: Trajectory, rate_hz: float = 50.0,
                      noise: OdometryNoise | None = None,
                      rng: np.random.Generator | int | None = 0) -> OdometryTrack:
    """Simulate wheel odometry along ``trajectory`` (see the module docstring).

    Args:
        trajectory: the ground truth; its ``velocity`` drives the wheels.
        rate_hz: odometry rate, Hz.
        noise: error model; default :class:`OdometryNoise`.
        rng: generator or seed for the errors.

    Returns:
        The odometry at ``0, 1/rate_hz, ...`` up to the trajectory's duration.
    """
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise WorldsError(f'odometry rate must be positive, got {rate_hz}')
    noise = noise or OdometryNoise()
    rng = np.random.default_rng(rng)
    dt = 1.0 / rate_hz
    times = np.arange(0.0, trajectory.duration + 1e-9, dt)
    # Mean true body velocity over each odometry step, from the fine trajectory.
    fine_t = trajectory.times
    cum = np.concatenate([[[0.0, 0.0]], np.cumsum(trajectory.velocity[:-1]
                                                  * np.diff(fine_t)[:, None], axis=0)])
    integral = np.stack([np.interp(times, fine_t, cum[:, k]) for k in range(2)], axis=1)
    mean_vel = np.diff(integral, axis=0) / dt  # (n - 1, 2)
    b = noise.wheel_base
    left = mean_vel[:, 0] - mean_vel[:, 1] * b / 2
    right = mean_vel[:, 0] + mean_vel[:, 1] * b / 2
    scale = 1.0 + rng.normal(0.0, noise.scale_error, size=2)
    steps = len(mean_vel)
    rel = rng.normal(0.0, noise.speed_noise, size=(steps, 2))
    floor = rng.normal(0.0, noise.speed_noise_floor, size=(steps, 2))
    left_m = left * scale[0] * (1 + rel[:, 0]) + floor[:, 0] * (np.abs(left) > 1e-6)
    right_m = right * scale[1] * (1 + rel[:, 1]) + floor[:, 1] * (np.abs(right) > 1e-6)
    if noise.slip:
        middle = times[:-1] + dt / 2
        slipping = np.zeros(steps, bool)
        for start, end in noise.slip:
            slipping |= (middle >= start) & (middle < end)
        left_m = np.where(slipping, left_m * (1 + noise.slip_scale), left_m)
        right_m = np.where(slipping, right_m * (1 + noise.slip_scale), right_m)
    v = 0.5 * (left_m + right_m)
    w = (right_m - left_m) / b
    # Integrate: exact arc per step.
    dtheta = w * dt
    ds = v * dt
    theta = np.concatenate([[0.0], np.cumsum(dtheta)])
    mid = theta[:-1] + 0.5 * dtheta
    with np.errstate(invalid='ignore', divide='ignore'):
        chord = np.where(np.abs(dtheta) > 1e-9, np.sin(dtheta / 2) / (dtheta / 2), 1.0)
    x = np.concatenate([[0.0], np.cumsum(ds * chord * np.cos(mid))])
    y = np.concatenate([[0.0], np.cumsum(ds * chord * np.sin(mid))])
    poses = np.stack([x, y, wrap_angle(theta)], axis=1)
    twist = np.concatenate([np.stack([v, w], axis=1), [[v[-1], w[-1]]]]) if steps else (
        np.zeros((1, 2)))
    k_trans, k_rot, k_drift = 0.02, 0.02, 0.005
    var_xy = np.concatenate([[0.0], np.cumsum((k_trans * np.abs(ds)) ** 2)]) + 1e-6
    var_yaw = np.concatenate([[0.0], np.cumsum((k_rot * np.abs(dtheta)
                                                + k_drift * np.abs(ds)) ** 2)]) + 1e-6
    pose_variance = np.stack([var_xy, var_xy, var_yaw], axis=1)
    sigma_v = noise.speed_noise * 0.4 + noise.speed_noise_floor + 1e-3
    twist_variance = np.array([sigma_v ** 2, (2 * sigma_v / b) ** 2])
    origin = trajectory.poses[0].copy()
    origin[2] = math.remainder(origin[2], 2 * math.pi)
    return OdometryTrack(times, poses, twist, pose_variance, twist_variance, origin)
