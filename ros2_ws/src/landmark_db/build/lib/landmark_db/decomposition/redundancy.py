"""Elimination of redundant regions (Section 5.4).

All algorithms except B.2 may end with a decomposition that is not minimal. Regions
are discarded one at a time, always the region with the largest
minimum-overlapping-count omega = min over v in R of |{R' in D : v in R'}|, while that
largest omega is at least 2 (omega >= 2 means every pose of R is also covered by
another region, so dropping R loses nothing). Ties are broken by a seeded random
priority. Works on 0-MORDP regions, where coverage is membership.
"""
from __future__ import annotations

import numpy as np

from landmark_db.decomposition.problem import ZeroRegion

__all__ = ['eliminate_redundant']


def eliminate_redundant(regions: list[ZeroRegion], n_poses: int,
                        rng: np.random.Generator) -> list[ZeroRegion]:
    """Drop redundant regions, largest omega first, until the cover is minimal.

    Args:
        regions: the regions.
        n_poses: number of poses.
        rng: seeded generator for tie-breaking.

    Returns:
        The kept regions, in their original order.
    """
    d = len(regions)
    if d <= 1:
        return list(regions)
    sizes = np.array([r.poses.size for r in regions], dtype=np.int64)
    flat = np.concatenate([r.poses for r in regions])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    count = np.bincount(flat, minlength=n_poses)
    alive = sizes > 0
    priority = rng.permutation(d)
    while True:
        omega = np.minimum.reduceat(count[flat], starts)
        omega[~alive] = 0
        best = int(omega.max())
        if best < 2:
            break
        candidates = np.flatnonzero(omega == best)
        drop = int(candidates[np.argmax(priority[candidates])])
        alive[drop] = False
        count[regions[drop].poses] -= 1
    return [region for region, keep in zip(regions, alive) if keep]
