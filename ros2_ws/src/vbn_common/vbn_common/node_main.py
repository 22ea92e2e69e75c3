"""The ``main()`` every node of the project shares: start, spin until Ctrl-C, shut down.

Jazzy's ``rclpy.init()`` is not a context manager: the node is destroyed and the context
shut down (``rclpy.try_shutdown``) in a ``finally``, whether the spin ends by Ctrl-C, by
``ExternalShutdownException`` (the launch system's SIGINT) or by an error. The ROS
environment is checked before rclpy loads, so that a bad ``ROS_DOMAIN_ID`` or
``RMW_IMPLEMENTATION`` is one line instead of rcl's exit 102.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
import sys
import textwrap
from typing import Any

from vbn_common.errors import VbnError
from vbn_common.ros_environment import check_ros_environment

__all__ = ['NodeParameter', 'format_node_help', 'run_node']


@dataclass(frozen=True)
class NodeParameter:
    """One parameter of a node, as its ``--help`` lists it."""

    name: str
    default: Any
    description: str
    read_only: bool


def format_node_help(usage: str, summary: str, parameters: Sequence[NodeParameter]) -> str:
    """Return a node's ``--help``: usage, what it does, then every parameter.

    Each parameter line gives its name, its type and default (``None``: automatic, any
    type), whether it takes effect when set at run time or is read-only, and its
    description.
    """
    lines = [f'usage: {usage}', '', textwrap.fill(summary, 88), '',
             *textwrap.wrap('parameters (set with -p NAME:=VALUE or --params-file FILE; '
                            '"live": takes effect when set at run time):', 88)]
    for p in parameters:
        kind = 'any' if p.default is None else type(p.default).__name__
        when = 'read-only' if p.read_only else 'live'
        lines.append(f'  {p.name} ({kind}, default {p.default!r}, {when})')
        if p.description:
            lines.extend(textwrap.wrap(p.description, 84, initial_indent='      ',
                                       subsequent_indent='      '))
    return '\n'.join(lines) + '\n'


def run_node(name: str, make_node: Callable[[], Any], args: list[str] | None = None, *,
             threads: int = 1, start: Callable[[Any], None] | None = None,
             close: Callable[[Any], None] | None = None,
             help_text: Callable[[], str] | None = None) -> int:
    """Create a node, spin it until Ctrl-C or shutdown, and clean up.

    Args:
        name: The executable's name, for ``NAME: error: ...`` on stderr.
        make_node: Creates the node (after ``rclpy.init``); a
            :class:`~vbn_common.errors.VbnError` it raises is a start-up error.
        args: Command-line arguments for ``rclpy.init`` (None: ``sys.argv``).
        threads: Executor threads (1: a single-threaded executor).
        start: Called with the node once it is added to the executor.
        close: Called with the node before it is destroyed.
        help_text: Returns the node's ``--help`` (``-h``/``--help`` before any
            ``--ros-args``: printed, exit 0, no ROS started).

    Returns:
        The exit code: 2 on a start-up error (one line on stderr), else the node's
        ``exit_code`` attribute if it has one, else 0.
    """
    argv = list(sys.argv[1:] if args is None else args[1:])
    ours = argv[:argv.index('--ros-args')] if '--ros-args' in argv else argv
    if help_text is not None and ({'-h', '--help'} & set(ours)):
        print(help_text(), end='')
        return 0
    try:
        check_ros_environment()
    except VbnError as error:
        print(f'{name}: error: {error}', file=sys.stderr)
        return 2
    import rclpy
    from rclpy.executors import (
        ExternalShutdownException,
        MultiThreadedExecutor,
        SingleThreadedExecutor,
    )

    rclpy.init(args=args)
    node = None
    try:
        node = make_node()
        executor = MultiThreadedExecutor(num_threads=threads) if threads > 1 else \
            SingleThreadedExecutor()
        executor.add_node(node)
        if start is not None:
            start(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except VbnError as error:
        print(f'{name}: error: {error}', file=sys.stderr)
        return 2
    finally:
        if node is not None:
            if close is not None:
                close(node)
            node.destroy_node()
        rclpy.try_shutdown()
    return int(getattr(node, 'exit_code', 0))
