"""``vbn doctor``: report the toolchain and ROS environment, prove a two-process DDS exchange."""
from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import uuid

__all__ = ['register', 'run']


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``doctor`` subcommand."""
    parser = subparsers.add_parser(
        'doctor', help='print versions and check a two-process DDS exchange',
        description='Print the Python, rclpy, RMW, OpenCV and rosbags versions, check the '
                    'ROS 2 environment variables (ROS_DOMAIN_ID, RMW_IMPLEMENTATION, '
                    'ROS_AUTOMATIC_DISCOVERY_RANGE, ROS_LOCALHOST_ONLY), report whether '
                    'tf2_msgs is importable and its TFMessage type hash matches ROS 2 '
                    "Jazzy's, then start an echo node in a second process and exchange a "
                    'message with it over DDS. Exit 0 only when the message came back and '
                    'nothing above failed; the last line is the verdict.')
    parser.add_argument('--timeout', type=float, default=30.0,
                        help='seconds to wait for discovery and the echo (default 30)')
    parser.set_defaults(func=run)


def _version(module: str) -> str:
    from importlib import metadata
    try:
        return metadata.version(module)
    except metadata.PackageNotFoundError:
        return 'not installed'


def _tf2_report() -> tuple[list[str], str]:
    """Lines about tf2_msgs, and a problem ('' when none) for the verdict."""
    from rosbags.typesys import Stores, get_typestore

    from vbn_common.ros_tools.msgtypes import import_message_class, message_type_hash

    msgtype = 'tf2_msgs/msg/TFMessage'
    cls = import_message_class(msgtype)
    if cls is None:
        # Only /tf and /tf_static need it; the DDS check does not.
        return ['tf2_msgs:      not importable (run make setup)'], ''
    package = sys.modules['tf2_msgs']
    built = message_type_hash(cls)
    jazzy = get_typestore(Stores.ROS2_JAZZY).hash_rihs01(msgtype)
    match = 'match' if built == jazzy else 'MISMATCH'
    lines = [f'tf2_msgs:      importable ({os.path.dirname(package.__file__ or "?")})',
             f'tf2 hash:      {built or "unknown (no type support)"} ({msgtype} as built here)',
             f'jazzy hash:    {jazzy} (rosbags, ROS 2 Jazzy): {match}']
    if built == jazzy:
        return lines, ''
    return lines, (f'{msgtype} was built with type hash {built or "unknown"}, ROS 2 Jazzy has '
                   f'{jazzy} (rebuild it with make setup)')


def run(args: argparse.Namespace) -> int:
    """Print the report and the verdict; return 0 when the exchange worked, else 1.

    The ROS 2 environment variables are checked before rclpy is imported: a value
    rclpy cannot use gives a ``verdict: FAILED - <variable>=<value> ... (allowed:
    ...)`` line instead of a traceback or a silent exit.
    """
    import cv2

    from vbn_common.errors import VbnCommonError
    from vbn_common.ros_environment import (
        installed_rmw_implementations,
        ros_environment_problems,
    )

    print(f'python:        {platform.python_version()} ({sys.executable})')
    print(f'rclpy:         {_version("ros-rclpy")} (ROS 2 Jazzy wheels)')
    print(f'opencv:        {cv2.__version__}')
    print(f'rosbags:       {_version("rosbags")}')
    discovery = os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE') or 'SUBNET (unset)'
    print(f'ROS_DOMAIN_ID: {os.environ.get("ROS_DOMAIN_ID") or "0 (unset)"}, '
          f'discovery range: {discovery}')
    rmw_installed = installed_rmw_implementations()
    print(f'rmw installed: {", ".join(rmw_installed) or "none found"}; '
          f'RMW_IMPLEMENTATION: {os.environ.get("RMW_IMPLEMENTATION") or "unset"}')
    problems = ros_environment_problems(os.environ, rmw_installed)
    if problems:
        # Importing rclpy (or the tf2 check, which loads it) could end the process.
        print('tf2_msgs:      not checked (the ROS environment is not usable)')
        print(f'verdict:       FAILED - {"; ".join(problems)}')
        return 1
    tf2_lines, tf2_problem = _tf2_report()
    for line in tf2_lines:
        print(line)

    import rclpy
    from rclpy.utilities import get_rmw_implementation_identifier

    from vbn_common.dds_probe import ping
    from vbn_common.graph_processes import graph_process_argv
    from vbn_common.ros_tools.session import rcl_errors_as_one_line

    suffix = f'_{os.getpid()}'
    echo = subprocess.Popen(graph_process_argv('dds_probe', 'echo', '--suffix', suffix),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    text = f'hello from vbn doctor, nonce {uuid.uuid4().hex[:12]}'
    result = None
    failure = ''
    try:
        with rcl_errors_as_one_line('initialise ROS 2'):
            rclpy.init()
            print(f'rmw:           {get_rmw_implementation_identifier()}')
            node = rclpy.create_node('vbn_doctor')
        result = ping(node, text, suffix=suffix, timeout_s=args.timeout)
        node.destroy_node()
    except VbnCommonError as error:
        failure = str(error)
    finally:
        rclpy.try_shutdown()
        echo.terminate()
        try:
            _, stderr = echo.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            echo.kill()
            _, stderr = echo.communicate()
    if result is not None:
        print(f'dds exchange:  echo node in process {echo.pid}, '
              f'discovery {result.discovery_s:.2f} s')
        if result.ok:
            print(f'published:     "{text}"')
            print(f'echoed back:   "{result.message}" (round trip {result.round_trip_ms:.1f} ms)')
        else:
            failure = result.detail
    if not failure and not tf2_problem:
        print('verdict:       OK - a publisher and a subscriber in two processes '
              'exchanged messages over DDS')
        return 0
    print(f'verdict:       FAILED - {"; ".join(p for p in (failure, tf2_problem) if p)}')
    if failure and stderr.strip():
        print('echo node said: ' + stderr.strip().splitlines()[-1])
    return 1
