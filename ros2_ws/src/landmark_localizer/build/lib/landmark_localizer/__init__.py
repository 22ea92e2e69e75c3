"""landmark_localizer: view-based localization against the landmark database.

Core modules (no rclpy): voting, tracking, region switching, pose solvers and the
localizer state machine; the node module is the only ROS glue.
"""
from __future__ import annotations

__version__ = '0.1.0'

__all__ = ['__version__']
