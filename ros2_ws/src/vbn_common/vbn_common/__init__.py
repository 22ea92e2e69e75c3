"""vbn_common: what the builder and the localizer both stand on.

Core modules (no rclpy): bag reading and writing on rosbags (``bags/``), image decoding
(``images.py``), SIFT features (``features.py``), the exploration reader
(``exploration.py``), camera models, frames, transforms and the two-view pose solvers of
the thesis's Chapter 7 (``geometry/``), the contract topic and frame names
(``names.py``) and the ROS environment check (``ros_environment.py``). ROS glue: the
node main, region markers, the ``/tf`` broadcaster and the bag tools over DDS
(``ros_tools/``), ``dds_probe`` and the ``vbn`` commands ``doctor``, ``bag-info``,
``play``, ``record`` and ``echo`` (``cli/``).
"""
from __future__ import annotations

__version__ = '0.1.0'

__all__ = ['__version__']
