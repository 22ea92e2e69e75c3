"""landmark_db: world instances, region decomposition and the landmark database.

The core of this package imports numpy, scipy and matplotlib only (never rclpy):
the world model of Chapter 3, the rho-MORDP algorithms of Chapters 4 and 5, the
simulator of Chapter 8 and the stored database.
"""
from __future__ import annotations

__version__ = '0.1.0'

__all__ = ['__version__']
