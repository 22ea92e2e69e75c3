"""A bad ROS 2 environment gives one clear line through the real ``vbn``.

Before: ``ROS_DOMAIN_ID=abc`` ended in an RCLError traceback, ``ROS_DOMAIN_ID=300`` in
a Fast DDS port error without a verdict, ``RMW_IMPLEMENTATION=rmw_cyclonedds_cpp`` in
rcl's raw line and exit 102; ``vbn echo TOPIC --once`` without a publisher waited
without a word.
"""
from __future__ import annotations

import subprocess
import time

import pytest

pytestmark = pytest.mark.integration

BAD_ENVIRONMENTS = [
    ({'ROS_DOMAIN_ID': 'abc'}, 'ROS_DOMAIN_ID=abc is not an integer', 'allowed: an integer 0-232'),
    ({'ROS_DOMAIN_ID': '300'}, 'ROS_DOMAIN_ID=300 is too large', 'allowed: an integer 0-232'),
    ({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'},
     'RMW_IMPLEMENTATION=rmw_cyclonedds_cpp is not installed here',
     'allowed: rmw_fastrtps_cpp, or unset'),
]


def _run(args: list[str], env: dict[str, str], timeout: float = 60
         ) -> subprocess.CompletedProcess[str]:
    return subprocess.run(args, env=env, capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


@pytest.mark.parametrize(('bad', 'problem', 'allowed'), BAD_ENVIRONMENTS)
def test_doctor_reports_and_fails_on_a_bad_environment(ros_env, bad, problem, allowed):
    result = _run(['vbn', 'doctor', '--timeout', '10'], {**ros_env, **bad})
    assert result.returncode == 1, result
    assert 'Traceback' not in result.stdout + result.stderr
    assert 'RTPS' not in result.stdout + result.stderr  # Fast DDS never started
    lines = result.stdout.splitlines()
    assert lines[0].startswith('python:')  # the report is still printed
    assert lines[-1].startswith(f'verdict:       FAILED - {problem}')
    assert allowed in lines[-1]


@pytest.mark.parametrize(('bad', 'problem', 'allowed'), BAD_ENVIRONMENTS)
def test_echo_says_what_is_wrong_in_one_line(ros_env, bad, problem, allowed):
    result = _run(['vbn', 'echo', '/x', '--once'], {**ros_env, **bad})
    assert result.returncode == 2, result
    assert result.stdout == ''
    (line,) = result.stderr.splitlines()
    assert line.startswith(f'vbn echo: error: {problem}')
    assert allowed in line


def test_play_with_an_uninstalled_rmw_says_so_in_one_line(ros_env):
    # rcl would end the process on `import rclpy` (exit 102): the check runs before.
    result = _run(['vbn', 'play', 'bags/room_run'],
                  {**ros_env, 'RMW_IMPLEMENTATION': 'rmw_zenoh_cpp'})
    assert result.returncode == 2, result
    (line,) = result.stderr.splitlines()
    assert line.startswith('vbn play: error: RMW_IMPLEMENTATION=rmw_zenoh_cpp is not installed')


def test_echo_timeout_without_publisher_fails_in_one_line(ros_env):
    start = time.monotonic()
    result = _run(['vbn', 'echo', '/vbn_test/nobody_publishes', '--once', '--timeout', '2'],
                  ros_env)
    elapsed = time.monotonic() - start
    assert result.returncode == 2, result
    assert elapsed < 15, elapsed
    assert result.stderr.splitlines() == [
        'vbn echo: error: no publisher of /vbn_test/nobody_publishes appeared within 2 s']


def test_echo_without_timeout_says_once_that_it_waits(start_process):
    proc = start_process(['vbn', 'echo', '/vbn_test/nobody_publishes', '--once'])
    proc.wait_for_output(r'waiting for a publisher on /vbn_test/nobody_publishes '
                         r'\(use --timeout S to give up\)\n', timeout=30)
    # Still waiting a while later, and it said so only once.
    deadline = time.monotonic() + 3
    while time.monotonic() < deadline:
        assert proc.popen.poll() is None, proc.output
        time.sleep(0.2)
    assert proc.output.count('waiting for a publisher') == 1, proc.output
    assert proc.stop() == 0, proc.output


@pytest.mark.parametrize('args', [
    ['localizer', '--ros-args', '-p', 'db:=/nonexistent.db'],
    ['builder', '--ros-args', '-p', 'db:=/nonexistent/x.db'],
    ['dds_probe', 'echo'],
])
def test_every_executable_refuses_a_bad_domain_in_one_line(ros_env, args):
    """The node executables give the same one line as ``vbn`` before rclpy starts."""
    result = _run(args, {**ros_env, 'ROS_DOMAIN_ID': 'abc'})
    assert result.returncode == 2, result
    assert result.stdout == '' and 'Traceback' not in result.stderr
    assert result.stderr.strip().splitlines() == [
        f'{args[0]}: error: ROS_DOMAIN_ID=abc is not an integer (allowed: an integer 0-232; '
        "0-101 and 215-232 also stay clear of Linux's ephemeral ports)"]


@pytest.mark.parametrize(('args', 'line'), [
    (['builder', '--ros-args', '-p', 'decomposition.k:=abc'],
     "builder: error: parameter decomposition.k: Trying to set parameter 'decomposition.k' "
     "to 'abc' of type 'STRING', expecting type 'INTEGER'"),
    (['localizer', '--ros-args', '-p', 'dbb:=x'],
     "localizer: error: unknown parameter 'dbb' (did you mean 'db'?)"),
    (['builder', '--ros-args', '-p', 'decompositon.k:=3'],
     "builder: error: unknown parameter 'decompositon.k' (did you mean 'decomposition.k'?)"),
])
def test_a_mistyped_parameter_is_one_line_naming_it(ros_env, args, line):
    result = _run(args, ros_env)
    assert result.returncode == 2, result
    assert 'Traceback' not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(line), lines
