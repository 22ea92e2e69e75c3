"""Print the messages of a topic as YAML, like ``ros2 topic echo`` (``vbn echo``).

The topic's type comes from the graph (waiting until a publisher appears), its
class from ``<pkg>.msg``; the subscription's QoS adapts to the publishers' offer.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import time
from typing import Any

from rclpy.node import Node

from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.ros_tools.msgtypes import (
    import_message_class,
    subscription_qos_for,
    wait_for_topic_type,
)
from visibility_builder.ros_tools.yaml_echo import message_to_yaml

__all__ = ['EchoOptions', 'echo_topic']


@dataclass(frozen=True)
class EchoOptions:
    """What to print and for how long.

    Attributes:
        count: Stop after this many messages (None: until interrupted).
        timeout_s: Give up after this many seconds in all (None: wait).
        msgtype: The topic's type if known (skips waiting for it in the graph).
        truncate_length: Cut longer arrays and strings (None: print everything).
        no_arr: Print arrays as their type and length.
        no_str: Print strings as their length.
    """

    count: int | None = None
    timeout_s: float | None = None
    msgtype: str | None = None
    truncate_length: int | None = 128
    no_arr: bool = False
    no_str: bool = False


def echo_topic(node: Node, executor: Any, topic: str, options: EchoOptions,
               write: Callable[[str], None]) -> int:
    """Print messages of ``topic`` through ``write``; return how many were printed.

    Raises:
        VisibilityBuilderError: No publisher or not enough messages within the
            timeout, or a type without a Python package here.
    """
    start = time.monotonic()
    msgtype = options.msgtype or wait_for_topic_type(node, topic, executor, options.timeout_s)
    cls = import_message_class(msgtype)
    if cls is None:
        raise VisibilityBuilderError(
            f'cannot echo {topic}: message type {msgtype} has no Python package here')
    offered = [info.qos_profile for info in node.get_publishers_info_by_topic(topic)]
    received = 0

    def on_message(msg: Any) -> None:
        nonlocal received
        if options.count is not None and received >= options.count:
            return
        received += 1
        write(message_to_yaml(msg, truncate_length=options.truncate_length,
                              no_arr=options.no_arr, no_str=options.no_str) + '---\n')

    node.create_subscription(cls, topic, on_message, subscription_qos_for(offered, depth=10))
    while options.count is None or received < options.count:
        if options.timeout_s is not None and time.monotonic() - start > options.timeout_s:
            wanted = f'{options.count} ' if options.count is not None else ''
            raise VisibilityBuilderError(
                f'received {received} of {wanted}messages on {topic} within '
                f'{options.timeout_s:g} s')
        executor.spin_once(timeout_sec=0.05)
    return received
