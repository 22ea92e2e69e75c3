"""Check the ROS 2 environment variables before rclpy is loaded or initialised.

A bad value in these variables does not give a clear error from ROS itself:

- ``ROS_DOMAIN_ID=abc`` ends ``rclpy.init`` in an ``RCLError`` traceback;
- ``ROS_DOMAIN_ID=300`` makes Fast DDS print a port error and end the process
  (exit 1) while the first node is created: domain ids above 232 do not map to
  valid UDP ports with the default port mapping (port base 7400, domain gain 250);
- ``RMW_IMPLEMENTATION`` naming a middleware that is not installed makes rcl end
  the process (exit 102) while its library is being *loaded*, i.e. on ``import
  rclpy``, before any Python code could catch it;
- an unknown ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is silently taken as localhost-only,
  and any ``ROS_LOCALHOST_ONLY`` other than ``1`` silently as "disabled".

So the tools check the variables here, before importing rclpy, and turn a bad value
into one line naming the variable, its value and what is allowed. This module must
not import rclpy (or anything that loads rcl).
"""
from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
import os
from pathlib import Path
import re
import sys

from vbn_common.errors import VbnCommonError

__all__ = [
    'DISCOVERY_RANGES',
    'DOMAIN_ID_MAX',
    'check_ros_environment',
    'installed_rmw_implementations',
    'ros_environment_problems',
]

#: Largest ROS_DOMAIN_ID whose Fast DDS ports (default mapping) are valid UDP ports.
DOMAIN_ID_MAX = 232

#: The values rcl accepts for ROS_AUTOMATIC_DISCOVERY_RANGE (case-sensitive).
DISCOVERY_RANGES = ('SUBNET', 'LOCALHOST', 'OFF', 'SYSTEM_DEFAULT')

_DOMAIN_IDS_ALLOWED = (
    f'an integer 0-{DOMAIN_ID_MAX}; 0-101 and 215-{DOMAIN_ID_MAX} also stay clear of '
    "Linux's ephemeral ports")
_DECIMAL = re.compile(r'[0-9]+')


def installed_rmw_implementations(prefixes: Sequence[str | Path] | None = None
                                  ) -> tuple[str, ...]:
    """Return the RMW implementations whose library is installed, without loading any.

    An RMW implementation package registers itself in the ament index under the
    ``rmw_typesupport`` resource type and installs ``lib/lib<name>.so``; both must be
    present in one install prefix.

    Args:
        prefixes: install prefixes to search (default: ``AMENT_PREFIX_PATH`` and this
            Python's prefix, where the ROS 2 wheels install their ament index).

    Returns:
        Sorted implementation names, e.g. ``('rmw_fastrtps_cpp',)``; empty if none is
        found (then nothing can be said about ``RMW_IMPLEMENTATION``).
    """
    if prefixes is None:
        prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
        prefixes.append(sys.prefix)
    found: set[str] = set()
    for prefix in map(Path, prefixes):
        index = prefix / 'share' / 'ament_index' / 'resource_index' / 'rmw_typesupport'
        if not index.is_dir():
            continue
        for entry in index.iterdir():
            name = entry.name
            # rmw_implementation is the dispatcher that loads one of the others.
            if name == 'rmw_implementation' or not name.startswith('rmw_'):
                continue
            if (prefix / 'lib' / f'lib{name}.so').exists():
                found.add(name)
    return tuple(sorted(found))


def ros_environment_problems(environ: Mapping[str, str],
                             rmw_installed: Collection[str]) -> list[str]:
    """Return one line per ROS 2 environment variable whose value would break rclpy.

    Unset or empty variables are fine (ROS uses its defaults). Each line names the
    variable, its value and what is allowed, e.g.
    ``ROS_DOMAIN_ID=abc is not an integer (allowed: an integer 0-232; ...)``.

    Args:
        environ: the environment to check (e.g. ``os.environ``).
        rmw_installed: the RMW implementations installed here (see
            :func:`installed_rmw_implementations`); empty: do not check
            ``RMW_IMPLEMENTATION``.

    Returns:
        The problems, in a fixed order; empty when the environment is usable.
    """
    problems = []
    domain_id = environ.get('ROS_DOMAIN_ID', '').strip()
    if domain_id and not _DECIMAL.fullmatch(domain_id):
        problems.append(f'ROS_DOMAIN_ID={domain_id} is not an integer '
                        f'(allowed: {_DOMAIN_IDS_ALLOWED})')
    elif domain_id and int(domain_id) > DOMAIN_ID_MAX:
        problems.append(f'ROS_DOMAIN_ID={domain_id} is too large for Fast DDS ports '
                        f'(allowed: {_DOMAIN_IDS_ALLOWED})')

    rmw = environ.get('RMW_IMPLEMENTATION', '').strip()
    if rmw and rmw_installed and rmw not in rmw_installed:
        problems.append(f'RMW_IMPLEMENTATION={rmw} is not installed here '
                        f'(allowed: {", ".join(sorted(rmw_installed))}, or unset)')

    discovery = environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '')
    if discovery and discovery not in DISCOVERY_RANGES:
        problems.append(f'ROS_AUTOMATIC_DISCOVERY_RANGE={discovery} is not a discovery range '
                        f'(allowed: {", ".join(DISCOVERY_RANGES)}, or unset)')

    localhost_only = environ.get('ROS_LOCALHOST_ONLY', '')
    if localhost_only and localhost_only not in ('0', '1'):
        problems.append(f'ROS_LOCALHOST_ONLY={localhost_only} is neither 1 nor 0 '
                        '(allowed: 1, 0, or unset; deprecated since Jazzy, use '
                        'ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)')
    return problems


def check_ros_environment(environ: Mapping[str, str] | None = None,
                          rmw_installed: Collection[str] | None = None) -> None:
    """Raise if the ROS 2 environment would make rclpy fail; call before importing rclpy.

    Args:
        environ: the environment to check (default: ``os.environ``).
        rmw_installed: the RMW implementations installed here (default: found by
            :func:`installed_rmw_implementations`).

    Raises:
        VbnCommonError: a variable has a value ROS cannot use; the message
            names the variable, its value and what is allowed (all problems, joined
            by ``'; '``).
    """
    environ = os.environ if environ is None else environ
    if rmw_installed is None:
        rmw_installed = installed_rmw_implementations()
    problems = ros_environment_problems(environ, rmw_installed)
    if problems:
        raise VbnCommonError('; '.join(problems))
