"""The command lines of the processes a ROS graph of ours is made of, for harnesses to start.

A DDS exchange between processes can only be shown by processes: ``vbn doctor`` starts
the echo side of its check, and the demo starts the localizer node, a recorder and a
player, as a launch file would start ``ros2 run`` nodes beside ``ros2 bag play`` and
``ros2 bag record``. This module is the one place that names them; everything else a
harness needs (a build, a render, a localization) it imports and calls.
"""
from __future__ import annotations

import shutil
import sys

from vbn_common.errors import VbnCommonError

__all__ = ['GRAPH_PROCESSES', 'graph_process_argv']

#: What each graph process runs: our bag tools over DDS, the probe's echo, the nodes.
GRAPH_PROCESSES = {
    'play': [sys.executable, '-m', 'vbn_common.cli.main', 'play'],
    'record': [sys.executable, '-m', 'vbn_common.cli.main', 'record'],
    'dds_probe': [sys.executable, '-m', 'vbn_common.dds_probe_main'],
}
#: Node executables, found on ``PATH`` as ``ros2 run`` finds them in ``lib/<package>``.
NODE_EXECUTABLES = ('localizer', 'builder')


def graph_process_argv(name: str, *args: str, path: str | None = None) -> list[str]:
    """Return the command line of graph process ``name`` with ``args``.

    Args:
        name: ``play``, ``record``, ``dds_probe`` or a node executable (``localizer``,
            ``builder``).
        args: Its arguments (``--ros-args ...`` for a node).
        path: The ``PATH`` to find a node executable on (default this process's).

    Raises:
        VbnCommonError: An unknown name, or a node that is not installed.
    """
    if name in GRAPH_PROCESSES:
        return [*GRAPH_PROCESSES[name], *args]
    if name not in NODE_EXECUTABLES:
        raise VbnCommonError(f'no graph process {name!r} '
                             f'({", ".join([*GRAPH_PROCESSES, *NODE_EXECUTABLES])})')
    executable = shutil.which(name, path=path)
    if executable is None:
        raise VbnCommonError(f'the {name} node is not installed (run make setup)')
    return [executable, *args]
