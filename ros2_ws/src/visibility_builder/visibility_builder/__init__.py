"""visibility_builder: from exploration bags to the landmark database.

Core modules (no rclpy): bag reading and writing on rosbags, image decoding,
SIFT features, correspondence classes, filters, image pose estimation, and the
renderer that synthesises bags. ROS glue (nodes, DDS tools) lives in the few
modules that say so in their docstring.
"""
from __future__ import annotations

__version__ = '0.1.0'

__all__ = ['__version__']
