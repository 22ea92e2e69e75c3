"""What the localizer node needs besides rclpy: warnings, frame statistics, the mailbox.

Pure Python (no rclpy), each piece tested on its own: :class:`Warnings` logs a kind of
problem once and then at most every ``repeat_s`` with a count; :class:`FrameStats` is
what ``/diagnostics`` reports about the frames; :class:`Mailbox` is the one slot
between the executor thread, which files each image, and the frame worker, which takes
the newest; :func:`limit_malloc_arenas` keeps the node's resident memory flat.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable
import ctypes
import re
import threading
import time
from typing import Any

import numpy as np

__all__ = ['LATENCY_WINDOW', 'WARN_REPEAT_S', 'FrameStats', 'Mailbox', 'Warnings',
           'limit_malloc_arenas', 'reason_kind']

#: Frames in the latency window of /diagnostics.
LATENCY_WINDOW = 200
#: A repeated warning is logged again at most this often, with a count.
WARN_REPEAT_S = 10.0
#: glibc's ``M_ARENA_MAX`` (malloc.h) and the arenas the node allows.
_M_ARENA_MAX, _ARENAS = -8, 2


class Warnings:
    """Log each kind of problem once, then at most every ``repeat_s`` with a count.

    Args:
        log: Where a line goes (the node logger's ``warning``).
        repeat_s: Least time between two lines of the same kind.
        clock: Monotonic seconds (injectable for tests).
    """

    def __init__(self, log: Callable[[str], Any], repeat_s: float = WARN_REPEAT_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.log, self.repeat_s, self.clock = log, repeat_s, clock
        self._last: dict[str, float] = {}
        self._since: dict[str, int] = {}

    def warn(self, kind: str, text: str) -> bool:
        """Log ``text`` unless ``kind`` was logged within ``repeat_s``; say whether logged."""
        now = self.clock()
        last = self._last.get(kind)
        if last is not None and now - last < self.repeat_s:
            self._since[kind] = self._since.get(kind, 0) + 1
            return False
        more = self._since.pop(kind, 0)
        self._last[kind] = now
        self.log(text + (f' ({more} more since the last warning)' if more else ''))
        return True


def reason_kind(text: str) -> str:
    """Return a warning's kind: its text without numbers (one warning per kind)."""
    return re.sub(r'[0-9.]+', '#', text)


class FrameStats:
    """What /diagnostics reports about the frames: counts, drops by reason, latency.

    The executor thread and the frame worker both write it, the diagnostics timer reads
    it: drops and latencies go through a lock (each count has one writer).
    """

    def __init__(self, window: int = LATENCY_WINDOW) -> None:
        self.received = 0
        self.processed = 0
        self.poses = 0
        self.dropped: dict[str, int] = {}
        self.latency: deque[float] = deque(maxlen=window)
        self._lock = threading.Lock()

    def drop(self, reason: str) -> None:
        """Count a dropped frame."""
        with self._lock:
            self.dropped[reason] = self.dropped.get(reason, 0) + 1

    def dropped_counts(self) -> dict[str, int]:
        """Return a copy of the drops by reason."""
        with self._lock:
            return dict(self.dropped)

    def add_latency(self, seconds: float) -> None:
        """Add one processed frame's latency to the window."""
        with self._lock:
            self.latency.append(seconds)

    def latency_ms(self) -> dict[str, float]:
        """p50, p95 and max of the per-frame latency over the window, milliseconds."""
        with self._lock:
            values = np.fromiter(self.latency, float) * 1e3
        if not len(values):
            return {'latency_p50_ms': float('nan'), 'latency_p95_ms': float('nan'),
                    'latency_max_ms': float('nan')}
        p50, p95 = np.percentile(values, [50, 95])
        return {'latency_p50_ms': float(p50), 'latency_p95_ms': float(p95),
                'latency_max_ms': float(values.max())}


class Mailbox:
    """One slot between the executor (``put``) and the frame worker (``take``).

    A ``put`` while the slot is full replaces the waiting item and returns it (the caller
    counts it as dropped): the worker always gets the newest frame and nothing queues.
    """

    def __init__(self) -> None:
        self._ready = threading.Condition()
        self._item: Any = None
        self._full = False
        self._closed = False

    def put(self, item: Any) -> tuple[bool, Any]:
        """Leave ``item``; return ``(replaced, the replaced item or None)``."""
        with self._ready:
            replaced, old = self._full, self._item
            self._item, self._full = item, True
            self._ready.notify()
        return replaced, old

    def take(self, timeout: float | None = None) -> tuple[bool, Any]:
        """Wait for an item; ``(False, None)`` once closed (or after ``timeout``)."""
        with self._ready:
            self._ready.wait_for(lambda: self._full or self._closed, timeout=timeout)
            if not self._full or self._closed:
                return False, None
            item, self._item, self._full = self._item, None, False
            return True, item

    def close(self) -> None:
        """Wake the worker for good: every later ``take`` returns ``(False, None)``."""
        with self._ready:
            self._closed = True
            self._ready.notify_all()

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._closed


def limit_malloc_arenas(arenas: int = _ARENAS) -> bool:
    """Share at most ``arenas`` glibc malloc arenas between all threads; say if it took.

    glibc gives threads their own arenas (up to 8 per core). When frames were processed
    on two executor threads in turn, freed memory was left scattered over several arenas
    and the node's resident memory grew by a quarter over 10,000 frames (239 to 301 MiB);
    with two arenas it stayed flat (1.02x). The frame worker and the executor thread still
    allocate both, so the cap stays (the node's test over 10,000 frames checks it).
    Elsewhere than glibc this does nothing.
    """
    try:
        libc = ctypes.CDLL(None)
        return bool(libc.mallopt(_M_ARENA_MAX, arenas))
    except (OSError, AttributeError):
        return False


def one_thread_per_library() -> None:
    """Run OpenCV and OpenBLAS on the calling thread, without pools of their own.

    A frame's work is small pieces (a warp or a correlation of a few patches, a solve of
    a few hundred rows): waking a pool for each costs more than it saves, and beside the
    executor thread, the DDS threads and a bag player on two cores the pools contend. The
    pinhole demo with scene points measured by their patches went from a node latency
    p50 of 60 ms and 35 dropped frames to 34 ms and 23 with one thread each (the same
    database and run, ``OPENBLAS_NUM_THREADS=1 OPENCV_FOR_THREADS_NUM=1``). ``vbn
    localize --one-core`` and the benchmarks measure the same way.
    """
    import cv2

    from vbn_common.blas import set_blas_threads

    cv2.setNumThreads(1)
    set_blas_threads(1)
