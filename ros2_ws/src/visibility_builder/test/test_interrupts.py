"""Interrupting a build stops every worker, says so in one line and loses nothing.

``vbn build`` and the ``builder`` node get SIGINT while SIFT runs on every core, alone or
as Ctrl-C sends it (to the whole process group, twice): each ends within seconds with
one line, exit 130, no process left behind and the previous database byte for byte.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path
import signal
import subprocess
import time

from paths import REPO
import pytest

pytestmark = pytest.mark.integration

ROOT = REPO
BAG = ROOT / 'bags' / 'room_exploration'


def file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _children(pid: int) -> set[int]:
    """Every descendant of ``pid`` (from /proc)."""
    found: set[int] = set()
    stack = [pid]
    while stack:
        parent = stack.pop()
        for task in Path(f'/proc/{parent}/task').glob('*'):
            try:
                kids = {int(k) for k in (task / 'children').read_text().split()}
            except OSError:
                continue
            stack.extend(kids - found)
            found |= kids
    return found


def _alive(pids: set[int]) -> set[int]:
    alive = set()
    for pid in pids:
        try:
            state = Path(f'/proc/{pid}/stat').read_text().split(') ')[-1][0]
        except OSError:
            continue
        if state != 'Z':
            alive.add(pid)
    return alive


def _wait_for(log: Path, text: str, proc: subprocess.Popen, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while text not in log.read_text(errors='replace'):
        assert proc.poll() is None, log.read_text()
        assert time.monotonic() < deadline, log.read_text()
        time.sleep(0.05)


def _is_worker(pid: int) -> bool:
    """A pool worker (not multiprocessing's resource tracker)."""
    try:
        cmdline = Path(f'/proc/{pid}/cmdline').read_bytes()
    except OSError:
        return False
    return b'spawn_main' in cmdline and b'resource_tracker' not in cmdline


def _workers_started(proc: subprocess.Popen, count: int, timeout: float = 60) -> set[int]:
    deadline = time.monotonic() + timeout
    while len({k for k in _alive(_children(proc.pid)) if _is_worker(k)}) < count:
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)
    return _alive(_children(proc.pid))


@pytest.fixture
def previous_db(room_db, tmp_path) -> Path:
    db = tmp_path / 'room.db'
    db.write_bytes(room_db.read_bytes())
    return db


@pytest.mark.parametrize('how', ['alone', 'group_twice', 'sigterm'])
def test_vbn_build_interrupted_during_sift(how, previous_db, ros_env, tmp_path) -> None:
    before = file_digest(previous_db)
    log = tmp_path / 'build.log'
    with open(log, 'w') as out:
        # A background job of a script inherits SIGINT ignored: vbn must not.
        proc = subprocess.Popen(['vbn', 'build', str(BAG), '--db', str(previous_db),
                                 '--workers', '2', '--quiet'], stdout=out, stderr=out,
                                env=ros_env, start_new_session=True,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    _wait_for(log, '[features]', proc)
    workers = _workers_started(proc, 2)
    if how == 'alone':
        os.kill(proc.pid, signal.SIGINT)
    elif how == 'sigterm':
        os.kill(proc.pid, signal.SIGTERM)
    else:
        os.killpg(proc.pid, signal.SIGINT)
        time.sleep(0.02)       # the second Ctrl-C of an impatient user
        os.killpg(proc.pid, signal.SIGINT)
    code, last = (143, 'vbn build: terminated') if how == 'sigterm' else \
        (130, 'vbn build: interrupted')
    assert proc.wait(timeout=30) == code, log.read_text()
    output = log.read_text()
    assert output.strip().splitlines()[-1] == last, output
    assert 'Traceback' not in output and 'KeyboardInterrupt' not in output
    deadline = time.monotonic() + 10
    while _alive(workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(workers)
    assert file_digest(previous_db) == before
    assert sorted(p.name for p in previous_db.parent.iterdir()) == ['build.log', 'room.db']


def test_builder_node_interrupted_during_sift(previous_db, ros_env, tmp_path) -> None:
    before = file_digest(previous_db)
    log = tmp_path / 'builder.log'
    with open(log, 'w') as out:
        proc = subprocess.Popen(['builder', '--ros-args', '-p', f'db:={previous_db}', '-p',
                                 f'bag:={BAG}'], stdout=out, stderr=out, env=ros_env,
                                start_new_session=True)
    _wait_for(log, 'file mode: building', proc)
    workers = _workers_started(proc, 2)
    os.killpg(proc.pid, signal.SIGINT)
    assert proc.wait(timeout=60) == 130, log.read_text()
    output = log.read_text()
    assert 'build stopped by the shutdown' in output and 'Traceback' not in output, output
    assert 'InvalidHandle' not in output
    deadline = time.monotonic() + 10
    while _alive(workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(workers)
    assert file_digest(previous_db) == before
