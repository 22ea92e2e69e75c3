"""The ``localizer`` executable: ``ros2 run landmark_localizer localizer --ros-args -p db:=DB``.

Checks the ROS environment before rclpy loads (a bad ``ROS_DOMAIN_ID`` or
``RMW_IMPLEMENTATION`` is one line, ``localizer: error: ...``, exit 2), then runs the
lifecycle node of :mod:`landmark_localizer.node` until Ctrl-C or its shutdown
transition. A start-up error (a parameter of the wrong type, an unknown parameter, with
``autostart`` a database that cannot be used) is the same one line and exit 2.
"""
from __future__ import annotations

import sys

from landmark_localizer.node_support import limit_malloc_arenas, one_thread_per_library
from vbn_common.node_main import run_node

__all__ = ['main']


def main(args: list[str] | None = None) -> int:
    """Run the localizer node; return the exit code (2 on a start-up error)."""
    limit_malloc_arenas()
    one_thread_per_library()
    return run_node('localizer', _make_node, args, help_text=_help)


def _help() -> str:
    from landmark_localizer.parameters import parameter_specs
    from vbn_common.node_main import NodeParameter, format_node_help

    return format_node_help(
        'localizer [-h] --ros-args -p db:=FILE [-p NAME:=VALUE ...] [--params-file FILE]',
        'The localizer lifecycle node: finds its region in the landmark database by '
        "feature voting, tracks the region's landmark features, switches region by "
        'predicted motion and publishes the pose of each camera image '
        '(/localizer/pose, /localizer/pose_with_covariance, /localizer/region, map -> '
        'odom on /tf). With autostart false a lifecycle manager configures and '
        'activates it.',
        [NodeParameter(s.name, s.default, s.description, s.read_only)
         for s in parameter_specs()])


def _make_node() -> object:
    from landmark_localizer.node import LocalizerNode

    return LocalizerNode()


if __name__ == '__main__':
    sys.exit(main())
