"""Errors of the landmark_db package."""
from __future__ import annotations

from vbn_common.errors import VbnError

__all__ = ['LandmarkDbError']


class LandmarkDbError(VbnError):
    """Invalid world, decomposition, scene or database input."""
