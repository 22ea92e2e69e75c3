"""Helpers of the localizer node's tests over DDS: what it hears, what it publishes.

:class:`Publisher` sends frames of a sample run (and bad input) from the test's node,
:class:`Listener` collects what the localizer publishes, both optionally in a namespace
(``ns='/robot1'``); :func:`read_run` reads a run bag by stamp; :func:`start_localizer`
starts the executable and waits until it is ready.
"""
from __future__ import annotations

import math
from pathlib import Path
import time

import numpy as np
from paths import REPO

from vbn_common.bags import open_bag
from vbn_common.geometry.frames import quaternion_yaw
from vbn_common.images import decode_image

ROOT = REPO


BAGS = ROOT / 'bags'


WAIT = 120.0


IMAGE_TOPIC = '/camera/image_raw/compressed'


def read_run(name: str) -> dict:
    """Image stamps, ground truth and odometry of a run bag, by stamp."""
    truth, odom, images, infos = {}, {}, [], []
    with open_bag(BAGS / name) as reader:
        for topic, msgtype, stamp, raw in reader.messages():
            if topic == '/ground_truth/pose':
                msg = reader.deserialize(raw, msgtype)
                q = msg.pose.orientation
                truth[stamp] = (msg.pose.position.x, msg.pose.position.y,
                                float(quaternion_yaw(np.array([q.x, q.y, q.z, q.w]))))
            elif topic == '/odom':
                msg = reader.deserialize(raw, msgtype)
                q = msg.pose.pose.orientation
                odom[stamp] = (msg.pose.pose.position.x, msg.pose.pose.position.y,
                               float(quaternion_yaw(np.array([q.x, q.y, q.z, q.w]))))
            elif topic == IMAGE_TOPIC:
                images.append((stamp, reader.deserialize(raw, msgtype)))
            elif topic == '/camera/camera_info':
                infos.append(reader.deserialize(raw, msgtype))
    return {'truth': truth, 'odom': odom, 'images': images, 'info': infos[0]}


def stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class Listener:
    """Everything the localizer publishes, as the test node hears it."""

    def __init__(self, ros_node, ns: str = '') -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
        from std_msgs.msg import Int32
        from tf2_msgs.msg import TFMessage
        from visualization_msgs.msg import MarkerArray

        from vbn_common.ros_tools.markers import LATCHED_QOS
        from vbn_common.ros_tools.tf_broadcast import DYNAMIC_QOS

        self.ros = ros_node
        node = ros_node.node
        self.poses: list = []
        self.poses_cov: list = []
        self.regions: list[int] = []
        self.tf: list = []
        self.diagnostics: list = []
        self.markers: list = []
        node.create_subscription(PoseStamped, ns + '/localizer/pose', self.poses.append, 100)
        node.create_subscription(PoseWithCovarianceStamped, ns + '/localizer/pose_with_covariance',
                                 self.poses_cov.append, 100)
        self.region_times: list[float] = []   # monotonic receive time of each region
        node.create_subscription(Int32, ns + '/localizer/region', self._on_region, 100)
        node.create_subscription(TFMessage, ns + '/tf', self._on_tf, DYNAMIC_QOS)
        node.create_subscription(DiagnosticArray, ns + '/diagnostics', self.diagnostics.append, 10)
        node.create_subscription(MarkerArray, ns + '/localizer/regions', self.markers.append,
                                 LATCHED_QOS)

    def _on_region(self, msg) -> None:
        self.regions.append(msg.data)
        self.region_times.append(time.monotonic())

    def _on_tf(self, msg) -> None:
        self.tf.extend(t for t in msg.transforms if t.header.frame_id == 'map')

    def status(self) -> dict[str, str]:
        """The newest localizer diagnostics as a dict."""
        status = [s for s in self.diagnostics[-1].status if s.name == 'localizer'][0]
        return {kv.key: kv.value for kv in status.values}

    def wait_settled(self, timeout: float = 60.0) -> dict[str, str]:
        """Wait until the node has handled every frame it received and published nothing
        for a whole diagnostics period (what follows the end of a playback).

        Not "until every pose arrived here": the pose topic keeps the last 10, so a
        listener that falls behind at 100 Hz loses some, by design.
        """
        def handled(s: dict[str, str]) -> bool:
            return int(s['frames_processed']) + int(s['frames_dropped']) >= \
                int(s['frames_received'])
        seen: dict[int, str] = {}     # diagnostics received -> poses published then

        def quiet(s: dict[str, str]) -> bool:
            n = len(self.diagnostics)
            seen.setdefault(n, s['poses_published'])
            return handled(s) and seen.get(n - 1) == s['poses_published']
        return self.wait_status(quiet, timeout)

    def wait_status(self, predicate, timeout: float = 30.0) -> dict[str, str]:
        count = len(self.diagnostics)
        assert self.ros.spin_until(lambda: len(self.diagnostics) > count and
                                   predicate(self.status()), timeout), \
            self.status() if self.diagnostics else 'no diagnostics'
        return self.status()


