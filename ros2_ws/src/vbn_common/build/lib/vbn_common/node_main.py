"""The ``main()`` every node of the project shares: start, spin until Ctrl-C, shut down.

Jazzy's ``rclpy.init()`` is not a context manager: the node is destroyed and the context
shut down (``rclpy.try_shutdown``) in a ``finally``, whether the spin ends by Ctrl-C, by
``ExternalShutdownException`` (the launch system's SIGINT) or by an error. The ROS
environment is checked before rclpy loads, so that a bad ``ROS_DOMAIN_ID`` or
``RMW_IMPLEMENTATION`` is one line instead of rcl's exit 102.
"""
from __future__ import annotations

from collections.abc import Callable
import sys
from typing import Any

from vbn_common.errors import VbnError
from vbn_common.ros_environment import check_ros_environment

__all__ = ['run_node']


def run_node(name: str, make_node: Callable[[], Any], args: list[str] | None = None, *,
             threads: int = 1, start: Callable[[Any], None] | None = None,
             close: Callable[[Any], None] | None = None) -> int:
    """Create a node, spin it until Ctrl-C or shutdown, and clean up.

    Args:
        name: The executable's name, for ``NAME: error: ...`` on stderr.
        make_node: Creates the node (after ``rclpy.init``); a
            :class:`~vbn_common.errors.VbnError` it raises is a start-up error.
        args: Command-line arguments for ``rclpy.init`` (None: ``sys.argv``).
        threads: Executor threads (1: a single-threaded executor).
        start: Called with the node once it is added to the executor.
        close: Called with the node before it is destroyed.

    Returns:
        The exit code: 2 on a start-up error (one line on stderr), else the node's
        ``exit_code`` attribute if it has one, else 0.
    """
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
