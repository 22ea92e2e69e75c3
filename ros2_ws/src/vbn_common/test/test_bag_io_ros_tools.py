"""Tests of the bag tools' rclpy glue that need no DDS: YAML echo, type lookup, QoS, timing."""
from __future__ import annotations

import time

import pytest
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
import yaml

from vbn_common.bags import default_qos
from vbn_common.errors import VbnCommonError
from vbn_common.ros_tools.msgtypes import (
    DEFAULT_DEPTH,
    bag_qos_from_profile,
    import_message_class,
    profile_from_bag_qos,
    subscription_qos_for,
)
from vbn_common.ros_tools.play import PlayStats, sleep_until
from vbn_common.ros_tools.yaml_echo import message_to_dict, message_to_yaml


def test_import_message_class() -> None:
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import Image
    assert import_message_class('sensor_msgs/msg/Image') is Image
    assert import_message_class('geometry_msgs/PoseStamped') is PoseStamped
    from tf2_msgs.msg import TFMessage  # built in the workspace (ros2_ws/src/tf2_msgs)
    assert import_message_class('tf2_msgs/msg/TFMessage') is TFMessage
    assert import_message_class('my_msgs/msg/Thing') is None  # no such package here
    assert import_message_class('sensor_msgs/msg/NoSuchType') is None
    with pytest.raises(VbnCommonError):
        import_message_class('Image')


def test_yaml_matches_ros2_topic_echo_layout() -> None:
    from geometry_msgs.msg import PoseStamped
    msg = PoseStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 500
    msg.header.frame_id = 'map'
    msg.pose.position.x = 1.5
    msg.pose.orientation.w = 1.0
    assert message_to_yaml(msg) == (
        'header:\n  stamp:\n    sec: 12\n    nanosec: 500\n  frame_id: map\n'
        'pose:\n  position:\n    x: 1.5\n    y: 0.0\n    z: 0.0\n'
        '  orientation:\n    x: 0.0\n    y: 0.0\n    z: 0.0\n    w: 1.0\n')


def test_yaml_truncates_arrays_like_ros2_topic_echo() -> None:
    from sensor_msgs.msg import Image
    msg = Image(height=2, width=200, encoding='mono8', step=200)
    values = [i % 256 for i in range(400)]
    msg.data = bytes(values)
    full = message_to_dict(msg, truncate_length=None)
    assert full['data'] == values
    cut = yaml.safe_load(message_to_yaml(msg))
    assert cut['data'] == list(range(128)) + ['...']
    assert cut['encoding'] == 'mono8' and cut['width'] == 200
    no_arr = yaml.safe_load(message_to_yaml(msg, no_arr=True))
    assert no_arr['data'] == '<sequence type: uint8, length: 400>'


def test_yaml_of_fixed_arrays_nested_sequences_and_strings() -> None:
    from nav_msgs.msg import Odometry
    from visualization_msgs.msg import Marker, MarkerArray
    odom = Odometry()
    odom.pose.covariance[0] = 0.25
    data = yaml.safe_load(message_to_yaml(odom))
    assert data['pose']['covariance'][0] == 0.25 and len(data['pose']['covariance']) == 36
    assert yaml.safe_load(message_to_yaml(odom, no_arr=True))['pose']['covariance'] == \
        '<array type: double[36]>'
    markers = MarkerArray(markers=[Marker(id=3, ns='x' * 200), Marker(id=4)])
    data = yaml.safe_load(message_to_yaml(markers))
    assert [m['id'] for m in data['markers']] == [3, 4]
    assert data['markers'][0]['ns'] == 'x' * 128 + '...'
    assert yaml.safe_load(message_to_yaml(markers, no_str=True))['markers'][0]['ns'] == \
        '<string length: 200>'


def test_bag_qos_round_trips_through_rclpy_profiles() -> None:
    offered = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=7,
                         reliability=ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         deadline=Duration(seconds=2, nanoseconds=5))
    qos = bag_qos_from_profile(offered)
    assert (qos.depth, qos.reliability.name, qos.durability.name) == \
        (7, 'BEST_EFFORT', 'TRANSIENT_LOCAL')
    assert (qos.deadline.sec, qos.deadline.nsec) == (2, 5)
    back = profile_from_bag_qos([qos])
    assert back.depth == 7 and back.reliability == ReliabilityPolicy.BEST_EFFORT
    assert back.durability == DurabilityPolicy.TRANSIENT_LOCAL


