"""vbn_worlds: the worlds the project tests and measures itself in; a robot installs none of it.

The renderer of 2.5-D scenes through every camera model (``render/``), the synthesis of
exploration and run bags from it, with odometry, people, light and world changes
(``synthesis/``), the random worlds of the thesis's Chapter 8 simulator (``simulator/``),
and the ``vbn render`` and ``vbn simulate`` commands (``cli/``). Stands on ``vbn_common``
and ``landmark_db``; no rclpy.
"""
from __future__ import annotations

__all__: list[str] = []
