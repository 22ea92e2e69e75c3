"""/tf and /tf_static over real DDS: the workspace's tf2_msgs, bag playback and the broadcaster.

``tf2_msgs`` is built by ``make setup`` from its Jazzy definitions (``ros2_ws/src/tf2_msgs``);
these tests show that what it generates interoperates: the type hash is the one a full
ROS 2 Jazzy install computes, transforms played from the sample bags arrive in another
process as ``map -> base_link``, a play-to-record round trip keeps them byte for byte, and
the transform broadcaster's messages reach a separate ``vbn echo``.
"""
from __future__ import annotations

import math
from pathlib import Path
import re

import numpy as np
from paths import REPO
import pytest
import yaml

from vbn_common.bags import deserialize, open_bag
from vbn_common.geometry.transforms import StampedTransform

pytestmark = pytest.mark.integration

BAGS = REPO / 'bags'
VBN = 'vbn'
WAIT = 120.0  # generous bound for discovery on a loaded 2-core machine


def raw_messages(path: Path, topics: list[str]) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {t: [] for t in topics}
    with open_bag(path) as reader:
        assert not reader.warnings, reader.warnings
        for topic, _msgtype, _stamp, raw in reader.messages(topics=topics):
            out[topic].append(raw)
    return out


def test_room_run_tf_round_trip_is_byte_exact(tmp_path: Path, start_process) -> None:
    topics = ['/tf', '/tf_static', '/odom']
    out = tmp_path / 'recorded'
    record = start_process([VBN, 'record', '--topics', *topics, '--out', str(out)],
                           name='record')
    record.wait_for_output('recording into', timeout=WAIT)
    play = start_process([VBN, 'play', str(BAGS / 'room_run'), '--rate', '4', '--topics',
                          *topics, '--wait-for-subscribers', '--wait-timeout', str(WAIT)],
                         name='play')
    assert play.wait(timeout=3 * WAIT) == 0, play.output
    assert 'skipping' not in play.output
    assert record.stop() == 0, record.output
    original = raw_messages(BAGS / 'room_run', topics)
    got = raw_messages(out, topics)
    assert [len(got[t]) for t in topics] == [2193, 1, 2193]
    for topic in topics:
        assert got[topic] == original[topic], topic  # every message, byte for byte, in order
    with open_bag(out) as reader:
        static_qos = reader.topics['/tf_static'].qos_profiles[0]
        assert static_qos.durability.name == 'TRANSIENT_LOCAL'


def test_node_receives_map_to_base_link_from_the_exploration_bag(ros_node, start_process
                                                                 ) -> None:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from tf2_msgs.msg import TFMessage

    dynamic: list = []
    static: list = []
    node = ros_node.node
    node.create_subscription(TFMessage, '/tf', lambda m: dynamic.extend(m.transforms),
                             QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    node.create_subscription(TFMessage, '/tf_static', lambda m: static.extend(m.transforms),
                             QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    play = start_process([VBN, 'play', str(BAGS / 'room_exploration'), '--rate', '20',
                          '--topics', '/tf', '/tf_static', '--wait-for-subscribers',
                          '--wait-timeout', str(WAIT)], name='play')
    assert ros_node.spin_until(lambda: len(dynamic) >= 200 and static, timeout=2 * WAIT), \
        (len(dynamic), len(static), play.output)
    assert play.wait(timeout=WAIT) == 0, play.output

    truth = []
    with open_bag(BAGS / 'room_exploration') as reader:
        for _t, msgtype, _s, raw in reader.messages(topics=['/ground_truth/pose']):
            truth.append(deserialize(raw, msgtype))
    assert len(dynamic) == len(truth) == 200
    for tf, pose in zip(dynamic, truth, strict=True):
        assert (tf.header.frame_id, tf.child_frame_id) == ('map', 'base_link')
        assert (tf.header.stamp.sec, tf.header.stamp.nanosec) == (
            pose.header.stamp.sec, pose.header.stamp.nanosec)
        assert tf.transform.translation.x == pytest.approx(pose.pose.position.x, abs=1e-12)
        assert tf.transform.translation.y == pytest.approx(pose.pose.position.y, abs=1e-12)
        assert tf.transform.rotation.z == pytest.approx(pose.pose.orientation.z, abs=1e-12)
    assert [(t.header.frame_id, t.child_frame_id) for t in static] == [('base_link', 'camera')]


def test_broadcaster_reaches_another_process(ros_node, start_process) -> None:
    from vbn_common.ros_tools.tf_broadcast import TransformBroadcaster

    node = ros_node.node
    static = TransformBroadcaster(node, static=True)
    static.send(StampedTransform.planar(5 * 10**9, 'base_link', 'camera', 0.1, 0.0, 0.0))
    static.send(StampedTransform.planar(5 * 10**9, 'base_link', 'laser', 0.2, 0.0, math.pi))
    # Latched: an echo that starts after the broadcast still gets both frames in one message.
    echo_static = start_process([VBN, 'echo', '/tf_static', '--once', '--timeout', str(WAIT)],
                                name='echo-static')
    assert ros_node.spin_until(lambda: echo_static.popen.poll() is not None, timeout=WAIT)
    assert echo_static.wait(timeout=10) == 0, echo_static.output
    frames = [t['child_frame_id']
              for t in yaml.safe_load(echo_static.output.split('---')[0])['transforms']]
    assert frames == ['camera', 'laser']

    dynamic = TransformBroadcaster(node)
    echo = start_process([VBN, 'echo', '/tf', '--once', '--timeout', str(WAIT)], name='echo')
    transform = StampedTransform.planar(7 * 10**9 + 5, 'map', 'odom', 1.5, -2.0, 0.25)
    # /tf is volatile: publish until the echo has matched and printed one message.
    assert ros_node.spin_until(
        lambda: dynamic.send(transform) or echo.popen.poll() is not None, timeout=WAIT)
    assert echo.wait(timeout=10) == 0, echo.output
    msg = yaml.safe_load(echo.output.split('---')[0])['transforms'][0]
    assert (msg['header']['frame_id'], msg['child_frame_id']) == ('map', 'odom')
    assert (msg['header']['stamp']['sec'], msg['header']['stamp']['nanosec']) == (7, 5)
    got = np.array([msg['transform']['translation'][k] for k in 'xyz'])
    np.testing.assert_allclose(got, [1.5, -2.0, 0.0])
    assert 2 * math.atan2(msg['transform']['rotation']['z'],
                          msg['transform']['rotation']['w']) == pytest.approx(0.25)
    assert re.search(r'frame_id: map', echo.output)