def test_a_remote_offer_without_history_is_recorded_keep_last_10() -> None:
    # What get_publishers_info_by_topic reports for another process's publisher.
    remote = QoSProfile(history=HistoryPolicy.UNKNOWN, depth=0,
                        reliability=ReliabilityPolicy.RELIABLE)
    qos = bag_qos_from_profile(remote)
    assert (qos.history.name, qos.depth, qos.reliability.name) == ('KEEP_LAST', 10, 'RELIABLE')
    keep_all = bag_qos_from_profile(QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=0))
    assert keep_all.history.name == 'KEEP_ALL'


def test_play_qos_defaults_and_mixed_offers() -> None:
    none = profile_from_bag_qos([])
    assert none.reliability == ReliabilityPolicy.RELIABLE
    assert none.durability == DurabilityPolicy.VOLATILE and none.depth == DEFAULT_DEPTH
    mixed = profile_from_bag_qos([default_qos(), default_qos(reliability='best_effort')])
    assert mixed.reliability == ReliabilityPolicy.BEST_EFFORT
    discovered = default_qos()._replace(depth=0)  # DDS discovery carries no depth
    assert profile_from_bag_qos([discovered]).depth == DEFAULT_DEPTH


def test_subscription_adapts_to_offers() -> None:
    reliable = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
    best = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    sub = subscription_qos_for([reliable])
    assert sub.reliability == ReliabilityPolicy.RELIABLE
    assert sub.durability == DurabilityPolicy.TRANSIENT_LOCAL
    sub = subscription_qos_for([reliable, best])
    assert sub.reliability == ReliabilityPolicy.BEST_EFFORT
    assert sub.durability == DurabilityPolicy.VOLATILE


def test_sleep_until_never_returns_early() -> None:
    for delay in (0.0, 0.0005, 0.003, 0.012):
        deadline = time.perf_counter() + delay
        sleep_until(deadline)
        assert time.perf_counter() >= deadline


def test_jitter_summary() -> None:
    stats = PlayStats(published=4, lateness_s=[0.001, 0.0, 0.002, 0.0],
                      interval_error_s=[-0.001, 0.002, -0.002])
    summary = stats.jitter_summary()
    assert summary['jitter_max_ms'] == pytest.approx(2.0)
    assert summary['jitter_p50_ms'] == pytest.approx(2.0)
    assert summary['lateness_max_ms'] == pytest.approx(2.0)
    assert PlayStats().jitter_summary() == {}


class FakeTime:
    """A clock whose sleeps wake up ``late`` seconds after they should."""

    def __init__(self, late: float) -> None:
        self.now = 0.0
        self.late = late
        self.spins = 0

    def clock(self) -> float:
        self.spins += 1
        self.now += 1e-6  # every clock read costs a microsecond of spinning
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds + self.late


def test_deadline_sleeper_adapts_its_margin_to_late_wakeups() -> None:
    from vbn_common.ros_tools.play import DeadlineSleeper
    fake = FakeTime(late=0.002)
    sleeper = DeadlineSleeper(clock=fake.clock, sleep=fake.sleep)
    lateness = []
    for i in range(1, 40):
        deadline = i / 30
        sleeper.sleep_until(deadline)
        lateness.append(fake.now - deadline)
    assert min(lateness) >= 0.0
    assert sleeper.margin == pytest.approx(0.003, rel=0.01)  # 1.5 x the 2 ms wake-up delay
    assert max(lateness[5:]) < 1e-5  # once adapted, on time to the microsecond
    fake = FakeTime(late=0.0001)  # an idle machine: the margin decays to its minimum
    sleeper = DeadlineSleeper(clock=fake.clock, sleep=fake.sleep)
    for i in range(1, 200):
        sleeper.sleep_until(i / 30)
    assert sleeper.margin == pytest.approx(0.0005)
