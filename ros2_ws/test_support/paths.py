"""Where things are, for every package's tests: the repository, its sample bags, the sources."""
from __future__ import annotations

from pathlib import Path

__all__ = ['BAGS', 'REPO', 'SRC', 'SUPPORT']

#: This folder: the helpers the packages' tests share, and their data.
SUPPORT = Path(__file__).resolve().parent
#: The repository's root.
REPO = SUPPORT.parents[1]
#: The sample bags.
BAGS = REPO / 'bags'
#: The packages' sources.
SRC = REPO / 'ros2_ws' / 'src'
