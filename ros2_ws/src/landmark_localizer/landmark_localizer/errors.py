"""Errors of the landmark_localizer package."""
from __future__ import annotations

from vbn_common.errors import VbnError

__all__ = ['LocalizerError']


class LocalizerError(VbnError):
    """Invalid database, camera or localizer input, reported in one line."""
