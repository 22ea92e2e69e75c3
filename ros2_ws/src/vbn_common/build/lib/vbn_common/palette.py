"""Region colours shared by the RViz markers and the figures, without matplotlib.

The 52 colours are those of matplotlib's qualitative ``tab20``, ``tab20b`` and ``Set3``
palettes (the first two from Tableau's category colours, the third from ColorBrewer),
written out here so that a robot that only localizes draws its regions in RViz without
installing matplotlib. A test checks them against matplotlib's where it is installed.
"""
from __future__ import annotations

import numpy as np

__all__ = ['PALETTE_HEX', 'region_colours']

#: ``tab20``, ``tab20b`` and ``Set3``, in that order.
PALETTE_HEX = (
    '#1f77b4', '#aec7e8', '#ff7f0e', '#ffbb78', '#2ca02c', '#98df8a', '#d62728', '#ff9896',
    '#9467bd', '#c5b0d5', '#8c564b', '#c49c94', '#e377c2', '#f7b6d2', '#7f7f7f', '#c7c7c7',
    '#bcbd22', '#dbdb8d', '#17becf', '#9edae5',
    '#393b79', '#5254a3', '#6b6ecf', '#9c9ede', '#637939', '#8ca252', '#b5cf6b', '#cedb9c',
    '#8c6d31', '#bd9e39', '#e7ba52', '#e7cb94', '#843c39', '#ad494a', '#d6616b', '#e7969c',
    '#7b4173', '#a55194', '#ce6dbd', '#de9ed6',
    '#8dd3c7', '#ffffb3', '#bebada', '#fb8072', '#80b1d3', '#fdb462', '#b3de69', '#fccde5',
    '#d9d9d9', '#bc80bd', '#ccebc5', '#ffed6f',
)


def _rgba(hex_colours: tuple[str, ...]) -> np.ndarray:
    rgb = np.array([[int(h[i:i + 2], 16) for i in (1, 3, 5)] for h in hex_colours]) / 255
    return np.column_stack([rgb, np.ones(len(rgb))])


def region_colours(count: int, seed: int = 0) -> np.ndarray:
    """Return ``(count, 4)`` RGBA colours in ``[0, 1]``, distinct for neighbouring indices.

    The palette is cycled in a fixed shuffled order (``seed``), so a figure or a marker
    array is reproducible.

    Example:
        >>> region_colours(3).shape
        (3, 4)
    """
    palette = _rgba(PALETTE_HEX)
    order = np.random.default_rng(seed).permutation(len(palette))
    return palette[order[np.arange(count) % len(palette)]]
