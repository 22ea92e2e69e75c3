"""Fixtures for tests that start real nodes in subprocesses and talk to them over DDS.

Isolation: each test run picks its own random ``ROS_DOMAIN_ID`` (override with
``VBN_TEST_DOMAIN_ID``) and sets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, both in
this process (for in-process rclpy) and in every subprocess it starts, so two runs on
one machine never see each other.

Waiting: discovery takes seconds, so tests wait for a condition (matched endpoints, a
line of output, a received message) with a bounded timeout, never on a fixed sleep.
Every subprocess started through ``start_process`` is stopped at teardown (SIGINT,
then SIGTERM, then SIGKILL), and pytest-timeout fails a test whose node hangs.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
import os
from pathlib import Path
import subprocess
import sys

from paths import REPO
import pytest
from ros_harness import NodeProcess, RosTestNode, isolated_env, pick_domain_id


@pytest.fixture(scope='session')
def ros_domain_id() -> Iterator[int]:
    """The random domain ID of this test run, also exported to this process's rclpy."""
    domain_id = int(os.environ.get('VBN_TEST_DOMAIN_ID') or pick_domain_id())
    saved = {k: os.environ.get(k) for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')}
    os.environ.update(isolated_env(domain_id, {}))
    yield domain_id
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


@pytest.fixture(scope='session')
def ros_env(ros_domain_id: int) -> dict[str, str]:
    """Environment for subprocesses of this test run."""
    return isolated_env(ros_domain_id)


@pytest.fixture
def start_process(ros_env: dict[str, str], tmp_path: Path
                  ) -> Iterator[Callable[..., NodeProcess]]:
    """Start subprocesses in this run's DDS domain; all are stopped at teardown.

    Call as ``start_process([cmd, *args], env=None, name=None)``; a command given as
    ``'python'`` runs this interpreter.
    """
    started: list[NodeProcess] = []

    def start(args: list[str], env: dict[str, str] | None = None,
              name: str | None = None) -> NodeProcess:
        args = [sys.executable if args[0] == 'python' else args[0], *args[1:]]
        log_name = f'{name or Path(args[0]).name}-{len(started)}.log'
        proc = NodeProcess(args, env or ros_env, tmp_path / log_name)
        started.append(proc)
        return proc

    yield start
    for proc in started:
        proc.stop()


@pytest.fixture
def ros_node(ros_domain_id: int) -> Iterator[RosTestNode]:
    """An in-process rclpy node on this run's domain."""
    node = RosTestNode('vbn_test', ros_domain_id)
    yield node
    node.close()


@pytest.fixture(scope='session')
def room_build(tmp_path_factory) -> dict:
    """The room's database, built once per session with the defaults and shared.

    ``vbn build bags/room_exploration`` with ``--report``: ``{'db', 'report', 'output'}``
    (the database path, the report folder and what the command printed).
    """
    folder = tmp_path_factory.mktemp('room_build')
    db = folder / 'room.db'
    bag = REPO / 'bags' / 'room_exploration'
    proc = subprocess.run(['vbn', 'build', str(bag), '--db', str(db), '--report',
                           str(folder / 'report'), '--scene', 'room', '--quiet'],
                          capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return {'db': db, 'report': folder / 'report', 'output': proc.stdout}


@pytest.fixture(scope='session')
def room_db(room_build: dict) -> Path:
    """The session's room database (built once with the builder's defaults)."""
    return room_build['db']
