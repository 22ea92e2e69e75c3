"""The ``dds_probe`` executable: the echo side of ``vbn doctor``'s DDS check.

``dds_probe echo [--suffix S]`` republishes every ping of :mod:`vbn_common.dds_probe` on
the pong topic until Ctrl-C. The ROS environment is checked before rclpy loads, so that
a bad ``ROS_DOMAIN_ID`` or ``RMW_IMPLEMENTATION`` is one line (``dds_probe: error:
...``, exit 2) as for every executable of the project.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import sys

from vbn_common.node_main import run_node

__all__ = ['main']


def main(argv: Sequence[str] | None = None) -> int:
    """Run the echo side; return 2 for a bad ROS environment."""
    args = list(sys.argv[1:] if argv is None else argv)
    ours = args[:args.index('--ros-args')] if '--ros-args' in args else args
    parser = argparse.ArgumentParser(prog='dds_probe',
                                     description="the echo side of vbn doctor's DDS check")
    parser.add_argument('role', choices=['echo'], help='the role of this process')
    parser.add_argument('--suffix', default='', help='suffix of the ping/pong topic names')
    options = parser.parse_args(ours)

    def make_node() -> object:
        from vbn_common.dds_probe import EchoNode
        return EchoNode(options.suffix)

    return run_node('dds_probe', make_node, ['dds_probe', *args])


if __name__ == '__main__':
    sys.exit(main())
