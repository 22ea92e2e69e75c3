"""Print the messages of a topic as YAML, like ``ros2 topic echo`` (``vbn echo``).

The topic's type comes from the graph (waiting until a publisher appears), its
class from ``<pkg>.msg``; the subscription's QoS adapts to the publishers' offer.
Waiting without a timeout is announced once, so that a missing publisher does not
look like a hang.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import time
from typing import Any

from rclpy.node import Node

from vbn_common.errors import VbnCommonError
from vbn_common.ros_tools.msgtypes import (
    import_message_class,
    subscription_qos_for,
    topic_types,
    wait_for_topic_type,
)
from vbn_common.ros_tools.yaml_echo import message_to_yaml

__all__ = ['NOTICE_AFTER_S', 'EchoOptions', 'echo_topic']

#: Seconds without a publisher (and without a timeout) before the waiting is announced.
NOTICE_AFTER_S = 1.0


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
               write: Callable[[str], None],
               notify: Callable[[str], None] | None = None) -> int:
    """Print messages of ``topic`` through ``write``; return how many were printed.

    Args:
        node: a node in an initialised rclpy context, spun by ``executor``.
        executor: the executor that spins ``node``.
        topic: the topic name.
        options: what to print and for how long.
        write: takes each message's YAML (with its ``---`` line).
        notify: takes one line, once, when there is no timeout and no publisher of
            ``topic`` after :data:`NOTICE_AFTER_S` seconds (``vbn echo`` writes it to
            stderr).

    Raises:
        VbnCommonError: No publisher or not enough messages within the
            timeout, or a type without a Python package here.
    """
    start = time.monotonic()
    notice = _WaitingNotice(node, topic, start, notify if options.timeout_s is None else None)
    msgtype = options.msgtype or _wait_for_type(node, executor, topic, options.timeout_s,
                                                notice)
    cls = import_message_class(msgtype)
    if cls is None:
        raise VbnCommonError(
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
            raise VbnCommonError(
                f'received {received} of {wanted}messages on {topic} within '
                f'{options.timeout_s:g} s')
        if received == 0:
            notice.check()  # --type given and nobody publishes yet
        executor.spin_once(timeout_sec=0.05)
    return received


class _WaitingNotice:
    """Say once that echo is waiting for a publisher, if it has waited long enough."""

    def __init__(self, node: Node, topic: str, start: float,
                 notify: Callable[[str], None] | None) -> None:
        self._node = node
        self._topic = topic
        self._start = start
        self._notify = notify

    def check(self) -> None:
        if (self._notify is None or time.monotonic() - self._start < NOTICE_AFTER_S
                or self._node.count_publishers(self._topic) > 0):
            return
        self._notify(f'waiting for a publisher on {self._topic} (use --timeout S to give up)')
        self._notify = None


def _wait_for_type(node: Node, executor: Any, topic: str, timeout_s: float | None,
                   notice: _WaitingNotice) -> str:
    """Wait for the topic's type in the graph; announce the waiting once (no timeout)."""
    if timeout_s is not None:
        return wait_for_topic_type(node, topic, executor, timeout_s)
    try:
        return wait_for_topic_type(node, topic, executor, NOTICE_AFTER_S)
    except VbnCommonError:
        if len(topic_types(node).get(topic, [])) > 1:
            raise  # several types: waiting longer would not help
    notice.check()
    return wait_for_topic_type(node, topic, executor, None)
