"""The project's errors: ``VbnError`` at the root, and the one class of vbn_common.

``VbnError`` is the root of every user-facing error in the project: the ``vbn`` command
line turns any ``VbnError`` into a one-line message and a non-zero exit, and the nodes
log it in one line. Each package derives its own single exception class from it in its
``errors.py``.
"""
from __future__ import annotations

__all__ = ['NoPoseSourceError', 'VbnCommonError', 'VbnError']


class VbnError(Exception):
    """A problem with the user's input or environment, reported in one line."""


class VbnCommonError(VbnError):
    """Invalid bag, image, camera, geometry or ROS environment input, reported in one line."""


class NoPoseSourceError(VbnCommonError):
    """An exploration bag without poses of its images (no pose topic, no ``map`` on /tf).

    ``vbn build`` then estimates the poses from the images and the odometry.
    """
