"""The interruptible process pool: results in order, an error terminates the workers."""
from __future__ import annotations

import math

import pytest

from vbn_common.errors import VbnCommonError
from vbn_common.workers import map_in_processes


def test_results_come_in_order_with_progress():
    ticks = []
    out = map_in_processes(math.sqrt, [float(i * i) for i in range(20)], 2, chunksize=3,
                           progress=ticks.append)
    assert out == [float(i) for i in range(20)]
    assert sum(ticks) == 20 and ticks == [3] * 6 + [2]       # one call per chunk


def test_an_error_in_a_worker_reaches_the_caller():
    with pytest.raises(ValueError, match='math domain error'):
        map_in_processes(math.sqrt, [4.0, -1.0, 9.0], 2)


def test_an_error_in_the_progress_callback_stops_the_map():
    def stop(_count):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        map_in_processes(math.sqrt, [1.0] * 50, 2, progress=stop)


def test_a_worker_that_dies_is_an_error_not_a_hang():
    # os._exit in a worker (as the OOM killer's SIGKILL): multiprocessing.Pool would
    # replace the worker, lose the task and wait for ever.
    import os
    with pytest.raises(VbnCommonError, match='a worker process died'):
        map_in_processes(os._exit, [3, 3], 2)


def test_the_workers_are_gone_after_an_error():
    import multiprocessing
    with pytest.raises(ValueError):
        map_in_processes(math.sqrt, [-1.0] * 8, 2)
    assert multiprocessing.active_children() == []


def test_the_workers_run_in_a_session_of_their_own():
    # The terminal's Ctrl-C goes to the foreground process group: not to the workers.
    import os
    sessions = map_in_processes(os.getsid, [0, 0], 2)
    assert os.getsid(0) not in sessions


class _StopRequestError(Exception):
    pass


def test_check_stop_ends_a_map_whose_chunk_never_finishes():
    # A chunk of 60 s of sleep: progress would come too late, the check comes each tick.
    import multiprocessing
    import time
    calls = []

    def check():
        calls.append(time.monotonic())
        if len(calls) >= 3:
            raise _StopRequestError

    start = time.monotonic()
    with pytest.raises(_StopRequestError):
        map_in_processes(time.sleep, [60.0, 60.0], 2, check_stop=check)
    assert time.monotonic() - start < 30
    assert len(calls) == 3
    assert multiprocessing.active_children() == []


def test_a_script_without_a_main_guard_runs_once(tmp_path):
    # Spawned workers would run the caller's __main__ script again (and each spawn
    # its own workers in turn); they must not import it at all.
    import subprocess
    import sys

    script = tmp_path / 'unguarded.py'
    script.write_text('import math\nfrom vbn_common.workers import map_in_processes\n'
                      "print('top level ran', flush=True)\n"
                      'print(map_in_processes(math.sqrt, [4.0, 9.0, 16.0], 2))\n')
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ['top level ran', '[2.0, 3.0, 4.0]']
