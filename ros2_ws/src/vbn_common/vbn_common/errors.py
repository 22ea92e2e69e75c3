"""Errors of the vbn_common package."""
from __future__ import annotations

from landmark_db.errors import VbnError

__all__ = ['VbnCommonError']


class VbnCommonError(VbnError):
    """Invalid bag, image, camera, geometry or ROS environment input, reported in one line."""
