"""The ``builder`` executable: ``ros2 run visibility_builder builder --ros-args -p db:=DB``.

Checks the ROS environment before rclpy loads (a bad ``ROS_DOMAIN_ID`` or
``RMW_IMPLEMENTATION`` is one line, ``builder: error: ...``, exit 2), then runs the node
of :mod:`visibility_builder.builder_node` until Ctrl-C (or the end of a build with
``shutdown_after_build``). A start-up error (a parameter of the wrong type, an unknown
parameter, a bad build setting) is the same one line and exit 2.
"""
from __future__ import annotations

import sys

from vbn_common.node_main import run_node

__all__ = ['main']


def main(args: list[str] | None = None) -> int:
    """Run the builder node; return the exit code (2 on a start-up error, 1 if it failed).

    Three executor threads: ``~/build`` waits for the build while the recorder's
    subscriptions and the progress timer go on.
    """
    return run_node('builder', _make_node, args, threads=3, start=lambda node: node.start(),
                    close=lambda node: node.close(), help_text=_help)


def _help() -> str:
    from vbn_common.node_main import NodeParameter, format_node_help
    from visibility_builder.build_config import BuildConfig, flat_config, setting_descriptions
    from visibility_builder.builder_node import NODE_PARAMETERS, READ_ONLY

    describe = setting_descriptions()
    parameters = [NodeParameter(name, default, text, name in READ_ONLY)
                  for name, (default, text) in NODE_PARAMETERS.items()]
    parameters += [NodeParameter(name, value, describe.get(name, ''), False)
                   for name, value in flat_config(BuildConfig()).items()]
    return format_node_help(
        'builder [-h] --ros-args -p db:=FILE [-p bag:=BAG] [-p NAME:=VALUE ...]',
        'The builder node: builds the landmark database of an exploration bag (file mode, '
        '-p bag:=BAG) or of what it records from the live topics (live mode: on '
        '~/build or after idle_timeout seconds without a new image), publishing its '
        'progress and the regions. The build settings are those of vbn build --set.',
        parameters)


def _make_node() -> object:
    from visibility_builder.builder_node import BuilderNode

    return BuilderNode()


if __name__ == '__main__':
    sys.exit(main())
