"""Giving the C heap's free pages back to the system while the node runs.

Not in the thesis. A relocalization (a SIFT pass over the whole frame and the map
search) allocates tens of megabytes of temporaries in OpenCV and numpy and frees them
within the frame. glibc serves blocks of that size from its heap once it has seen one
freed (its mmap threshold grows with them), and a heap can only shrink from its top:
one small block allocated above the temporaries pins their pages, so the resident
memory of a node that relocalizes now and then steps up by whatever happened to be
pinned (a CI run of the 10,000-frame memory test saw 311 -> 346 MiB at its second
kidnapping). ``malloc_trim`` hands every whole free page back, wherever it lies;
:class:`HeapTrimmer` calls it from the frame worker at most once per period, between
frames, and once when no frame came for a period. A trim takes about 0.1 ms, and the
frame after it faults in again the pages it reuses: trimming every 10th frame of
``bags/room_run`` added 0.07 ms to the mean tracked frame (8.44 -> 8.51 ms), so the
period is 2 s, every 20th frame at 10 Hz. Elsewhere than glibc it does nothing. The
builder's SIFT workers do the opposite (:mod:`vbn_common.allocator`): their life is one
extraction, so they keep what they free.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import time
from typing import Any

__all__ = ['TRIM_PERIOD_S', 'HeapTrimmer', 'trim_heap']

#: The least time between two trims.
TRIM_PERIOD_S = 2.0


def _load_trim() -> Any:
    name = ctypes.util.find_library('c')
    try:
        trim = ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):   # not glibc: nothing to call
        return None
    if trim is not None:
        trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim


_TRIM = _load_trim()


def trim_heap() -> bool:
    """Return free heap pages to the system; whether any were returned (False off glibc)."""
    return bool(_TRIM(0)) if _TRIM is not None else False


class HeapTrimmer:
    """Trims the heap between frames at most once a period, and once when frames stop.

    Args:
        period: The least time between trims in seconds.
        clock: Monotonic seconds (tests pass their own).
    """

    def __init__(self, period: float = TRIM_PERIOD_S, clock: Any = time.monotonic) -> None:
        self.period, self._clock = period, clock
        self._last = clock()
        self._pending = False   # frames since the last trim
        self.trims = 0

    def after_frame(self) -> None:
        """Trim if the period has passed since the last trim (or since construction)."""
        self._pending = True
        if self._clock() - self._last >= self.period:
            self._trim()

    def when_idle(self) -> None:
        """Trim if a frame came since the last trim (called when none came for a period).

        A paused bag or a camera that stopped then leaves nothing of the last frames
        resident.
        """
        if self._pending:
            self._trim()

    def _trim(self) -> None:
        self._last, self._pending = self._clock(), False
        trim_heap()
        self.trims += 1
