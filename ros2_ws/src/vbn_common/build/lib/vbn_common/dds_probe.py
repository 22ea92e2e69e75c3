"""A two-process DDS check: an echo node and the client that pings it (ROS glue).

``vbn doctor`` starts ``dds_probe echo`` in a second process and sends it a
``std_msgs/String`` ping with a nonce; the echo node republishes it on the pong
topic. A pong carrying the same nonce proves that a publisher and a subscriber in
two processes exchanged messages over the RMW in both directions.

The echo side is the ``dds_probe`` executable (:mod:`vbn_common.dds_probe_main`); on a
full ROS 2 install it also runs as ``ros2 run vbn_common dds_probe echo``.
"""
from __future__ import annotations

from dataclasses import dataclass
import time

import rclpy
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

__all__ = ['EchoNode', 'PingResult', 'ping']

PING_TOPIC = '/vbn_doctor/ping'
PONG_TOPIC = '/vbn_doctor/pong'
_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class EchoNode(Node):
    """Republish every ping on the pong topic, unchanged."""

    def __init__(self, suffix: str = '') -> None:
        super().__init__('vbn_dds_echo')
        self._pong = self.create_publisher(String, PONG_TOPIC + suffix, _QOS)
        self.create_subscription(String, PING_TOPIC + suffix, self._on_ping, _QOS)

    def _on_ping(self, msg: String) -> None:
        self._pong.publish(msg)


@dataclass(frozen=True)
class PingResult:
    """What one ping over DDS gave.

    Attributes:
        ok: True when the pong with our nonce came back.
        message: the text that went out and came back ('' when it did not).
        discovery_s: seconds until the echo node's endpoints matched ours.
        round_trip_ms: ping to pong time in milliseconds (NaN when not ok).
        detail: a one-line explanation when not ok.
    """

    ok: bool
    message: str
    discovery_s: float
    round_trip_ms: float
    detail: str = ''


def ping(node: Node, text: str, suffix: str = '', timeout_s: float = 30.0,
         executor: Executor | None = None) -> PingResult:
    """Send ``text`` to an echo node and wait for it to come back.

    Waits for matched endpoints (never a fixed sleep), then publishes once per second
    until the pong arrives or ``timeout_s`` passes.

    Args:
        node: a node in an initialised rclpy context.
        text: the payload; should contain a nonce.
        suffix: appended to the ping/pong topic names, to keep concurrent checks apart.
        timeout_s: overall bound in seconds.
        executor: the executor that spins ``node`` (default: rclpy's global one).

    Returns:
        The outcome; never raises for a missing peer.
    """
    def spin_once(timeout_sec: float) -> None:
        if executor is None:
            rclpy.spin_once(node, timeout_sec=timeout_sec)
        else:
            executor.spin_once(timeout_sec=timeout_sec)

    received: list[tuple[float, str]] = []
    pub = node.create_publisher(String, PING_TOPIC + suffix, _QOS)
    sub = node.create_subscription(
        String, PONG_TOPIC + suffix,
        lambda msg: received.append((time.monotonic(), msg.data)), _QOS)
    start = time.monotonic()
    deadline = start + timeout_s
    try:
        while time.monotonic() < deadline and (
                pub.get_subscription_count() == 0 or sub.get_publisher_count() == 0):
            spin_once(0.05)
        discovery_s = time.monotonic() - start
        if pub.get_subscription_count() == 0 or sub.get_publisher_count() == 0:
            return PingResult(False, '', discovery_s, float('nan'),
                              f'no echo node discovered within {timeout_s:.0f} s')
        sent_at = 0.0
        while time.monotonic() < deadline:
            if time.monotonic() - sent_at > 1.0:
                sent_at = time.monotonic()
                pub.publish(String(data=text))
            spin_once(0.02)
            for arrived, data in received:
                if data == text:
                    return PingResult(True, data, discovery_s, (arrived - sent_at) * 1e3)
        return PingResult(False, '', discovery_s, float('nan'),
                          f'echo node matched but no pong within {timeout_s:.0f} s')
    finally:
        node.destroy_subscription(sub)
        node.destroy_publisher(pub)
