"""Bags of the offline localizer: read a run bag, write and read the pose bag (bag I/O).

A *run bag* holds what the robot saw and did: images (``/camera/image_raw`` or
``/camera/image_raw/compressed``; the raw, lossless topic when a bag has both),
odometry (``/odom``, ``nav_msgs/Odometry``) and, in the samples, the ground truth
(``/ground_truth/pose``, ``geometry_msgs/PoseStamped``). :func:`read_run_bag` keeps
the images *encoded* (their CDR bytes), so that the localizer's latency includes
decoding, as it does on the robot.

A *pose bag* is what ``vbn localize`` writes and ``vbn demo`` records:
``/localizer/pose`` (``PoseStamped``), ``/localizer/pose_with_covariance``
(``PoseWithCovarianceStamped``), ``/localizer/region`` (``std_msgs/Int32``, one per
frame, -1 when lost) and a copy of ``/ground_truth/pose``: ``evo_ape bag2 BAG
/ground_truth/pose /localizer/pose`` reads it. :func:`read_pose_bag` reads one back
into arrays. Messages are rosbags objects of the Jazzy typestore; no rclpy here.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from landmark_localizer.errors import LocalizerError
from vbn_common import names
from vbn_common.bags import TYPESTORE, BagWriter, default_qos, deserialize, open_bag
from vbn_common.errors import VbnCommonError
from vbn_common.geometry.frames import quaternion_yaw, yaw_quaternion
from vbn_common.geometry.mount import static_mount_tilt

__all__ = ['PoseBag', 'PoseRecord', 'RunBag', 'read_pose_bag', 'read_run_bag',
           'write_pose_bag']

_LOG = logging.getLogger(__name__)

RAW_TOPIC, COMPRESSED_TOPIC = names.IMAGE_RAW, names.IMAGE_COMPRESSED
ODOM_TOPIC, TRUTH_TOPIC = names.ODOM, names.GROUND_TRUTH_POSE
POSE_TOPIC, COVARIANCE_TOPIC = names.LOCALIZER_POSE, names.LOCALIZER_POSE_WITH_COVARIANCE
REGION_TOPIC, DIAGNOSTICS_TOPIC = names.LOCALIZER_REGION, names.DIAGNOSTICS

_POSE_TYPES = ('geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/PoseWithCovarianceStamped',
               'nav_msgs/msg/Odometry')
_T = TYPESTORE.types


@dataclass(frozen=True)
class RunBag:
    """The content of a run bag the offline localizer needs.

    Attributes:
        path: The bag.
        image_topic: The image topic read.
        image_type: Its message type.
        stamps_ns: (n,) image header stamps, in bag order.
        images: n serialized (CDR) image messages.
        odom_stamps_ns: (m,) odometry stamps, sorted.
        odom_poses: (m, 3) ``odom -> base_link`` planar poses (x, y, yaw).
        truth_stamps_ns: (g,) ground-truth stamps, sorted (empty without ground truth).
        truth_poses: (g, 3) ``base_link`` poses in ``map``.
        truth_messages: The ground-truth messages as ``(bag time, msgtype, CDR)``.
        camera_info: The first ``/camera/camera_info`` message (None without one).
        camera_tilt: ``(3, 3)`` the run camera's pitch and roll on ``base_link`` from
            ``/tf_static`` (:mod:`vbn_common.geometry.mount`; the identity when level),
            None without that transform.
    """

    path: Path
    image_topic: str
    image_type: str
    stamps_ns: np.ndarray
    images: list[bytes]
    odom_stamps_ns: np.ndarray
    odom_poses: np.ndarray
    truth_stamps_ns: np.ndarray
    truth_poses: np.ndarray
    truth_messages: list[tuple[int, str, bytes]]
    camera_info: Any = None
    camera_tilt: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        """Number of images."""
        return len(self.images)

    def decode(self, i: int) -> np.ndarray:
        """Deserialize and decode image ``i`` to grey (what the localizer's latency includes)."""
        from vbn_common.images import decode_image

        return decode_image(deserialize(self.images[i], self.image_type))


@dataclass(frozen=True)
class PoseRecord:
    """One frame's output as the pose bag stores it.

    Attributes:
        stamp_ns: The image stamp.
        region: Region, -1 when lost.
        pose: (3,) ``base_link`` pose in ``map`` or None.
        covariance: (3, 3) covariance of ``(x, y, yaw)`` or None.
    """

    stamp_ns: int
    region: int
    pose: np.ndarray | None
    covariance: np.ndarray | None


@dataclass(frozen=True)
class PoseBag:
    """A pose bag read back.

    Attributes:
        pose_stamps_ns: (p,) stamps of ``/localizer/pose``.
        poses: (p, 3) its planar poses.
        covariance_stamps_ns: (c,) stamps of ``/localizer/pose_with_covariance``.
        covariances: (c, 3, 3) covariances of ``(x, y, yaw)``.
        regions: (r,) ``/localizer/region`` values in bag order.
        region_times_ns: (r,) their bag times.
        truth_stamps_ns: (g,) stamps of ``/ground_truth/pose``.
        truth_poses: (g, 3) its planar poses.
        diagnostics: The localizer node's ``/diagnostics`` key-values, oldest first
            (recordings of the node only).
    """

    pose_stamps_ns: np.ndarray
    poses: np.ndarray
    covariance_stamps_ns: np.ndarray
    covariances: np.ndarray
    regions: np.ndarray
    region_times_ns: np.ndarray
    truth_stamps_ns: np.ndarray
    truth_poses: np.ndarray
    diagnostics: tuple[dict[str, str], ...] = ()


def _stamp(header: Any, fallback_ns: int) -> int:
    stamp = int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec)
    return stamp or fallback_ns


