"""How many threads OpenBLAS runs, set from inside the process.

The builder's matching and the localizer's per-frame solves multiply small matrices
(tens to a few hundred rows): waking OpenBLAS's threads for each product costs more
than it saves, and on a shared 2-core machine it costs a lot (the room bag's matching
took 9.9 s with the default threads and 2.7 s with one; a two-view solve 40-500 ms
instead of 3 ms). ``OPENBLAS_NUM_THREADS=1`` in the environment only works if set
before numpy loads, which a library cannot ensure; these functions change the count
of the OpenBLAS libraries already loaded, the way threadpoolctl finds them (the
shared objects in ``/proc/self/maps`` and their known symbol names).
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
import ctypes
import functools
from pathlib import Path
import re

__all__ = ['set_blas_threads', 'single_threaded_blas']

_OPENBLAS_SYMBOLS = [
    ('scipy_openblas_get_num_threads64_', 'scipy_openblas_set_num_threads64_'),
    ('scipy_openblas_get_num_threads', 'scipy_openblas_set_num_threads'),
    ('openblas_get_num_threads64_', 'openblas_set_num_threads64_'),
    ('openblas_get_num_threads', 'openblas_set_num_threads'),
]


@functools.lru_cache(maxsize=1)
def _openblas_thread_controls() -> tuple[tuple[Callable[[], int], Callable[[int], None]], ...]:
    """Get/set thread-count functions of the OpenBLAS libraries loaded in this process.

    Found the way threadpoolctl finds them (the loaded shared objects, then the
    known symbol names); empty where there is no ``/proc/self/maps`` or no OpenBLAS.
    """
    try:
        maps = Path('/proc/self/maps').read_text()
    except OSError:
        return ()
    controls = []
    for path in sorted(set(re.findall(r'(/\S*openblas\S*\.so[\w.]*)', maps))):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for get_name, set_name in _OPENBLAS_SYMBOLS:
            if hasattr(lib, get_name) and hasattr(lib, set_name):
                getter, setter = getattr(lib, get_name), getattr(lib, set_name)
                getter.restype = ctypes.c_int
                setter.argtypes = [ctypes.c_int]
                controls.append((getter, setter))
                break
    return tuple(controls)


@contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Run OpenBLAS on one thread inside the block, restoring the count after.

    The products of Algorithm 6.3 are small (a few hundred rows a side): waking
    OpenBLAS's threads for each costs more than it saves. On the room bag, on two
    shared cores, matching took 9.9 s with the default threads and 2.7 s with one.
    """
    controls = _openblas_thread_controls()
    previous = [get() for get, _ in controls]
    for _, set_threads in controls:
        set_threads(1)
    try:
        yield
    finally:
        for (_, set_threads), count in zip(controls, previous):
            set_threads(count)


def set_blas_threads(count: int) -> None:
    """Set the thread count of every loaded OpenBLAS (no-op where there is none)."""
    for _, set_threads in _openblas_thread_controls():
        set_threads(count)
