"""The frame worker hands free heap pages back between frames (landmark_localizer.heap)."""
from __future__ import annotations

import os
import platform
import subprocess
import sys
import threading

import pytest

from landmark_localizer.frame_worker import FrameWorker
from landmark_localizer.heap import HeapTrimmer

GLIBC = platform.libc_ver()[0] == 'glibc' and os.path.exists('/proc/self/status')

# 45 MiB of 3 MiB blocks from the heap (a freed 4 MiB block raised glibc's mmap threshold),
# pinned by a 512 KiB block above them: freeing them leaves the resident memory as it was.
PINNED = """
import ctypes
from landmark_localizer.heap import trim_heap
libc = ctypes.CDLL('libc.so.6')
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
def rss():
    return next(int(l.split()[1]) for l in open('/proc/self/status')
                if l.startswith('VmRSS')) // 1024
MB = 1 << 20
libc.free(libc.malloc(4 * MB))
blocks = [libc.malloc(3 * MB) for _ in range(15)]
for p in blocks:
    ctypes.memset(p, 1, 3 * MB)
pin = libc.malloc(MB // 2)
ctypes.memset(pin, 1, MB // 2)
before = rss()
for p in blocks:
    libc.free(p)
freed = rss()
returned = trim_heap()
print(before, freed, rss(), int(returned))
"""


@pytest.mark.skipif(not GLIBC, reason="malloc_trim is glibc's")
def test_a_trim_returns_the_pages_a_small_block_pinned() -> None:
    out = subprocess.run([sys.executable, '-c', PINNED], capture_output=True, text=True,
                         check=True, env=os.environ.copy()).stdout.split()
    before, freed, trimmed, returned = (int(v) for v in out)
    assert freed > before - 5          # free, but resident: pinned by the block above
    assert trimmed < freed - 40        # handed back by the trim
    assert returned == 1


def test_the_trimmer_trims_at_most_once_a_period() -> None:
    now = [100.0]
    trimmer = HeapTrimmer(period=1.0, clock=lambda: now[0])
    for t in (100.2, 100.9, 101.0, 101.5, 101.99, 102.0, 105.0):
        now[0] = t
        trimmer.after_frame()
    assert trimmer.trims == 3          # at 101.0, 102.0 and 105.0


def test_the_trimmer_trims_once_when_frames_stop() -> None:
    now = [0.0]
    trimmer = HeapTrimmer(period=2.0, clock=lambda: now[0])
    trimmer.when_idle()
    assert trimmer.trims == 0          # nothing came since it started
    now[0] = 0.5
    trimmer.after_frame()              # too soon for a trim
    now[0] = 2.5
    trimmer.when_idle()
    trimmer.when_idle()
    assert trimmer.trims == 1          # one trim for the frame, not one per idle period
    now[0] = 3.0
    trimmer.after_frame()              # 0.5 s after the idle trim: none
    assert trimmer.trims == 1


class _Counting:
    """Counts the worker's calls; ``wait_for(n)`` waits until there were ``n``."""

    def __init__(self, period: float = 60.0) -> None:
        self.period, self.frames, self.idle = period, 0, 0
        self._changed = threading.Condition()

    def after_frame(self) -> None:
        with self._changed:
            self.frames += 1
            self._changed.notify_all()

    def when_idle(self) -> None:
        with self._changed:
            self.idle += 1
            self._changed.notify_all()

    def wait_for(self, frames: int, idle: int = 0) -> bool:
        with self._changed:
            return self._changed.wait_for(
                lambda: self.frames >= frames and self.idle >= idle, timeout=30)


def test_the_frame_worker_trims_after_each_frame_even_a_failed_one() -> None:
    trimmer, errors, processed = _Counting(), [], []

    def process(item: str) -> None:
        if item == 'bad':
            raise ValueError(item)
        processed.append(item)

    worker = FrameWorker(process, errors.append, trimmer=trimmer)
    worker.put('bad')
    assert trimmer.wait_for(1)
    worker.put('good')
    assert trimmer.wait_for(2)
    worker.close()
    assert trimmer.frames == 2 and processed == ['good'] and [str(e) for e in errors] == ['bad']
    assert trimmer.idle == 0 and not worker.alive


def test_the_frame_worker_calls_the_idle_trim_when_no_frame_comes() -> None:
    trimmer = _Counting(period=0.01)
    worker = FrameWorker(lambda item: None, lambda error: None, trimmer=trimmer)
    worker.put('frame')
    assert trimmer.wait_for(1, idle=2)   # a frame, then a period without one, twice
    worker.close()
    assert not worker.alive
