"""Helpers for tests that start real nodes in subprocesses and talk to them over DDS.

Importable from every package's tests (pytest's ``pythonpath`` includes this folder); the
fixtures that use them are in ``vbn_fixtures.py`` beside it.
"""
from __future__ import annotations

from collections.abc import Callable
import os
from pathlib import Path
import random
import re
import signal
import subprocess
import time

__all__ = ['NodeProcess', 'RosTestNode', 'isolated_env', 'pick_domain_id']

# Domain IDs 1..100 keep the default Fast DDS ports valid on Linux (0..101 are safe).
DOMAIN_ID_LOW, DOMAIN_ID_HIGH = 1, 100


def pick_domain_id(exclude: set[int] | frozenset[int] = frozenset()) -> int:
    """Return a random ROS domain ID, not in ``exclude``."""
    choices = [d for d in range(DOMAIN_ID_LOW, DOMAIN_ID_HIGH + 1) if d not in exclude]
    return random.SystemRandom().choice(choices)


def isolated_env(domain_id: int, base: dict[str, str] | None = None) -> dict[str, str]:
    """Return an environment for a subprocess on ``domain_id``, localhost discovery only."""
    env = dict(os.environ if base is None else base)
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    return env


class NodeProcess:
    """A subprocess whose combined output goes to a log file that tests can wait on."""

    def __init__(self, args: list[str], env: dict[str, str], log_path: Path,
                 cwd: Path | None = None) -> None:
        self.args = args
        self.log_path = log_path
        self._log = open(log_path, 'w')  # noqa: SIM115 - closed in stop()
        self.popen = subprocess.Popen(
            args, env=env, cwd=cwd, stdout=self._log, stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL, start_new_session=True)

    @property
    def output(self) -> str:
        """Everything the process printed so far."""
        return self.log_path.read_text(errors='replace')

    def wait_for_output(self, pattern: str, timeout: float = 30.0) -> re.Match[str]:
        """Wait until ``pattern`` (a regex) appears in the output.

        Raises:
            AssertionError: on timeout or if the process exits first, with its output.
        """
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            match = regex.search(self.output)
            if match:
                return match
            if self.popen.poll() is not None:
                match = regex.search(self.output)
                if match:
                    return match
                raise AssertionError(
                    f'{self.args[0]} exited with {self.popen.returncode} before printing '
                    f'{pattern!r}:\n{self.output}')
            time.sleep(0.02)
        raise AssertionError(f'{pattern!r} not printed within {timeout} s:\n{self.output}')

    def wait(self, timeout: float = 30.0) -> int:
        """Wait for the process to exit by itself and return its exit code."""
        try:
            return self.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.stop()
            raise AssertionError(
                f'{self.args} did not exit within {timeout} s:\n{self.output}') from None

    def stop(self, timeout: float = 10.0) -> int:
        """Stop the process: SIGINT, then SIGTERM, then SIGKILL; return its exit code."""
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            if self.popen.poll() is not None:
                break
            try:
                os.killpg(self.popen.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.popen.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                continue
        code = self.popen.wait()
        self._log.close()
        return code


class RosTestNode:
    """An rclpy node in its own context and executor, for the test process itself."""

    def __init__(self, name: str, domain_id: int) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, predicate: Callable[[], bool], timeout: float = 30.0) -> bool:
        """Spin until ``predicate()`` is true; return False on timeout."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.02)
        return predicate()

    def close(self) -> None:
        """Destroy the node and shut the context down."""
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()
