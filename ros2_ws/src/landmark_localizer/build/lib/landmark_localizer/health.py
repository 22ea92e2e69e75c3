"""Which regions' landmarks the world no longer shows: per-region landmark failures.

A region's landmark is k features visible from every pose of the region (thesis
Sections 3.1 and 5.1); the localizer's switching and pose rest on it. When the world
changes after the exploration (a poster taken down, a cupboard in front of a wall), a
landmark feature is no longer where the database says, and the region serves worse
than it was built to: it is *stale*, and its part of the floor wants re-exploring
(``vbn db-update``).

Evidence, per landmark feature of the region being tracked, from frames whose pose lies
in the region (beyond it the landmark need not be visible):

- *found*: the feature is an inlier of the frame's pose, or a probe found it;
- *missed*: a probe did not find it. Each frame the localizer probes
  ``health_probes`` landmark features it does not track, in turn: it searches each in
  a window where the pose projects it
  (:meth:`~landmark_localizer.tracking.Tracker.search`).
 One
miss means little (a person walking past hides features for a few frames), so a feature
*fails* only after at least ``min_misses`` misses that are at least ``failing_share`` of
its evidence; a region is stale when at least ``stale_share`` of its landmark features
fail (at least one).

The defaults were chosen on runs through changed worlds against databases updated
from a re-exploration (``vbn db-update``'s rebuilt regions as the truth: a region whose
landmark lost a quarter of its features there): of 68 such regions the runs tracked, 33
were reported stale and 1 region reported was not; in runs through the unchanged
worlds (room, L-shaped hall, with and without people) 5 of 116 regions tracked were
reported. Some landmark features are never found by a search even where nothing
changed (their triangulated point is off, or SIFT misses them at that scale), which is
why one failing feature does not make a region stale.
"""
from __future__ import annotations

from collections import defaultdict
import math

import numpy as np

__all__ = ['RegionHealth']


class RegionHealth:
    """Counts found and missed landmark features per region over a run.

    Args:
        min_misses: A feature fails only after this many misses.
        failing_share: ... and when misses are at least this share of its evidence.
        stale_share: A region is stale when this share of its landmark fails.

    Example:
        >>> health = RegionHealth()
        >>> for _ in range(3):
        ...     health.observe(4, np.array([1, 2, 3, 5]), found=np.array([1, 3]),
        ...                    missed=np.array([2, 5]))
        >>> health.failing(4).tolist(), health.stale_regions()
        ([2, 5], [4])
    """

    def __init__(self, min_misses: int = 2, failing_share: float = 0.75,
                 stale_share: float = 0.375) -> None:
        if min_misses < 1 or not 0 < failing_share <= 1 or not 0 < stale_share <= 1:
            raise ValueError(f'invalid region health settings: min_misses={min_misses}, '
                             f'failing_share={failing_share}, stale_share={stale_share}')
        self.min_misses = min_misses
        self.failing_share = failing_share
        self.stale_share = stale_share
        self._landmark: dict[int, np.ndarray] = {}
        self._found: dict[int, defaultdict[int, int]] = {}
        self._missed: dict[int, defaultdict[int, int]] = {}

    def observe(self, region: int, landmark: np.ndarray, found: np.ndarray = (),
                missed: np.ndarray = ()) -> None:
        """Count one frame's evidence on ``region``'s landmark.

        Args:
            region: The region's index.
            landmark: Its landmark classes (other classes in ``found``/``missed`` are
                ignored).
            found: Classes found this frame (pose inliers).
            missed: Classes searched where the pose put them and not found.
        """
        landmark = np.asarray(landmark, np.int64)
        if region not in self._landmark:
            self._landmark[region] = landmark
            self._found[region] = defaultdict(int)
            self._missed[region] = defaultdict(int)
        for counts, ids in ((self._found[region], found), (self._missed[region], missed)):
            for c in np.intersect1d(np.asarray(ids, np.int64), landmark):
                counts[int(c)] += 1

    def failing(self, region: int) -> np.ndarray:
        """Return ``region``'s landmark classes that fail (sorted)."""
        if region not in self._landmark:
            return np.zeros(0, np.int64)
        found, missed = self._found[region], self._missed[region]
        bad = [c for c, m in missed.items()
               if m >= self.min_misses and m >= self.failing_share * (m + found.get(c, 0))]
        return np.array(sorted(bad), np.int64)

    def stale_regions(self) -> list[int]:
        """Return the regions whose landmark fails (sorted)."""
        return [r for r in sorted(self._landmark)
                if self.failing(r).size >= max(1, math.ceil(
                    self.stale_share * self._landmark[r].size - 1e-9))]

    def summary(self) -> dict[int, dict[str, int]]:
        """Per observed region: landmark size, failing features, found and missed counts."""
        return {r: {'landmark': int(self._landmark[r].size),
                    'failing': int(self.failing(r).size),
                    'found': int(sum(self._found[r].values())),
                    'missed': int(sum(self._missed[r].values()))}
                for r in sorted(self._landmark)}
