"""Bag synthesis: exploration grids, run trajectories, odometry and bag writing.

Core modules (no rclpy): :mod:`.grid` (exploration poses), :mod:`.trajectory`
(smooth runs, kidnapped variant), :mod:`.odometry` (wheel odometry with seeded
drift). :mod:`.messages` converts to ROS 2 messages (rosbags types) and
:mod:`.bags` writes the bags through :mod:`vbn_common.bags`.
"""
from __future__ import annotations

from vbn_worlds.synthesis.grid import exploration_poses
from vbn_worlds.synthesis.odometry import (
    OdometryNoise,
    OdometryTrack,
    simulate_odometry,
)
from vbn_worlds.synthesis.trajectory import (
    RunParameters,
    Trajectory,
    kidnapped_trajectory,
    run_trajectory,
)

__all__ = [
    'OdometryNoise',
    'OdometryTrack',
    'RunParameters',
    'Trajectory',
    'exploration_poses',
    'kidnapped_trajectory',
    'run_trajectory',
    'simulate_odometry',
]
