"""Errors of the vbn_bench package."""
from __future__ import annotations

from vbn_common.errors import VbnError

__all__ = ['BenchError']


class BenchError(VbnError):
    """A benchmark that cannot run or one of its steps that failed, reported in one line."""
