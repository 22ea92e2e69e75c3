"""Publish a bag's messages on their recorded topics, timing and QoS (``vbn play``).

Messages go out serialized, exactly as recorded (``Publisher.publish(bytes)``
publishes raw CDR in rclpy 7 / Jazzy), so a play-to-record round trip reproduces
them byte for byte. Each topic is published with the QoS recorded in the bag
(:func:`~visibility_builder.ros_tools.msgtypes.profile_from_bag_qos`); a topic whose
message type has no Python package here (``/tf``: no ``tf2_msgs`` in the
pip-installed ROS 2) is skipped with one warning.

Timing: message ``i`` is due at ``wall_start + (t_i - t_start) / rate``. The
player sleeps until about 1.5 ms before the deadline and spin-waits the rest on
``time.perf_counter`` (OS sleeps overshoot by up to a millisecond or more), while a
reader thread decompresses the bag ahead into a bounded queue. The achieved
timing (publish-time lateness and the error of every inter-message interval) is
returned in :class:`PlayStats`; ``vbn play --stats`` prints it.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
import logging
import queue
import threading
import time
from typing import Any

import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from visibility_builder.bag_io import BagReader
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.ros_tools.msgtypes import import_message_class, profile_from_bag_qos

__all__ = ['PlayOptions', 'PlayStats', 'Player', 'sleep_until']

_LOG = logging.getLogger(__name__)

_SPIN_MARGIN_S = 0.0015  # sleep until this long before a deadline, then spin-wait
_QUEUE_MESSAGES = 256
_END = object()


@dataclass(frozen=True)
class PlayOptions:
    """How to play a bag.

    Attributes:
        rate: Playback speed factor (2.0 plays twice as fast).
        loop: Start again at the end, until interrupted.
        clock_hz: Publish ``/clock`` (``rosgraph_msgs/Clock``) at this rate in Hz,
            for nodes with ``use_sim_time``; None: no clock.
        topics: Play only these topics (None: all).
        start_offset_s: Skip the first seconds of the bag.
        wait_for_subscribers: Before starting, wait until every publisher has at
            least one matched subscription.
        wait_timeout_s: Give up waiting for subscribers after this long (None: wait).
        ack_timeout_s: At the end, wait this long for reliable subscribers to
            acknowledge everything published.
    """

    rate: float = 1.0
    loop: bool = False
    clock_hz: float | None = None
    topics: tuple[str, ...] | None = None
    start_offset_s: float = 0.0
    wait_for_subscribers: bool = False
    wait_timeout_s: float | None = None
    ack_timeout_s: float = 10.0


@dataclass
class PlayStats:
    """What was published and how precisely.

    Attributes:
        published: Messages published.
        skipped_topics: Topics not played (no message class here).
        lateness_s: Publish time minus due time, per message (seconds).
        interval_error_s: Achieved minus due inter-message interval, per
            consecutive pair (seconds): the inter-message jitter.
        clock_published: ``/clock`` messages published.
    """

    published: int = 0
    skipped_topics: list[str] = field(default_factory=list)
    lateness_s: list[float] = field(default_factory=list)
    interval_error_s: list[float] = field(default_factory=list)
    clock_published: int = 0

    def jitter_summary(self) -> dict[str, float]:
        """p50, p95 and max of the absolute inter-message jitter and lateness, in ms."""
        out: dict[str, float] = {}
        for name, values in (('jitter', self.interval_error_s), ('lateness', self.lateness_s)):
            if values:
                arr = np.abs(np.asarray(values)) * 1e3
                out[f'{name}_p50_ms'] = float(np.percentile(arr, 50))
                out[f'{name}_p95_ms'] = float(np.percentile(arr, 95))
                out[f'{name}_max_ms'] = float(arr.max())
        return out


def sleep_until(deadline: float) -> None:
    """Return at ``deadline`` (a ``time.perf_counter()`` value), sub-millisecond precise."""
    while True:
        remaining = deadline - time.perf_counter()
        if remaining <= 0.0:
            return
        if remaining > _SPIN_MARGIN_S:
            time.sleep(remaining - _SPIN_MARGIN_S)


class Player:
    """Publishes one bag through an rclpy node.

    Args:
        node: The node that owns the publishers.
        reader: The open bag.
        options: Playback options.

    Raises:
        VisibilityBuilderError: Bad options, or nothing playable in the bag.
    """

    def __init__(self, node: Node, reader: BagReader, options: PlayOptions) -> None:
        if not options.rate > 0:
            raise VisibilityBuilderError(f'--rate must be positive, got {options.rate}')
        if options.start_offset_s < 0:
            raise VisibilityBuilderError(
                f'--start-offset must not be negative, got {options.start_offset_s}')
        if options.clock_hz is not None and not options.clock_hz > 0:
            raise VisibilityBuilderError(f'--clock rate must be positive, got {options.clock_hz}')
        self.node = node
        self.reader = reader
        self.options = options
        self.stats = PlayStats()
        self._stop = threading.Event()
        self.publishers: dict[str, Any] = {}
        wanted = list(reader.topics) if options.topics is None else list(options.topics)
        missing = [t for t in wanted if t not in reader.topics]
        if missing:
            _LOG.warning('bag %s has no topic(s) %s', reader.path, ', '.join(missing))
        by_type: dict[str, list[str]] = {}
        for topic in wanted:
            if topic not in reader.topics:
                continue
            info = reader.topics[topic]
            cls = import_message_class(info.msgtype)
            if cls is None:
                by_type.setdefault(info.msgtype, []).append(topic)
                continue
            qos = profile_from_bag_qos(info.qos_profiles)
            self.publishers[topic] = node.create_publisher(cls, topic, qos)
        for msgtype, topics in by_type.items():
            _LOG.warning('skipping %s: message type %s has no Python package here',
                         ', '.join(topics), msgtype)
            self.stats.skipped_topics.extend(topics)
        if not self.publishers:
            raise VisibilityBuilderError(f'nothing to play in bag {reader.path}')
        self.clock_publisher = None
        if options.clock_hz is not None:
            from rosgraph_msgs.msg import Clock
            self._clock_cls = Clock
            self.clock_publisher = node.create_publisher(Clock, '/clock', QoSProfile(depth=1))

    def stop(self) -> None:
        """Ask a running :meth:`play` to return (thread-safe)."""
        self._stop.set()

    # -- waiting -------------------------------------------------------------------
    def wait_for_subscribers(self, executor: Any) -> bool:
        """Spin until every publisher has a matched subscription; False on timeout/stop."""
        timeout = self.options.wait_timeout_s
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._stop.is_set():
            waiting = [t for t, p in self.publishers.items() if p.get_subscription_count() < 1]
            if not waiting:
                return True
            if deadline is not None and time.monotonic() > deadline:
                return False
            executor.spin_once(timeout_sec=0.05)
        return False

    def unmatched_topics(self) -> list[str]:
        """Topics whose publisher has no matched subscription yet."""
        return [t for t, p in self.publishers.items() if p.get_subscription_count() < 1]

    # -- playing -------------------------------------------------------------------
    def _messages(self) -> Iterator[tuple[str, int, bytes]]:
        assert self.reader.start_ns is not None
        start = self.reader.start_ns + int(self.options.start_offset_s * 1e9)
        for topic, _msgtype, stamp, raw in self.reader.messages(
                topics=list(self.publishers), start_ns=start):
            yield topic, stamp, raw

    def _put(self, out: queue.Queue, item: object) -> bool:
        """Queue ``item`` unless asked to stop; return False when stopping."""
        while not self._stop.is_set():
            try:
                out.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _prefetch(self, out: queue.Queue) -> None:
        try:
            while True:
                for item in self._messages():
                    if not self._put(out, item):
                        return
                if not self._put(out, None):  # end of one pass
                    return
                if not self.options.loop:
                    break
        except Exception as error:  # noqa: BLE001 - reported in the main thread
            self._put(out, error)
        self._put(out, _END)

    def play(self) -> PlayStats:
        """Publish the bag (every pass when looping); return the statistics."""
        if self.reader.start_ns is None:
            _LOG.warning('bag %s has no messages to play', self.reader.path)
            return self.stats
        feed: queue.Queue = queue.Queue(maxsize=_QUEUE_MESSAGES)
        thread = threading.Thread(target=self._prefetch, args=(feed,), daemon=True)
        thread.start()
        rate = self.options.rate
        clock_period = None if self.options.clock_hz is None else 1.0 / self.options.clock_hz
        item: object = None
        try:
            while not self._stop.is_set():
                wall0 = bag0 = None
                prev: tuple[float, float] | None = None  # (due, achieved) of the last message
                next_clock = None
                while not self._stop.is_set():
                    item = feed.get()
                    if item is None or item is _END:
                        break
                    if isinstance(item, Exception):
                        raise VisibilityBuilderError(f'cannot read bag: {item}') from item
                    topic, stamp, raw = item
                    if wall0 is None:
                        wall0, bag0 = time.perf_counter(), stamp
                        next_clock = wall0
                    due = wall0 + (stamp - bag0) / 1e9 / rate
                    if clock_period is not None:
                        while next_clock <= due and not self._stop.is_set():
                            sleep_until(next_clock)
                            self._publish_clock(bag0 + int((next_clock - wall0) * rate * 1e9))
                            next_clock += clock_period
                    sleep_until(due)
                    self.publishers[topic].publish(raw)
                    achieved = time.perf_counter()
                    self.stats.published += 1
                    self.stats.lateness_s.append(achieved - due)
                    if prev is not None:
                        self.stats.interval_error_s.append((achieved - prev[1]) - (due - prev[0]))
                    prev = (due, achieved)
                if item is _END or not self.options.loop:
                    break
        finally:
            self._stop.set()
            thread.join(timeout=5.0)
        self._wait_for_acks()
        return self.stats

    def _publish_clock(self, stamp_ns: int) -> None:
        assert self.clock_publisher is not None
        msg = self._clock_cls()
        msg.clock.sec, msg.clock.nanosec = divmod(stamp_ns, 10**9)
        self.clock_publisher.publish(msg)
        self.stats.clock_published += 1

    def _wait_for_acks(self) -> None:
        timeout = Duration(seconds=self.options.ack_timeout_s)
        for topic, publisher in self.publishers.items():
            if publisher.qos_profile.reliability != ReliabilityPolicy.RELIABLE:
                continue
            if publisher.get_subscription_count() and not publisher.wait_for_all_acked(timeout):
                _LOG.warning('not every subscriber of %s acknowledged all messages', topic)
