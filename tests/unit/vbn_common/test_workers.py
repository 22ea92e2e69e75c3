"""The interruptible process pool: results in order, an error terminates the workers."""
from __future__ import annotations

import math

import pytest

from vbn_common.workers import map_in_processes


def test_results_come_in_order_with_progress():
    ticks = []
    out = map_in_processes(math.sqrt, [float(i * i) for i in range(20)], 2, chunksize=3,
                           progress=ticks.append)
    assert out == [float(i) for i in range(20)]
    assert ticks == [1] * 20


def test_an_error_in_a_worker_reaches_the_caller():
    with pytest.raises(ValueError, match='math domain error'):
        map_in_processes(math.sqrt, [4.0, -1.0, 9.0], 2)


def test_an_error_in_the_progress_callback_stops_the_map():
    def stop(_count):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        map_in_processes(math.sqrt, [1.0] * 50, 2, progress=stop)
