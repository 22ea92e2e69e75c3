"""Errors of the visibility_builder package."""
from __future__ import annotations

from vbn_common.errors import VbnError

__all__ = ['VisibilityBuilderError']


class VisibilityBuilderError(VbnError):
    """Invalid bag, scene, image or builder input, reported in one line."""
