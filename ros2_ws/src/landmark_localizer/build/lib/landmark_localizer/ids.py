"""Set operations on class ids within a frame's step, by a table instead of a sort.

Not in the thesis. A tracked frame asks a dozen times which of its tracks belong to a
region, to the model views or to the inliers; ``np.isin`` sorts both arrays each time
(about 25 microseconds for forty ids, a millisecond of a frame in all). The ids are
class indices below the database's class count, so a boolean table over them answers
in about one microsecond. The table is scratch: each call sets and clears the entries
it uses, and one table belongs to one localizer (a localizer steps one frame at a time).
"""
from __future__ import annotations

import numpy as np

__all__ = ['IdTable']


class IdTable:
    """Membership over ids in ``[0, size)``.

    Example:
        >>> table = IdTable(10)
        >>> table.member(np.array([3, 7, 1]), np.array([1, 2, 3]))
        array([ True, False,  True])
        >>> table.difference(np.array([9, 3, 9, 4]), np.array([3]))
        array([4, 9])
    """

    def __init__(self, size: int) -> None:
        self._table = np.zeros(max(int(size), 0), bool)

    def member(self, values: np.ndarray, members: np.ndarray) -> np.ndarray:
        """Return ``np.isin(values, members)`` (both arrays of ids in ``[0, size)``)."""
        values = np.asarray(values, np.int64)
        members = np.asarray(members, np.int64)
        table = self._table
        table[members] = True
        try:
            return table[values]
        finally:
            table[members] = False   # clear even when an id was out of range

    def difference(self, values: np.ndarray, members: np.ndarray) -> np.ndarray:
        """Return ``np.setdiff1d(values, members)``: the sorted distinct ids not in members."""
        unique = np.unique(np.asarray(values, np.int64))
        return unique[~self.member(unique, members)]
