"""vbn_common: what every other package of the project stands on; it stands on none of them.

Core modules (no rclpy): the root error (``errors.py``), atomic output (``atomic.py``),
JSON files (``jsonio.py``), the worker pool (``workers.py``), the region palette
(``palette.py``), bag reading and writing on rosbags (``bags/``), image decoding
(``images.py``), SIFT features (``features.py``), the exploration reader
(``exploration.py``), camera models, frames, transforms and the two-view pose solvers of
the thesis's Chapter 7 (``geometry/``), the contract topic and frame names
(``names.py``) and the ROS environment check (``ros_environment.py``). ROS glue: the
node main, region markers, the ``/tf`` broadcaster and the bag tools over DDS
(``ros_tools/``), ``dds_probe``, the ``vbn`` dispatcher and its commands ``doctor``,
``bag-info``, ``play``, ``record`` and ``echo`` (``cli/``).
"""
from __future__ import annotations

__version__ = '0.1.0'

__all__ = ['__version__']
