"""landmark_db: world instances, region decomposition and the landmark database.

The world model of Chapter 3 (world instances and polygon scenes, with the shipped
``room`` and ``floor``), the rho-MORDP algorithms of Chapters 4 and 5 and the stored
database. Stands on ``vbn_common``; imports numpy and scipy, never rclpy.
"""
from __future__ import annotations

__version__ = '0.1.0'

__all__ = ['__version__']
