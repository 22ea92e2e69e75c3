"""Publish a bag's messages on their recorded topics, timing and QoS (``vbn play``).

Messages go out serialized, exactly as recorded (``Publisher.publish(bytes)``
publishes raw CDR in rclpy 7 / Jazzy), so a play-to-record round trip reproduces
them byte for byte. Each topic is published with the QoS recorded in the bag
(:func:`~vbn_common.ros_tools.msgtypes.profile_from_bag_qos`), so ``/tf_static``
goes out transient-local as recorded (``tf2_msgs`` is built in the workspace). A topic
whose message type has no Python package at all (a custom type the bag carries but
this machine does not) is left out with one warning naming it.

Timing: message ``i`` is due at ``wall_start + (t_i - t_start) / rate``. The
player sleeps until shortly before the deadline and spin-waits the rest on
``time.perf_counter`` (:class:`DeadlineSleeper`: an OS sleep wakes up late by up to
several milliseconds on a busy machine, so the spin margin adapts to the wake-up
latencies observed). The bag is read ahead in the same thread, only in the slack
before a deadline, so that decompressing a chunk never delays a publish. The
achieved timing (publish-time lateness and the error of every inter-message
interval) is returned in :class:`PlayStats`; ``vbn play --stats`` prints it.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
import logging
import threading
import time
from typing import Any

import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from vbn_common.bags import BagReader
from vbn_common.errors import VbnCommonError
from vbn_common.ros_tools.msgtypes import import_message_class, profile_from_bag_qos

__all__ = ['DeadlineSleeper', 'PlayOptions', 'PlayStats', 'Player', 'sleep_until']

_LOG = logging.getLogger(__name__)

_SPIN_MARGIN_S = 0.0015  # sleep until this long before a deadline, then spin-wait
_READ_SLACK_S = 0.010  # read ahead only while the next deadline is further away than this
_READ_AHEAD_MESSAGES = 512
_READ_START_S = 0.5  # read ahead this long before the first message goes out


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


class DeadlineSleeper:
    """Sleep until a ``time.perf_counter()`` deadline, sub-millisecond precise.

    An OS sleep wakes up late by a scheduling latency that depends on the load
    (about 0.1 ms on an idle machine, several milliseconds on a busy one). The
    sleeper sleeps until ``margin`` before the deadline and spin-waits the rest,
    and adapts ``margin`` to the wake-up latencies it observes: it jumps to
    1.5 x a late wake-up and decays by 2 % per sleep, within ``[min_margin,
    max_margin]``. So an idle machine burns little CPU spinning, and a busy one
    still meets its deadlines.

    Args:
        min_margin: Smallest spin margin in seconds.
        max_margin: Largest spin margin in seconds.
        clock: The clock (``time.perf_counter``); injectable for tests.
        sleep: The OS sleep (``time.sleep``); injectable for tests.
    """

    def __init__(self, min_margin: float = 0.0005, max_margin: float = 0.003,
                 clock: Callable[[], float] = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.min_margin = min_margin
        self.max_margin = max_margin
        self.margin = _SPIN_MARGIN_S
        self._clock = clock
        self._sleep = sleep

    def sleep_until(self, deadline: float) -> None:
        """Return at ``deadline``, never before."""
        clock = self._clock
        remaining = deadline - clock()
        if remaining > self.margin:
            wake = deadline - self.margin
            self._sleep(remaining - self.margin)
            late = clock() - wake
            self.margin = min(self.max_margin,
                              max(self.min_margin, 1.5 * late, 0.98 * self.margin))
        while clock() < deadline:
            pass


def sleep_until(deadline: float) -> None:
    """Return at ``deadline`` (a ``time.perf_counter()`` value) with a fixed 1.5 ms spin."""
    DeadlineSleeper(_SPIN_MARGIN_S, _SPIN_MARGIN_S).sleep_until(deadline)


class Player:
    """Publishes one bag through an rclpy node.

    Args:
        node: The node that owns the publishers.
        reader: The open bag.
        options: Playback options.

    Raises:
        VbnCommonError: Bad options, or nothing playable in the bag.
    """

    def __init__(self, node: Node, reader: BagReader, options: PlayOptions) -> None:
        if not options.rate > 0:
            raise VbnCommonError(f'--rate must be positive, got {options.rate}')
        if options.start_offset_s < 0:
            raise VbnCommonError(
                f'--start-offset must not be negative, got {options.start_offset_s}')
        if options.clock_hz is not None and not options.clock_hz > 0:
            raise VbnCommonError(f'--clock rate must be positive, got {options.clock_hz}')
        self.node = node
        self.reader = reader
        self.options = options
        self.stats = PlayStats()
        self._stop = threading.Event()
        self.sleeper = DeadlineSleeper()
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
            raise VbnCommonError(f'nothing to play in bag {reader.path}')
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

    def play(self) -> PlayStats:
        """Publish the bag (every pass when looping); return the statistics."""
        if self.reader.start_ns is None:
            _LOG.warning('bag %s has no messages to play', self.reader.path)
            return self.stats
        try:
            while not self._stop.is_set():
                played = self._play_pass()
                if not self.options.loop or not played:
                    break
        finally:
            self._stop.set()
        self._wait_for_acks()
        return self.stats

    def _play_pass(self) -> int:
        """Publish one pass over the bag; return the number of messages published.

        Reading runs in this thread, in the slack before each deadline: the next
        messages are fetched only while the next one is more than
        ``_READ_SLACK_S`` away, so decompressing a chunk never delays a publish
        (and no second thread competes for the GIL).
        """
        source = self._messages()
        ahead: deque[tuple[str, int, bytes]] = deque()
        exhausted = False

        def fetch(until: float) -> None:
            nonlocal exhausted
            while (not exhausted and len(ahead) < _READ_AHEAD_MESSAGES
                   and time.perf_counter() < until):
                try:
                    ahead.append(next(source))
                except StopIteration:
                    exhausted = True

        fetch(time.perf_counter() + _READ_START_S)
        if not ahead:
            return 0
        rate = self.options.rate
        clock_period = None if self.options.clock_hz is None else 1.0 / self.options.clock_hz
        wall0, bag0 = time.perf_counter(), ahead[0][1]
        next_clock = wall0
        prev: tuple[float, float] | None = None  # (due, achieved) of the last message
        published = 0
        while ahead and not self._stop.is_set():
            topic, stamp, raw = ahead[0]
            due = wall0 + (stamp - bag0) / 1e9 / rate
            if clock_period is not None:
                while next_clock <= due and not self._stop.is_set():
                    fetch(next_clock - _READ_SLACK_S)
                    self.sleeper.sleep_until(next_clock)
                    self._publish_clock(bag0 + int((next_clock - wall0) * rate * 1e9))
                    next_clock += clock_period
            fetch(due - _READ_SLACK_S)
            self.sleeper.sleep_until(due)
            self.publishers[topic].publish(raw)
            achieved = time.perf_counter()
            ahead.popleft()
            published += 1
            self.stats.published += 1
            self.stats.lateness_s.append(achieved - due)
            if prev is not None:
                self.stats.interval_error_s.append((achieved - prev[1]) - (due - prev[0]))
            prev = (due, achieved)
            if not ahead:
                fetch(float('inf'))  # nothing left to publish: read now
        return published

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
