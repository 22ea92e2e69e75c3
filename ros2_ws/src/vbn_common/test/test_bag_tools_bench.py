"""Benchmark: ``vbn play`` timing fidelity at 30 Hz (not run by default).

Run with ``pytest -m bench ros2_ws/src/vbn_common/test/test_bag_tools_bench.py -s``. It writes a
20 s bag of 320 x 240 mono8 images at 30 Hz, plays it with ``vbn play --stats``
without a subscriber, into ``vbn record`` over DDS, and into ``vbn record`` with
``--realtime`` (SCHED_FIFO, where permitted), and prints the achieved
inter-message jitter (|achieved - recorded interval|) and lateness, p50/p95/max in
milliseconds, with the machine's load average (the target is a jitter p95 under 2 ms
on an otherwise idle machine). It asserts only that every message was published and,
with the recorder, received.
"""
from __future__ import annotations

import os
from pathlib import Path
import re

import numpy as np
import pytest

from vbn_common.bags import TYPESTORE, BagWriter, default_qos, open_bag

pytestmark = [pytest.mark.bench, pytest.mark.integration, pytest.mark.timeout(600)]

T = TYPESTORE.types
RATE_HZ = 30.0
SECONDS = 20


def write_30hz_bag(path: Path) -> int:
    rng = np.random.default_rng(0)
    n = int(RATE_HZ * SECONDS)
    t0 = 1_763_769_600 * 10**9
    with BagWriter(path) as bag:
        conn = bag.add_topic('/camera/image_raw', 'sensor_msgs/msg/Image', [default_qos()])
        for i in range(n):
            stamp = t0 + round(i * 1e9 / RATE_HZ)
            head = T['std_msgs/msg/Header'](
                stamp=T['builtin_interfaces/msg/Time'](sec=stamp // 10**9,
                                                       nanosec=stamp % 10**9),
                frame_id='camera')
            bag.write(conn, stamp, T['sensor_msgs/msg/Image'](
                header=head, height=240, width=320, encoding='mono8', is_bigendian=0,
                step=320, data=rng.integers(0, 256, 320 * 240, dtype=np.uint8)))
    return n


def timing(output: str) -> dict[str, float]:
    line = re.search(r'^timing: (.*)$', output, re.MULTILINE).group(1)
    return {k: float(v) for k, v in (item.split('=') for item in line.split(', '))}


def report(label: str, stats: dict[str, float]) -> None:
    load = os.getloadavg()
    print(f'\n{label}: jitter p50/p95/max = {stats["jitter_p50_ms"]:.3f}/'
          f'{stats["jitter_p95_ms"]:.3f}/{stats["jitter_max_ms"]:.3f} ms; lateness '
          f'p50/p95/max = {stats["lateness_p50_ms"]:.3f}/{stats["lateness_p95_ms"]:.3f}/'
          f'{stats["lateness_max_ms"]:.3f} ms; load average {load[0]:.2f} on '
          f'{os.cpu_count()} CPUs')


def test_play_jitter_at_30_hz(tmp_path: Path, start_process) -> None:
    n = write_30hz_bag(tmp_path / 'b30')
    play = start_process(['vbn', 'play', str(tmp_path / 'b30'), '--stats'], name='play')
    assert play.wait(timeout=SECONDS + 120) == 0, play.output
    assert f'published {n} messages' in play.output
    report('no subscriber', timing(play.output))

    for label, extra in (('into vbn record over DDS', []),
                         ('into vbn record over DDS, --realtime', ['--realtime'])):
        out = tmp_path / f'rec{len(extra)}'
        record = start_process(['vbn', 'record', '--topics', '/camera/image_raw', '--out',
                                str(out)], name='record')
        record.wait_for_output('recording into', timeout=120)
        play = start_process(['vbn', 'play', str(tmp_path / 'b30'), '--stats',
                              '--wait-for-subscribers', *extra], name='play')
        assert play.wait(timeout=SECONDS + 240) == 0, play.output
        assert record.stop() == 0
        with open_bag(out) as reader:
            assert reader.message_count == n
        if 'cannot switch to real-time priority' in play.output:
            label += ' (not permitted: normal priority)'
        report(label, timing(play.output))
