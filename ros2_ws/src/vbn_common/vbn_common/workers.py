"""A process pool that an interrupt stops at once: SIFT and pair matching on every core.

``concurrent.futures.ProcessPoolExecutor`` handles Ctrl-C badly: the terminal sends
SIGINT to the whole process group, each worker dies of ``KeyboardInterrupt`` wherever it
is (possibly holding the call queue's lock), and the pool's shutdown then waits on a
worker that never answers. ``vbn build`` hung that way for good in 3 of 11 tries, and a
second Ctrl-C left workers and the resource tracker behind.

Here the workers ignore SIGINT (only the parent decides), the pool is a
``multiprocessing`` pool of the 'spawn' context (never forked: the builder node calls
this with rclpy's threads alive), and anything that ends the map early, an interrupt
above all, terminates the workers before it propagates. Pure Python, no rclpy.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
import ctypes
import multiprocessing
import signal
import threading
from typing import Any

from vbn_common.errors import VbnCommonError

__all__ = ['map_in_processes']

#: Room for glibc's ``struct sigaction`` (152 bytes on x86-64 and aarch64), saved whole.
_SIGACTION_BYTES = 256
#: How often the map checks that its workers are alive, seconds.
_WATCH_S = 0.5


def _start_worker(initializer: Callable[..., None] | None, initargs: tuple) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if initializer is not None:
        initializer(*initargs)


def _run_chunk(job: tuple[Callable[[Any], Any], list[Any]]) -> list[Any]:
    func, chunk = job
    return [func(item) for item in chunk]


def map_in_processes(func: Callable[[Any], Any], items: Iterable[Any], workers: int, *,
                     initializer: Callable[..., None] | None = None, initargs: tuple = (),
                     chunksize: int = 1,
                     progress: Callable[[int], None] | None = None) -> list[Any]:
    """Return ``[func(item) for item in items]`` computed in ``workers`` processes, in order.

    Args:
        func: A module-level function (the workers import it by name).
        items: Its arguments, each pickled to a worker.
        workers: Processes (>= 1).
        initializer: Called once in each worker with ``initargs``.
        initargs: Arguments of ``initializer``.
        chunksize: Items sent to a worker at once.
        progress: Called with the number of results just finished (a chunk's), in the
            calling process.

    Returns:
        The results, in the order of ``items``.

    Raises:
        Whatever ``func`` raised in a worker, ``KeyboardInterrupt``, or
        :class:`~vbn_common.errors.VbnCommonError` when a worker died: in every case
        the workers are terminated and joined first.
    """
    context = multiprocessing.get_context('spawn')
    results: list[Any] = []
    pool = None
    try:
        # The workers are started with SIGINT ignored (inherited through exec, so a
        # Ctrl-C while one still imports does not print its traceback).
        with _sigint_ignored():
            pool = context.Pool(workers, initializer=_start_worker,
                                initargs=(initializer, initargs))
        # multiprocessing.Pool replaces a worker that dies (the OOM killer, a crash in
        # OpenCV) and loses its task: the map would wait for ever. Watch the workers.
        workers_started = list(pool._pool)
        items = list(items)
        size = max(1, int(chunksize))
        # Chunks made here: imap with chunksize > 1 returns a generator without timeout.
        chunks = [(func, items[i:i + size]) for i in range(0, len(items), size)]
        results_of = pool.imap(_run_chunk, chunks)
        while True:
            try:
                result = results_of.next(timeout=_WATCH_S)
            except StopIteration:
                break
            except multiprocessing.TimeoutError:
                dead = [w for w in workers_started if w.exitcode is not None]
                if dead:
                    raise VbnCommonError(
                        f'a worker process died (exit code {dead[0].exitcode}) while '
                        f'computing {getattr(func, "__name__", func)}: out of memory?') \
                        from None
                continue
            results.extend(result)
            if progress is not None:
                progress(len(result))
        pool.close()
    except BaseException:
        if pool is not None:
            with _no_second_interrupt():
                pool.terminate()
                pool.join()
        raise
    pool.join()
    return results


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """Ignore SIGINT in the whole process for a moment (the workers' fork and exec).

    The main thread uses :func:`signal.signal`; another thread (the builder node builds
    in one) cannot, so there the disposition is saved and restored whole with libc's
    ``sigaction`` (rclpy's own handler included). The pool's constructor returns once
    the processes are started, a few milliseconds; a Ctrl-C in them is lost for the
    workers only in the main thread; elsewhere the process ignores it too.
    """
    if threading.current_thread() is threading.main_thread():
        # Blocked as well as ignored: Linux keeps a blocked signal pending even while it
        # is ignored, so a Ctrl-C in the window is raised here once it is unblocked.
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, previous)
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        return
    saved = _save_sigaction()
    try:
        yield
    finally:
        if saved is not None:
            _libc().sigaction(signal.SIGINT, saved, None)


def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(None, use_errno=True)


def _save_sigaction() -> ctypes.Array | None:
    """Set SIGINT to ignored; return the previous ``struct sigaction`` (None if unable)."""
    try:
        libc = _libc()
        saved = ctypes.create_string_buffer(_SIGACTION_BYTES)
        if libc.sigaction(signal.SIGINT, None, saved) != 0:
            return None
        ignore = ctypes.create_string_buffer(saved.raw, _SIGACTION_BYTES)
        ctypes.memmove(ignore, ctypes.byref(ctypes.c_void_p(int(signal.SIG_IGN))),
                       ctypes.sizeof(ctypes.c_void_p))    # sa_handler comes first
        if libc.sigaction(signal.SIGINT, ignore, None) != 0:
            return None
        return saved
    except (OSError, AttributeError):
        return None


@contextmanager
def _no_second_interrupt() -> Iterator[None]:
    """Let a second Ctrl-C or a SIGTERM not cut the workers' termination short.

    Main thread only (where Python can set handlers).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
