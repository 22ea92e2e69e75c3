"""Errors of the landmark_db package.

``VbnError`` is the root of every user-facing error in the project: the ``vbn``
command line turns any ``VbnError`` into a one-line message and a non-zero exit.
Each package derives its own single exception class from it.
"""
from __future__ import annotations

__all__ = ['LandmarkDbError', 'VbnError']


class VbnError(Exception):
    """A problem with the user's input or environment, reported in one line."""


class LandmarkDbError(VbnError):
    """Invalid world, decomposition, scene or database input."""
