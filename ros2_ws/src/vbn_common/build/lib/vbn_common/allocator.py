"""Keep freed heap memory in a worker process instead of returning it to the kernel.

OpenCV's SIFT allocates and frees its scale-space pyramid (megabytes) for every image.
glibc serves such blocks by ``mmap`` and unmaps them on ``free``, so every image
faults its pages in again: on the room bag's 256 x 1024 panoramas the kernel time
(0.47 s per 12 images) was as large as SIFT's own (0.56 s). Raising glibc's mmap and
trim thresholds (``mallopt``) keeps the blocks in the heap for the next image: kernel
time 0.04 s, the same peak memory. Called only in pool workers, whose life is one
extraction or matching run; elsewhere (no glibc) it does nothing.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import logging

__all__ = ['reuse_freed_memory']

logger = logging.getLogger(__name__)

# mallopt parameters (glibc malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3


def reuse_freed_memory(mmap_threshold: int = 256 << 20,
                       trim_threshold: int = 1 << 30) -> bool:
    """Serve blocks below ``mmap_threshold`` bytes from the heap and keep freed memory.

    Args:
        mmap_threshold: Blocks at least this large still get their own ``mmap``.
        trim_threshold: Free heap top kept before it is returned to the kernel.

    Returns:
        True when glibc accepted both settings, False where there is no glibc.
    """
    name = ctypes.util.find_library('c')
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    ok = bool(mallopt(_M_MMAP_THRESHOLD, int(mmap_threshold))) and \
        bool(mallopt(_M_TRIM_THRESHOLD, int(trim_threshold)))
    logger.debug('mallopt thresholds set: %s', ok)
    return ok