def _planar_pose(msg: Any) -> np.ndarray:
    """(x, y, yaw) of a PoseStamped, PoseWithCovarianceStamped or Odometry."""
    pose = msg.pose
    while hasattr(pose, 'pose'):
        pose = pose.pose
    q = pose.orientation
    return np.array([pose.position.x, pose.position.y,
                     float(quaternion_yaw((q.x, q.y, q.z, q.w)))])


def _sorted(stamps: list[int], poses: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(np.asarray(stamps, np.int64), kind='stable')
    return (np.asarray(stamps, np.int64)[order],
            np.asarray(poses, float).reshape(-1, 3)[order])


def read_run_bag(path: str | os.PathLike[str], limit: int | None = None,
                 image_topic: str | None = None) -> RunBag:
    """Read the images (encoded), odometry and ground truth of a run bag.

    Args:
        path: Bag directory or ``.mcap``.
        limit: Keep only the first ``limit`` images (and the odometry and ground truth
            up to 1 s after the last one).
        image_topic: Image topic; default ``/camera/image_raw``, else the compressed one.

    Returns:
        The run.

    Raises:
        LocalizerError: The bag cannot be read or has no images.
    """
    bag = open_bag(path)
    with bag:
        topics = bag.topics
        if image_topic is None:
            image_topic = next((t for t in (RAW_TOPIC, COMPRESSED_TOPIC) if t in topics), None)
        if image_topic is None or image_topic not in topics:
            raise LocalizerError(f'bag {path} has no image topic '
                                 f'({image_topic or RAW_TOPIC + " or " + COMPRESSED_TOPIC})')
        image_type = topics[image_topic].msgtype
        wanted = [t for t in (image_topic, ODOM_TOPIC, TRUTH_TOPIC, names.CAMERA_INFO,
                              names.TF_STATIC) if t in topics]
        static: list[Any] = []
        camera_info = None
        stamps: list[int] = []
        images: list[bytes] = []
        odom: tuple[list[int], list[np.ndarray]] = ([], [])
        truth: tuple[list[int], list[np.ndarray]] = ([], [])
        truth_messages: list[tuple[int, str, bytes]] = []
        stop_ns: int | None = None
        try:
            for topic, msgtype, bag_ns, raw in bag.messages(topics=wanted):
                if stop_ns is not None and bag_ns > stop_ns:
                    break
                if topic == image_topic:
                    if limit is not None and len(images) >= limit:
                        stop_ns = bag_ns + 10**9
                        continue
                    header = deserialize(raw, msgtype).header
                    stamps.append(_stamp(header, bag_ns))
                    images.append(raw)
                elif topic == ODOM_TOPIC and msgtype in _POSE_TYPES:
                    msg = deserialize(raw, msgtype)
                    odom[0].append(_stamp(msg.header, bag_ns))
                    odom[1].append(_planar_pose(msg))
                elif topic == TRUTH_TOPIC and msgtype in _POSE_TYPES:
                    msg = deserialize(raw, msgtype)
                    truth[0].append(_stamp(msg.header, bag_ns))
                    truth[1].append(_planar_pose(msg))
                    truth_messages.append((bag_ns, msgtype, raw))
                elif topic == names.CAMERA_INFO and camera_info is None:
                    camera_info = deserialize(raw, msgtype)
                elif topic == names.TF_STATIC:
                    static.extend(deserialize(raw, msgtype).transforms)
        except VbnCommonError as error:
            raise LocalizerError(f'bag {path}: {error}') from error
    if not images:
        raise LocalizerError(f'bag {path} has no messages on {image_topic}')
    odom_stamps, odom_poses = _sorted(*odom)
    truth_stamps, truth_poses = _sorted(*truth)
    _LOG.info('read %s: %d images (%s), %d odometry, %d ground-truth poses', path,
              len(images), image_topic, len(odom_stamps), len(truth_stamps))
    camera_frame = (getattr(getattr(camera_info, 'header', None), 'frame_id', '')
                    or names.CAMERA_FRAME).lstrip('/')
    return RunBag(Path(path), image_topic, image_type, np.asarray(stamps, np.int64), images,
                  odom_stamps, odom_poses, truth_stamps, truth_poses, truth_messages,
                  camera_info, static_mount_tilt(static, names.BASE_FRAME, camera_frame))


def _header(stamp_ns: int, frame: str) -> Any:
    return _T['std_msgs/msg/Header'](
        stamp=_T['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9,
                                                nanosec=stamp_ns % 10**9),
        frame_id=frame)


def _pose(pose: np.ndarray) -> Any:
    q = yaw_quaternion(float(pose[2]))
    return _T['geometry_msgs/msg/Pose'](
        position=_T['geometry_msgs/msg/Point'](x=float(pose[0]), y=float(pose[1]), z=0.0),
        orientation=_T['geometry_msgs/msg/Quaternion'](x=float(q[0]), y=float(q[1]),
                                                       z=float(q[2]), w=float(q[3])))


def covariance_6x6(covariance: np.ndarray) -> np.ndarray:
    """(36,) row-major 6x6 covariance (x, y, z, roll, pitch, yaw) from the planar 3x3.

    z, roll and pitch are fixed by the planar model; their variances are set to a
    large value (1e6) as REP 145 suggests for unobserved values.
    """
    out = np.zeros((6, 6))
    out[2, 2] = out[3, 3] = out[4, 4] = 1e6
    idx = np.array([0, 1, 5])
    out[np.ix_(idx, idx)] = np.asarray(covariance, float).reshape(3, 3)
    return out.reshape(36)


def write_pose_bag(path: str | os.PathLike[str], records: Iterable[PoseRecord],
                   truth_messages: Iterable[tuple[int, str, bytes]] = (),
                   overwrite: bool = False) -> int:
    """Write the localizer's output (and a ground-truth copy) as a rosbag2 MCAP bag.

    Args:
        path: Bag directory to create.
        records: One per frame, in stamp order; frames without a pose write only
            their region.
        truth_messages: ``(bag time, msgtype, CDR)`` of ``/ground_truth/pose`` to copy.
        overwrite: Replace an existing bag.

    Returns:
        Number of poses written.

    Raises:
        LocalizerError: The bag cannot be written.
    """
    n_poses = 0
    try:
        with BagWriter(path, overwrite=overwrite) as bag:
            qos = [default_qos()]
            c_pose = bag.add_topic(POSE_TOPIC, 'geometry_msgs/msg/PoseStamped', qos)
            c_cov = bag.add_topic(COVARIANCE_TOPIC,
                                  'geometry_msgs/msg/PoseWithCovarianceStamped', qos)
            c_region = bag.add_topic(REGION_TOPIC, 'std_msgs/msg/Int32', qos)
            truth = list(truth_messages)
            c_truth = bag.add_topic(TRUTH_TOPIC, truth[0][1], qos) if truth else None
            for bag_ns, _, raw in truth:
                bag.write_raw(c_truth, bag_ns, raw)
            for record in records:
                stamp = int(record.stamp_ns)
                bag.write(c_region, stamp, _T['std_msgs/msg/Int32'](data=int(record.region)))
                if record.pose is None:
                    continue
                header = _header(stamp, names.MAP_FRAME)
                pose = _pose(record.pose)
                bag.write(c_pose, stamp, _T['geometry_msgs/msg/PoseStamped'](
                    header=header, pose=pose))
                cov = (np.full((3, 3), np.nan) if record.covariance is None
                       else record.covariance)
                bag.write(c_cov, stamp, _T['geometry_msgs/msg/PoseWithCovarianceStamped'](
                    header=header, pose=_T['geometry_msgs/msg/PoseWithCovariance'](
                        pose=pose, covariance=covariance_6x6(cov))))
                n_poses += 1
    except VbnCommonError as error:
        raise LocalizerError(f'cannot write {path}: {error}') from error
    return n_poses


def read_pose_bag(path: str | os.PathLike[str]) -> PoseBag:
    """Read a pose bag (``vbn localize`` output or a recording of the node).

    Args:
        path: Bag directory or ``.mcap``.

    Returns:
        The poses, covariances, regions and ground truth it holds (empty arrays for
        missing topics).

    Raises:
        LocalizerError: The bag cannot be read or has no ``/localizer/pose`` topic.
    """
    bag = open_bag(path)
    poses: tuple[list[int], list[np.ndarray]] = ([], [])
    truth: tuple[list[int], list[np.ndarray]] = ([], [])
    cov_stamps: list[int] = []
    covs: list[np.ndarray] = []
    regions: list[int] = []
    region_times: list[int] = []
    diagnostics: list[dict[str, str]] = []
    with bag:
        if POSE_TOPIC not in bag.topics:
            raise LocalizerError(f'bag {path} has no {POSE_TOPIC} topic')
        wanted = [t for t in (POSE_TOPIC, COVARIANCE_TOPIC, REGION_TOPIC, TRUTH_TOPIC,
                              DIAGNOSTICS_TOPIC) if t in bag.topics]
        try:
            for topic, msgtype, bag_ns, raw in bag.messages(topics=wanted):
                msg = deserialize(raw, msgtype)
                if topic == DIAGNOSTICS_TOPIC:
                    diagnostics += [{kv.key: kv.value for kv in status.values}
                                    for status in msg.status if status.name == 'localizer']
                elif topic == REGION_TOPIC:
                    regions.append(int(msg.data))
                    region_times.append(bag_ns)
                elif topic == COVARIANCE_TOPIC:
                    cov_stamps.append(_stamp(msg.header, bag_ns))
                    full = np.asarray(msg.pose.covariance, float).reshape(6, 6)
                    idx = np.array([0, 1, 5])
                    covs.append(full[np.ix_(idx, idx)])
                else:
                    target = poses if topic == POSE_TOPIC else truth
                    target[0].append(_stamp(msg.header, bag_ns))
                    target[1].append(_planar_pose(msg))
        except VbnCommonError as error:
            raise LocalizerError(f'bag {path}: {error}') from error
    pose_stamps, pose_values = _sorted(*poses)
    truth_stamps, truth_values = _sorted(*truth)
    return PoseBag(pose_stamps, pose_values, np.asarray(cov_stamps, np.int64),
                   np.asarray(covs, float).reshape(-1, 3, 3), np.asarray(regions, np.int64),
                   np.asarray(region_times, np.int64), truth_stamps, truth_values,
                   tuple(diagnostics))
