"""A process pool that an interrupt stops at once: SIFT, matching, decomposition on every core.

``concurrent.futures.ProcessPoolExecutor`` handles Ctrl-C badly: the terminal sends
SIGINT to the whole process group, each worker dies of ``KeyboardInterrupt`` wherever it
is (possibly holding the call queue's lock), and the pool's shutdown then waits on a
worker that never answers. ``vbn build`` hung that way for good in 3 of 11 tries, and a
second Ctrl-C left workers and the resource tracker behind.

Here only the parent decides: the workers start in a session of their own, so that the
terminal's Ctrl-C (sent to the foreground process group) never reaches them, not even
while one still imports (it printed a ``KeyboardInterrupt`` traceback then), and they
ignore SIGINT besides; the pool is a ``multiprocessing`` pool of the 'spawn' start
method (never forked: the builder node calls this with rclpy's threads alive); anything
that ends the map early, an interrupt above all, terminates the workers (SIGTERM)
before it propagates, and a worker that dies is an error rather than a hang. The parent
never ignores a signal itself: ignoring SIGINT while it started the workers lost a
Ctrl-C to an OpenBLAS thread. Pure Python, no rclpy.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
import multiprocessing
from multiprocessing import context as mp_context
from multiprocessing import popen_spawn_posix
from multiprocessing import spawn as mp_spawn
from multiprocessing import util as mp_util
import os
import signal
import sys
import threading
from typing import Any

from vbn_common.errors import VbnCommonError

__all__ = ['available_cores', 'map_in_processes']

#: How often the map checks that its workers are alive, seconds.
_WATCH_S = 0.5


_SPAWN_LOCK = threading.Lock()


def _spawn_in_own_session(path: str, args: list[str], passfds: Iterable[int]) -> int:
    """``multiprocessing.util.spawnv_passfds`` with the child in a new session.

    The same ``fork_exec`` call as CPython 3.11's, with ``call_setsid`` set.
    """
    import _posixsubprocess
    import subprocess

    passfds = tuple(sorted(map(int, passfds)))
    errpipe_read, errpipe_write = os.pipe()
    try:
        return _posixsubprocess.fork_exec(
            args, [path], True, passfds, None, None, -1, -1, -1, -1, -1, -1,
            errpipe_read, errpipe_write, False, True, -1, None, None, None, -1, None,
            subprocess._USE_VFORK)
    finally:
        os.close(errpipe_read)
        os.close(errpipe_write)


def _preparation_without_main(name: str) -> dict[str, Any]:
    """``spawn.get_preparation_data`` without the caller's main module.

    A spawned child normally runs the parent's ``__main__`` script again (as
    ``__mp_main__``): a script that calls a parallel step at its top level, without an
    ``if __name__ == '__main__'`` guard, would then run itself in every worker. The
    workers run module-level functions of the packages only, so they need no main.
    """
    data = _GET_PREPARATION_DATA(name)
    data.pop('init_main_from_path', None)
    data.pop('init_main_from_name', None)
    return data


_GET_PREPARATION_DATA = mp_spawn.get_preparation_data


class _SessionPopen(popen_spawn_posix.Popen):
    """The 'spawn' start method, the child in a session of its own (CPython 3.11)."""

    def _launch(self, process_obj: Any) -> None:
        with _SPAWN_LOCK:
            original = mp_util.spawnv_passfds
            if sys.version_info[:2] == (3, 11):     # fork_exec's arguments are 3.11's
                mp_util.spawnv_passfds = _spawn_in_own_session
            mp_spawn.get_preparation_data = _preparation_without_main
            try:
                super()._launch(process_obj)
            finally:
                mp_util.spawnv_passfds = original
                mp_spawn.get_preparation_data = _GET_PREPARATION_DATA


class _SessionProcess(mp_context.SpawnProcess):
    @staticmethod
    def _Popen(process_obj: Any) -> _SessionPopen:  # noqa: N802 - multiprocessing's name
        return _SessionPopen(process_obj)


class _SessionSpawnContext(mp_context.SpawnContext):
    Process = _SessionProcess


_SESSION_SPAWN = _SessionSpawnContext()


def _start_worker(initializer: Callable[..., None] | None, initargs: tuple) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if initializer is not None:
        initializer(*initargs)


def _run_chunk(job: tuple[Callable[[Any], Any], list[Any]]) -> list[Any]:
    func, chunk = job
    return [func(item) for item in chunk]


def available_cores() -> int:
    """Return the cores this process may run on (its affinity mask, else the machine's)."""
    if hasattr(os, 'sched_getaffinity'):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def map_in_processes(func: Callable[[Any], Any], items: Iterable[Any], workers: int, *,
                     initializer: Callable[..., None] | None = None, initargs: tuple = (),
                     chunksize: int = 1,
                     progress: Callable[[int], None] | None = None,
                     check_stop: Callable[[], None] | None = None) -> list[Any]:
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
        check_stop: Called in the calling process every half second while the map
            waits, whether or not a chunk finished; what it raises ends the map (the
            workers are terminated first). A slow chunk (workers still importing on a
            loaded machine) then cannot hold a shutdown back.

    Returns:
        The results, in the order of ``items``.

    Raises:
        Whatever ``func`` raised in a worker, ``KeyboardInterrupt``, or
        :class:`~vbn_common.errors.VbnCommonError` when a worker died: in every case
        the workers are terminated and joined first.
    """
    results: list[Any] = []
    pool = None
    try:
        with _signals_deferred():
            pool = _SESSION_SPAWN.Pool(workers, initializer=_start_worker,
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
            if check_stop is not None:
                check_stop()
            try:
                result = results_of.next(timeout=_WATCH_S)
            except StopIteration:
                break
            except multiprocessing.TimeoutError as error:
                dead = [w for w in workers_started if w.exitcode is not None]
                if dead:
                    raise VbnCommonError(
                        f'a worker process died (exit code {dead[0].exitcode}) while '
                        f'computing {getattr(func, "__name__", func)}: out of memory?') \
                        from error
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
def _signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back while the workers start; act on them afterwards.

    An interrupt raised while the parent hands a new worker its start-up data leaves
    the worker reading a closed pipe (it printed an ``EOFError``). Only the main thread
    can set handlers; elsewhere (the builder node) the node's own handler only flags
    the shutdown, which the build acts on between images.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    signals = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.signal(s, lambda signum, _frame: held.append(signum))
                for s in signals}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if held:
            handler = previous[held[0]]
            if callable(handler):
                handler(held[0], None)          # the command's own: raises
            elif handler == signal.SIG_DFL:
                os.kill(os.getpid(), held[0])


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
