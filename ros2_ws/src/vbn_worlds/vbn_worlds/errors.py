"""Errors of the vbn_worlds package."""
from __future__ import annotations

from vbn_common.errors import VbnError

__all__ = ['WorldsError']


class WorldsError(VbnError):
    """Invalid scene, camera, path or rendering input, reported in one line."""
