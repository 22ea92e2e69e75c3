"""``vbn doctor``: report the toolchain and prove a two-process DDS exchange."""
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
        description='Print the Python, rclpy, RMW, OpenCV and rosbags versions, then start '
                    'an echo node in a second process and exchange a message with it over '
                    'DDS. Exit 0 only when the message came back.')
    parser.add_argument('--timeout', type=float, default=30.0,
                        help='seconds to wait for discovery and the echo (default 30)')
    parser.set_defaults(func=run)


def _version(module: str) -> str:
    from importlib import metadata
    try:
        return metadata.version(module)
    except metadata.PackageNotFoundError:
        return 'not installed'


def run(args: argparse.Namespace) -> int:
    """Print the report and the verdict; return 0 when the exchange worked."""
    import cv2
    import rclpy
    from rclpy.utilities import get_rmw_implementation_identifier

    from visibility_builder.dds_probe import ping

    print(f'python:        {platform.python_version()} ({sys.executable})')
    print(f'rclpy:         {_version("ros-rclpy")} (ROS 2 Jazzy wheels)')
    print(f'opencv:        {cv2.__version__}')
    print(f'rosbags:       {_version("rosbags")}')
    print(f'ROS_DOMAIN_ID: {os.environ.get("ROS_DOMAIN_ID", "0 (unset)")}, '
          f'discovery range: {os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET (unset)")}')

    suffix = f'_{os.getpid()}'
    echo = subprocess.Popen(
        [sys.executable, '-m', 'visibility_builder.dds_probe', 'echo', '--suffix', suffix],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    rclpy.init()
    try:
        print(f'rmw:           {get_rmw_implementation_identifier()}')
        node = rclpy.create_node('vbn_doctor')
        text = f'hello from vbn doctor, nonce {uuid.uuid4().hex[:12]}'
        result = ping(node, text, suffix=suffix, timeout_s=args.timeout)
        node.destroy_node()
    finally:
        rclpy.try_shutdown()
        echo.terminate()
        try:
            _, stderr = echo.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            echo.kill()
            _, stderr = echo.communicate()
    print(f'dds exchange:  echo node in process {echo.pid}, discovery {result.discovery_s:.2f} s')
    if result.ok:
        print(f'published:     "{text}"')
        print(f'echoed back:   "{result.message}" (round trip {result.round_trip_ms:.1f} ms)')
        print('verdict:       OK - a publisher and a subscriber in two processes '
              'exchanged messages over DDS')
        return 0
    print(f'verdict:       FAILED - {result.detail}')
    if stderr.strip():
        print('echo node said: ' + stderr.strip().splitlines()[-1])
    return 1
