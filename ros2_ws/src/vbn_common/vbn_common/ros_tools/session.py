"""An rclpy node for a command-line tool, with the tool in charge of signals.

rclpy's own SIGINT handler shuts the context down under the tool's feet; the bag
tools need to finish their work first (``record`` closes its bag, ``play`` waits
for acknowledgements), so they initialize rclpy without signal handlers and
handle SIGINT and SIGTERM themselves.

The ROS 2 environment variables are checked before rclpy initialises (see
:mod:`vbn_common.ros_environment`), and an ``RCLError`` that rclpy still
raises while initialising becomes one :class:`VbnCommonError` line.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
import os
import signal
from typing import Any

from vbn_common.errors import VbnCommonError
from vbn_common.ros_environment import check_ros_environment

__all__ = ['on_stop_signals', 'rcl_errors_as_one_line', 'ros_node']


@contextmanager
def rcl_errors_as_one_line(doing: str) -> Iterator[None]:
    """Turn an ``RCLError`` raised inside the block into a one-line VbnCommonError.

    Args:
        doing: what the block does, for the message (e.g. ``'initialise ROS 2'``).

    Raises:
        VbnCommonError: ``cannot <doing>: <rcl's message without its source location>``.
    """
    from rclpy.impl.implementation_singleton import rclpy_implementation

    try:
        yield
    except rclpy_implementation.RCLError as error:
        detail = str(error).strip().splitlines()[0] if str(error).strip() else repr(error)
        detail = detail.split(', at /')[0]  # rcl appends the C source file and line
        raise VbnCommonError(f'cannot {doing}: {detail}') from error


@contextmanager
def ros_node(name: str) -> Iterator[tuple[Any, Any]]:
    """Yield ``(node, executor)`` in a fresh rclpy context; clean up on exit.

    The node name gets the process id appended so that two tools never share a name.

    Raises:
        VbnCommonError: the ROS 2 environment variables have a value rclpy
            cannot use, or rclpy failed to initialise (one line each).
    """
    check_ros_environment()
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    with rcl_errors_as_one_line('initialise ROS 2'):
        rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = None
    try:
        with rcl_errors_as_one_line('initialise ROS 2'):
            node = rclpy.create_node(f'{name}_{os.getpid()}', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        yield node, executor
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        context.try_shutdown()


@contextmanager
def on_stop_signals(handler: Callable[[int], None]) -> Iterator[None]:
    """Call ``handler(signum)`` on SIGINT and SIGTERM inside the block; restore after."""
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    for sig in previous:
        signal.signal(sig, lambda signum, _frame: handler(signum))
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def raise_keyboard_interrupt(_signum: int) -> None:
    """Interrupt the main thread like Ctrl-C (a stop-signal handler)."""
    raise KeyboardInterrupt
