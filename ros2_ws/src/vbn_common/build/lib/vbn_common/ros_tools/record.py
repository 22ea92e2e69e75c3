"""Record topics of any type as raw CDR into an MCAP bag (``vbn record``).

Each requested topic is subscribed as soon as a publisher of it appears in the
graph, with its type taken from the graph and a QoS compatible with every offered
profile (like ``ros2 bag record``); the offered profiles are written to the bag
so that ``vbn play`` offers them again. Messages arrive as serialized bytes
(``create_subscription(..., raw=True)``) and are written unchanged, stamped with
their receive time.

The bag is written in place (:class:`~vbn_common.bags.BagWriter` with
``atomic=False``). Stopping -- by :meth:`Recorder.stop` from a SIGINT/SIGTERM
handler, or when the duration is over -- first takes every message already
delivered to the process, then closes the bag, so that the bag is valid and
holds everything received.
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Any

from rclpy.node import Node

from vbn_common.bags import TYPESTORE, BagWriter, normalize_msgtype
from vbn_common.errors import VbnCommonError
from vbn_common.ros_tools.msgtypes import (
    bag_qos_from_profile,
    import_message_class,
    subscription_qos_for,
    topic_types,
)

__all__ = ['Recorder', 'find_msgdef']

_LOG = logging.getLogger(__name__)


def find_msgdef(msgtype: str) -> str | None:
    """Return the ``.msg`` text of a type installed here but unknown to rosbags, if found."""
    package, kind, name = normalize_msgtype(msgtype).split('/')
    try:
        from ament_index_python.packages import get_package_share_directory
        share = get_package_share_directory(package)
    except Exception:  # noqa: BLE001 - package not in the ament index
        return None
    from pathlib import Path
    path = Path(share) / kind / f'{name}.msg'
    return path.read_text() if path.is_file() else None


class Recorder:
    """Subscribes to topics and writes what arrives into a bag.

    Args:
        node: The node that owns the subscriptions.
        writer: An open :class:`BagWriter` (in-place mode).
        topics: Topic names to record.
        announce: Called with a line of text for each topic subscribed.
        stop_event: Set it to stop :meth:`spin` (e.g. from a signal handler).
        bag_names: The name each topic gets in the bag, by the topic's name (default:
            its own; a node in a namespace records ``/robot1/odom`` as ``/odom``).
    """

    def __init__(self, node: Node, writer: BagWriter, topics: list[str],
                 announce: Any = print, stop_event: threading.Event | None = None,
                 bag_names: dict[str, str] | None = None) -> None:
        self.node = node
        self.writer = writer
        self.bag_names = dict(bag_names or {})
        self.pending = list(dict.fromkeys(topics))
        self.announce = announce
        self.subscriptions: dict[str, Any] = {}
        self.counts: dict[str, int] = {}
        self._stop = stop_event or threading.Event()
        self._unplayable: set[str] = set()

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return sum(self.counts.values())

    def stop(self) -> None:
        """Ask :meth:`spin` to finish (safe from a signal handler)."""
        self._stop.set()

    def subscribe_new_topics(self) -> None:
        """Subscribe every pending topic that now has a publisher in the graph."""
        if not self.pending:
            return
        graph = topic_types(self.node)
        for topic in list(self.pending):
            types = graph.get(topic)
            offered = self.node.get_publishers_info_by_topic(topic)
            if not types or not offered:
                continue
            self.pending.remove(topic)
            if len(types) > 1:
                _LOG.warning('not recording %s: it has several types (%s)', topic,
                             ', '.join(types))
                continue
            self._subscribe(topic, types[0], [info.qos_profile for info in offered])

    def _subscribe(self, topic: str, msgtype: str, offered: list[Any]) -> None:
        cls = import_message_class(msgtype)
        if cls is None:
            _LOG.warning('not recording %s: message type %s has no Python package here',
                         topic, msgtype)
            return
        msgdef = None
        if normalize_msgtype(msgtype) not in TYPESTORE.fielddefs:
            msgdef = find_msgdef(msgtype)
            if msgdef is None:
                _LOG.warning('not recording %s: no definition of %s found', topic, msgtype)
                return
        try:
            connection = self.writer.add_topic(
                self.bag_names.get(topic, topic), msgtype,
                [bag_qos_from_profile(q) for q in offered], msgdef=msgdef)
        except VbnCommonError as error:
            _LOG.warning('not recording %s: %s', topic, error)
            return
        self.counts[topic] = 0

        def on_message(raw: bytes, topic: str = topic, connection: Any = connection) -> None:
            if not self.writer.is_open:   # closed by its owner: what comes late is dropped
                return
            self.writer.write_raw(connection, time.time_ns(), raw)
            self.counts[topic] += 1
            if self.counts[topic] == 1:
                self.announce(f'first message on {topic}')

        self.subscriptions[topic] = self.node.create_subscription(
            cls, topic, on_message, subscription_qos_for(offered), raw=True)
        self.announce(f'recording {topic} [{msgtype}]')

    def spin(self, executor: Any, duration_s: float | None = None) -> None:
        """Record until :meth:`stop` or ``duration_s`` seconds, then drain what arrived."""
        start = time.monotonic()
        next_graph_check = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if duration_s is not None and now - start >= duration_s:
                break
            if now >= next_graph_check:
                self.subscribe_new_topics()
                next_graph_check = now + 0.1
            executor.spin_once(timeout_sec=0.05)
        self.drain(executor)

    def drain(self, executor: Any, quiet_s: float = 0.2, max_s: float = 2.0) -> None:
        """Take messages already delivered, until none comes for ``quiet_s`` (max ``max_s``)."""
        last_count, last_change = self.message_count, time.monotonic()
        give_up = last_change + max_s
        while time.monotonic() - last_change < quiet_s and time.monotonic() < give_up:
            executor.spin_once(timeout_sec=0.02)
            if self.message_count != last_count:
                last_count, last_change = self.message_count, time.monotonic()