def start_localizer(start_process, db: Path, *params: str, ros_args: tuple[str, ...] = ()):
    """Start ``localizer`` with ``-p`` for each of ``params`` and wait until it is ready."""
    args = [a for p in params for a in ('-p', p)]
    node = start_process(['localizer', '--ros-args', '-p', f'db:={db}', *args, *ros_args],
                         name='localizer')
    node.wait_for_output('localizer ready', timeout=WAIT)
    return node


class Publisher:
    """Bad and good input for the localizer, from the test node."""

    def __init__(self, ros_node, run: dict, ns: str = '') -> None:
        from geometry_msgs.msg import PoseWithCovarianceStamped
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import CameraInfo, CompressedImage, Image

        self.ros, self.run = ros_node, run
        node = ros_node.node
        self.image = node.create_publisher(Image, ns + '/camera/image_raw', 10)
        self.compressed = node.create_publisher(CompressedImage, ns + IMAGE_TOPIC, 10)
        self.info = node.create_publisher(CameraInfo, ns + '/camera/camera_info', 10)
        self.odom = node.create_publisher(Odometry, ns + '/odom', 50)
        self.initial = node.create_publisher(PoseWithCovarianceStamped, ns + '/initialpose', 10)
        self.types = {'Image': Image, 'CompressedImage': CompressedImage,
                      'CameraInfo': CameraInfo, 'Odometry': Odometry}
        publishers = (self.image, self.compressed, self.info, self.odom, self.initial)
        assert ros_node.spin_until(
            lambda: all(p.get_subscription_count() > 0 for p in publishers), timeout=WAIT)

    def frame(self, index: int, stamp: int):
        """Bag image ``index`` as a CompressedImage with another stamp."""
        source = self.run['images'][index % len(self.run['images'])][1]
        msg = self.types['CompressedImage'](format=source.format, data=bytes(source.data))
        msg.header.frame_id = 'camera'
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
        return msg

    def raw(self, stamp: int, encoding: str = 'mono8', width: int = 1024, height: int = 256,
            step: int | None = None, data: bytes | None = None, index: int = 0):
        msg = self.types['Image'](encoding=encoding, width=width, height=height,
                                  step=width if step is None else step)
        if data is None:
            gray = decode_image(self.run['images'][index][1])
            data = gray.tobytes() if gray.shape == (height, width) else bytes(width * height)
        msg.data = data
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
        return msg

    def camera_info(self, width: int = 1024, height: int = 256):
        info = self.run['info']
        msg = self.types['CameraInfo'](width=width, height=height,
                                       distortion_model=info.distortion_model,
                                       d=[float(v) for v in info.d])
        k = np.array(info.k, float)
        if width != info.width:
            k[[0, 2]] = width / (2 * math.pi), width / 2
        msg.k = [float(v) for v in k]
        return msg

    def odometry(self, stamp: int, x: float, y: float = 0.0):
        msg = self.types['Odometry']()
        msg.header.frame_id, msg.child_frame_id = 'odom', 'base_link'
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
        msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
        msg.pose.pose.orientation.w = 1.0
        return msg


def rss_kib(pid: int) -> int:
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1])
    raise AssertionError('no VmRSS')
