"""Read an exploration bag: images, camera info and the pose of every image.

The first step of the offline builder (thesis Chapter 6): the images of the
exploration and the planar pose each was taken at. Messages come through the
project's bag reader and are duck-typed; no ROS type is imported.

Images come from ``/camera/image_raw`` (``sensor_msgs/Image``) or
``/camera/image_raw/compressed`` (``sensor_msgs/CompressedImage``; when a bag
has both, the raw, lossless topic is read). They are not decoded here: each
frame keeps its bytes as an :class:`~vbn_common.images.EncodedImage`
(only the layout of raw images is checked), so that the feature step can decode
them in worker processes. The calibration is the first ``/camera/camera_info``.

Poses, planar ``(x, y, yaw)`` in ``map``:

- ``ground_truth``: ``/ground_truth/pose`` (``geometry_msgs/PoseStamped``, the
  pose of ``base_link`` in ``map``; ``PoseWithCovarianceStamped`` and
  ``nav_msgs/Odometry`` are read too), the message with the nearest header stamp
  within ``pose_tolerance_s`` of the image's stamp.
- ``tf``: the chain ``map -> ... -> base_link`` of ``/tf`` and ``/tf_static``
  (``map -> base_link`` directly, as the exploration samples have it, or through
  ``odom``), every dynamic link taken at its nearest stamp within the tolerance
  (no interpolation: an exploring robot stands still while it takes images).

``estimated``: ``/estimated/pose`` (of ``vbn estimate-poses``), read as the ground
truth is. ``auto`` (the default) takes the first of the three the bag has. The camera's
pose is the base pose composed with ``base_link -> camera`` (``/tf_static`` or ``/tf``)
in 3-D, then reduced to the plane: the camera's position is its frame's origin on the
floor; its *heading* the azimuth in ``map`` of its forward axis, the optical ``z`` axis
of ``camera`` (REP 103 optical convention: ``z`` forward, ``x`` right, ``y`` down;
``ReadConfig.camera_forward_axis = 'x'`` for a body-convention camera frame). For the
samples' camera (optical frame rotated from ``base_link`` by ``(-0.5, 0.5, -0.5,
0.5)``) the heading is the base yaw; for a panorama, the azimuth of its centre column.

Stamps are header stamps (the bag time when a header stamp is zero).

Bad input: a bag without messages, without images, without camera info or without
any pose source cannot be read and raises :class:`VbnCommonError` in one
line. Frames that cannot be used are skipped with one warning per kind of
problem, counted in :attr:`Exploration.skipped`: ``'bad_image'`` (wrong
``step``, data size or encoding, a raw size that disagrees with the camera info,
an undecodable message), ``'no_pose'`` (no pose within the tolerance) and
``'invalid_pose'`` (NaN or infinite values, a zero quaternion, a camera looking
straight up or down). A tilted base (not planar) and a camera info that changes
mid-bag are warnings; the frames are kept.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace
import logging
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from vbn_common.bags import open_bag
from vbn_common.errors import NoPoseSourceError, VbnCommonError
from vbn_common.geometry.camera import CameraModel, camera_from_info
from vbn_common.geometry.mount import level_frames, level_tilt, tilt_angles, tilted
from vbn_common.images import EncodedImage, ImageDecodeError, check_image
from vbn_common.names import (
    BASE_FRAME,
    CAMERA_FRAME,
    CAMERA_INFO,
    ESTIMATED_POSE,
    GROUND_TRUTH_POSE,
    IMAGE_TOPICS,
    MAP_FRAME,
    TF,
    TF_STATIC,
)
from vbn_common.tf_buffer import (
    TfBuffer,
    compose_transforms,
    nearest_stamps,
    quaternion_matrices,
    rotation_angles_deg,
)

__all__ = [
    'IMAGE_TOPICS',
    'POSE_SOURCES',
    'SKIP_REASONS',
    'CameraInfo',
    'Exploration',
    'Frame',
    'ReadConfig',
    'read_exploration',
]

_LOG = logging.getLogger(__name__)

#: Image topics tried in this order when ``ReadConfig.image_topic`` is ``None``.
_POSE_TOPIC_SOURCES = ('ground_truth', 'estimated')   # read from a pose topic
POSE_SOURCES = ('auto', 'ground_truth', 'estimated', 'tf')
#: Keys of :attr:`Exploration.skipped`.
SKIP_REASONS = ('bad_image', 'no_pose', 'invalid_pose')

_IMAGE_TYPES = ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage')
_INFO_TYPES = ('sensor_msgs/msg/CameraInfo',)
_POSE_TYPES = ('geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/PoseWithCovarianceStamped',
               'nav_msgs/msg/Odometry')
_TF_TYPES = ('tf2_msgs/msg/TFMessage',)
_TF, _TF_STATIC = TF, TF_STATIC


@dataclass(frozen=True)
class ReadConfig:
    """Parameters of :func:`read_exploration`.

    Attributes:
        image_topic: the image topic; ``None`` reads ``/camera/image_raw`` if the bag
            has images there, else ``/camera/image_raw/compressed``.
        camera_info_topic: the ``sensor_msgs/CameraInfo`` topic.
        pose_topic: the ground-truth pose topic (pose of ``base_frame`` in ``map_frame``).
        pose_source: ``'auto'`` (the first of these the bag has), ``'ground_truth'``,
            ``'estimated'`` (``/estimated/pose`` of ``vbn estimate-poses``) or ``'tf'``.
        pose_tolerance_s: largest time between an image and the pose (or each
            ``/tf`` link) it gets, seconds.
        map_frame: the fixed frame.
        base_frame: the robot's frame.
        camera_frame: the camera's frame; ``None`` takes the images' header frame id.
        camera_forward_axis: the camera frame's axis the camera looks along: ``'z'``
            (optical frame, the project's ``camera``) or ``'x'``.
        max_tilt_deg: a base frame tilted more than this from the vertical is
            reported as not planar (warning; the frame is kept).
    """

    image_topic: str | None = None
    camera_info_topic: str = CAMERA_INFO
    pose_topic: str = GROUND_TRUTH_POSE
    pose_source: str = 'auto'
    pose_tolerance_s: float = 0.05
    map_frame: str = MAP_FRAME
    base_frame: str = BASE_FRAME
    camera_frame: str | None = None
    camera_forward_axis: str = 'z'
    max_tilt_deg: float = 2.0

    def __post_init__(self) -> None:
        """Reject invalid values with a :class:`VbnCommonError`."""
        if self.pose_source not in POSE_SOURCES:
            raise VbnCommonError(
                f'pose_source must be one of {", ".join(POSE_SOURCES)}, got {self.pose_source!r}')
        if not (math.isfinite(self.pose_tolerance_s) and self.pose_tolerance_s >= 0):
            raise VbnCommonError(
                f'pose_tolerance_s must be a non-negative number, got {self.pose_tolerance_s}')
        if self.camera_forward_axis not in ('x', 'z'):
            raise VbnCommonError(
                f"camera_forward_axis must be 'x' or 'z', got {self.camera_forward_axis!r}")
        if not (math.isfinite(self.max_tilt_deg) and 0 <= self.max_tilt_deg <= 90):
            raise VbnCommonError(
                f'max_tilt_deg must be in [0, 90], got {self.max_tilt_deg}')
        for name in ('camera_info_topic', 'pose_topic', 'map_frame', 'base_frame'):
            if not getattr(self, name):
                raise VbnCommonError(f'{name} must not be empty')


@dataclass(frozen=True)
class CameraInfo:
    """The fields of ``sensor_msgs/CameraInfo`` that the builder uses.

    Attributes:
        width: image width, pixels.
        height: image height, pixels.
        distortion_model: ``'plumb_bob'``, ``'cylindrical'`` (the project's panoramas), ...
        d: distortion coefficients.
        k: row-major 3 x 3 intrinsic matrix (9 values).
        frame_id: the header's frame id.
    """

    width: int
    height: int
    distortion_model: str
    d: tuple[float, ...]
    k: tuple[float, ...]
    frame_id: str

    @classmethod
    def from_message(cls, msg: Any) -> CameraInfo:
        """Copy the fields of a ``sensor_msgs/CameraInfo`` (rosbags or rclpy)."""
        return cls(width=int(msg.width), height=int(msg.height),
                   distortion_model=str(msg.distortion_model),
                   d=tuple(float(v) for v in msg.d), k=tuple(float(v) for v in msg.k),
                   frame_id=str(msg.header.frame_id))


@dataclass(frozen=True)
class Frame:
    """One image of the exploration and where it was taken.

    Attributes:
        stamp_ns: the image's header stamp, nanoseconds.
        image: the undecoded image.
        base_pose: ``(x, y, yaw)`` of ``base_link`` in ``map`` (yaw of its ``x`` axis,
            radians in ``[-pi, pi]``).
        camera_pose: ``(x, y, heading)`` of the camera in ``map``: the camera frame's
            origin on the floor and the azimuth of its forward (optical ``z``) axis.
        topic: the topic the image came from.
        camera_tilt: ``(3, 3)`` the camera's pitch and roll at this frame
            (:mod:`vbn_common.geometry.mount`) when the pose source tilts the base (a
            shaking robot, an uneven floor) beyond the mount's; ``None`` otherwise.
    """

    stamp_ns: int
    image: EncodedImage
    base_pose: tuple[float, float, float]
    camera_pose: tuple[float, float, float]
    topic: str
    camera_tilt: np.ndarray | None = None


@dataclass(frozen=True)
class Exploration:
    """What :func:`read_exploration` read from a bag.

    Attributes:
        frames: the usable images in bag order.
        camera_info: the calibration (the bag's first camera info).
        pose_source: ``'ground_truth'``, ``'estimated'`` or ``'tf'``.
        frame_ids: ``{'map': ..., 'base': ..., 'camera': ...}`` as used.
        topics: ``{'image': ..., 'camera_info': ..., 'pose': ...}`` as read
            (``'pose'`` is ``'/tf'`` for the tf source).
        skipped: frames skipped, by reason (every key of :data:`SKIP_REASONS`).
        warnings: the warnings given (also logged).
        path: the bag.
        camera_tilt: ``(3, 3)`` pitch and roll of the camera on ``base_link``
            (:mod:`vbn_common.geometry.mount`; ``ray_level = tilt @ ray_optical``),
            from ``base_link -> camera``; ``None`` when level or unknown.
    """

    frames: tuple[Frame, ...]
    camera_info: CameraInfo
    pose_source: str
    frame_ids: dict[str, str]
    topics: dict[str, str]
    skipped: dict[str, int]
    warnings: tuple[str, ...] = ()
    path: Path = field(default_factory=Path)
    camera_tilt: np.ndarray | None = None

    def stamps_ns(self) -> np.ndarray:
        """Return the frames' stamps, ``(n,)`` int64 nanoseconds."""
        return np.array([f.stamp_ns for f in self.frames], dtype=np.int64)

    def base_poses(self) -> np.ndarray:
        """Return the frames' base poses, ``(n, 3)`` ``(x, y, yaw)``."""
        return np.array([f.base_pose for f in self.frames], dtype=float).reshape(-1, 3)

    def camera_poses(self) -> np.ndarray:
        """Return the frames' camera poses, ``(n, 3)`` ``(x, y, heading)``."""
        return np.array([f.camera_pose for f in self.frames], dtype=float).reshape(-1, 3)

    def camera_model(self) -> CameraModel:
        """Return the camera model of the camera info, with the mount's tilt if any."""
        return tilted(camera_from_info(self.camera_info), self.camera_tilt)


def _planar(pose: np.ndarray) -> tuple[float, float, float]:
    return float(pose[0]), float(pose[1]), float(pose[2])


def _stamp_ns(header: Any, bag_time_ns: int) -> int:
    stamp = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return stamp if stamp != 0 else bag_time_ns


class _Warnings:
    def __init__(self) -> None:
        self.messages: list[str] = []

    def __call__(self, message: str) -> None:
        self.messages.append(message)
        _LOG.warning('%s', message)


# -- reading -----------------------------------------------------------------------------
def read_exploration(bag_path: str | os.PathLike[str],
                     config: ReadConfig | None = None) -> Exploration:
    """Read the images of an exploration bag and the pose each was taken at.

    Args:
        bag_path: a rosbag2 directory or ``.mcap`` file.
        config: topics, frames, pose source and tolerance (default :class:`ReadConfig`).

    Returns:
        The frames, calibration and pose source; what was skipped and why.

    Raises:
        VbnCommonError: an unreadable bag, no messages, images, camera info, poses or
            usable frame.

    Example:
        >>> read_exploration('bags/room_exploration').pose_source  # doctest: +SKIP
        'ground_truth'
    """
    config = config or ReadConfig()
    path = Path(bag_path)
    warn = _Warnings()
    with open_bag(path) as bag:
        if not bag.message_count:
            raise VbnCommonError(f'bag {path} contains no messages')
        counts = {name: info.count for name, info in bag.topics.items()}
        image_topic = _image_topic(path, bag.topics, config)
        if not counts.get(config.camera_info_topic):
            raise VbnCommonError(
                f'bag {path} has no camera info: no messages on {config.camera_info_topic}')
        source = _pose_source(path, counts, config)
        if source == 'estimated':   # read like the ground truth, from its own topic
            config = replace(config, pose_topic=ESTIMATED_POSE)
        topics = [image_topic, config.camera_info_topic]
        topics += [config.pose_topic] if source in _POSE_TOPIC_SOURCES else [_TF]
        topics += [_TF_STATIC] if counts.get(_TF_STATIC) else []
        if source in _POSE_TOPIC_SOURCES and counts.get(_TF):  # base_link -> camera there?
            topics.append(_TF)
        for topic in topics[1:]:
            allowed = {config.camera_info_topic: _INFO_TYPES, config.pose_topic: _POSE_TYPES,
                       _TF: _TF_TYPES, _TF_STATIC: _TF_TYPES}[topic]
            if bag.topics[topic].msgtype not in allowed:
                raise VbnCommonError(
                    f'bag {path}: {topic} has type {bag.topics[topic].msgtype}, expected '
                    f'{" or ".join(allowed)}')
        data = _read_messages(bag, topics, image_topic, config, warn)
    return _assemble(path, data, image_topic, source, config, warn)


def _image_topic(path: Path, topics: dict[str, Any], config: ReadConfig) -> str:
    if config.image_topic is not None:
        candidates: tuple[str, ...] = (config.image_topic,)
    else:
        candidates = IMAGE_TOPICS
    present = [t for t in candidates if t in topics and topics[t].count]
    if not present:
        raise VbnCommonError(
            f'bag {path} has no images: no messages on {" or ".join(candidates)}')
    topic = present[0]
    msgtype = topics[topic].msgtype
    if msgtype not in _IMAGE_TYPES:
        raise VbnCommonError(
            f'bag {path}: {topic} has type {msgtype}, expected sensor_msgs/msg/Image or '
            'sensor_msgs/msg/CompressedImage')
    if len(present) > 1:
        _LOG.info('bag %s has images on %s: reading %s', path, ' and '.join(present), topic)
    return topic


def _pose_source(path: Path, counts: dict[str, int], config: ReadConfig) -> str:
    has_truth = bool(counts.get(config.pose_topic))
    has_tf = bool(counts.get(_TF))
    if config.pose_source == 'ground_truth' and not has_truth:
        raise VbnCommonError(
            f'bag {path} has no ground truth: no messages on {config.pose_topic}')
    has_estimate = bool(counts.get(ESTIMATED_POSE))
    if config.pose_source == 'estimated' and not has_estimate:
        raise VbnCommonError(f'bag {path} has no {ESTIMATED_POSE} (vbn estimate-poses)')
    if config.pose_source == 'tf' and not has_tf:
        raise NoPoseSourceError(f'bag {path} has no pose source: no messages on {_TF}')
    if config.pose_source != 'auto':
        return config.pose_source
    if has_truth:
        return 'ground_truth'
    if has_estimate:
        return 'estimated'
    if has_tf:
        return 'tf'
    raise NoPoseSourceError(
        f'bag {path} has no pose source: no messages on {config.pose_topic} or {_TF}')


@dataclass
class _BagData:
    images: list[tuple[int, EncodedImage, str]] = field(default_factory=list)
    bad_images: Counter[str] = field(default_factory=Counter)
    camera_info: CameraInfo | None = None
    info_changes: int = 0
    first_change_ns: int | None = None
    pose_stamps: list[int] = field(default_factory=list)
    pose_values: list[tuple[float, ...]] = field(default_factory=list)  # x y z qx qy qz qw
    pose_frames: Counter[str] = field(default_factory=Counter)
    tf: TfBuffer = field(default_factory=TfBuffer)
    undecodable: Counter[str] = field(default_factory=Counter)


def _read_messages(bag: Any, topics: list[str], image_topic: str, config: ReadConfig,
                   warn: _Warnings) -> _BagData:
    data = _BagData()
    for topic, msgtype, bag_time, raw in bag.messages(topics=topics):
        try:
            msg = bag.deserialize(raw, msgtype)
        except VbnCommonError as error:
            data.undecodable[topic] += 1
            if topic == image_topic:
                data.bad_images[str(error)] += 1
            continue
        if topic == image_topic:
            stamp = _stamp_ns(msg.header, bag_time)
            try:
                image = check_image(msg)
            except ImageDecodeError as error:
                data.bad_images[str(error)] += 1
                continue
            data.images.append((stamp, image, str(msg.header.frame_id)))
        elif topic == config.camera_info_topic:
            info = CameraInfo.from_message(msg)
            if data.camera_info is None:
                data.camera_info = info
            elif info != data.camera_info:
                data.info_changes += 1
                if data.first_change_ns is None:
                    data.first_change_ns = _stamp_ns(msg.header, bag_time)
        elif topic == config.pose_topic:
            pose = msg.pose
            pose = getattr(pose, 'pose', pose)  # PoseWithCovariance(Stamped), Odometry
            p, q = pose.position, pose.orientation
            data.pose_stamps.append(_stamp_ns(msg.header, bag_time))
            data.pose_values.append((float(p.x), float(p.y), float(p.z), float(q.x),
                                     float(q.y), float(q.z), float(q.w)))
            data.pose_frames[str(msg.header.frame_id).lstrip('/')] += 1
        elif topic in (_TF, _TF_STATIC):
            for transform in msg.transforms:
                data.tf.add(transform, _stamp_ns(transform.header, bag_time),
                            static=topic == _TF_STATIC)
    for topic, count in sorted(data.undecodable.items()):
        warn(f'skipped {count} undecodable message(s) on {topic}')
    return data


def _assemble(path: Path, data: _BagData, image_topic: str, source: str, config: ReadConfig,
              warn: _Warnings) -> Exploration:
    info = data.camera_info
    if info is None:  # every camera info was undecodable
        raise VbnCommonError(
            f'bag {path} has no camera info: no readable message on {config.camera_info_topic}')
    if data.info_changes:
        warn(f'camera info on {config.camera_info_topic} changes in {data.info_changes} '
             f'message(s), first at stamp {data.first_change_ns}; using the first one '
             f'({info.width}x{info.height} {info.distortion_model})')
    images = []
    for stamp, image, frame_id in data.images:
        if not image.compressed and (image.width, image.height) != (info.width, info.height):
            data.bad_images[f'image {image.describe()} does not match the camera info size '
                            f'{info.width}x{info.height}'] += 1
        else:
            images.append((stamp, image, frame_id))
    skipped = dict.fromkeys(SKIP_REASONS, 0)
    skipped['bad_image'] = sum(data.bad_images.values())
    for message, count in data.bad_images.most_common():
        warn(f'skipped {count} image(s) on {image_topic}: {message}')
    total = len(images) + skipped['bad_image']
    if not images:
        raise VbnCommonError(
            f'no usable images in bag {path}: all {total} on {image_topic} are bad '
            f'({next(iter(data.bad_images), "unknown problem")})')
    camera_frame = config.camera_frame or images[0][2] or info.frame_id or CAMERA_FRAME
    camera_frame = camera_frame.lstrip('/')
    frame_ids = {'map': config.map_frame, 'base': config.base_frame, 'camera': camera_frame}
    stamps = np.array([stamp for stamp, _, _ in images], dtype=np.int64)
    tolerance_ns = int(round(config.pose_tolerance_s * 1e9))
    if data.tf.conflicts:
        warn(f'/tf gives more than one parent to {", ".join(sorted(data.tf.conflicts))}; '
             'using the first')

    if source in _POSE_TOPIC_SOURCES:
        base_r, base_t, found = _ground_truth(path, data, stamps, tolerance_ns, config, warn)
        pose_topic = config.pose_topic
    else:
        looked_up = data.tf.lookup(config.map_frame, config.base_frame, stamps, tolerance_ns)
        if looked_up is None:
            raise NoPoseSourceError(
                f'bag {path} has no pose source: no {config.pose_topic} and no transform '
                f'chain {config.map_frame} -> {config.base_frame} in /tf and /tf_static')
        base_r, base_t, found = looked_up
        pose_topic = _TF
    base_to_camera = data.tf.lookup(config.base_frame, camera_frame, stamps, tolerance_ns)
    camera_tilt = None
    if base_to_camera is None:
        warn(f'no transform {config.base_frame} -> {camera_frame} in /tf_static or /tf: '
             f'assuming the camera looks along {config.base_frame} +x from its origin')
        camera_r, camera_t = base_r, base_t
        axis = 0
    else:
        cam_r, cam_t, cam_found = base_to_camera
        for line in data.tf.static_change_warnings(config.base_frame, camera_frame):
            warn(line)
        found &= cam_found
        camera_r, camera_t = compose_transforms((base_r, base_t), (cam_r, cam_t))
        axis = 2 if config.camera_forward_axis == 'z' else 0
        if axis == 2:
            camera_tilt = _mount_tilt(cam_r, cam_found, camera_frame, config, warn)

    base_yaw = np.arctan2(base_r[:, 1, 0], base_r[:, 0, 0])
    forward = camera_r[:, :, axis]
    heading = np.arctan2(forward[:, 1], forward[:, 0])
    with np.errstate(invalid='ignore'):
        level = np.hypot(forward[:, 0], forward[:, 1]) > 1e-6
    base_pose = np.column_stack([base_t[:, :2], base_yaw])
    camera_pose = np.column_stack([camera_t[:, :2], heading])
    finite = (np.isfinite(base_pose).all(axis=1) & np.isfinite(camera_pose).all(axis=1)
              & np.isfinite(base_r).all(axis=(1, 2)))
    valid = found & finite & level
    skipped['no_pose'] = int((~found).sum())
    skipped['invalid_pose'] = int((found & ~(finite & level)).sum())
    if skipped['no_pose']:
        first = int(stamps[~found][0])
        warn(f'skipped {skipped["no_pose"]} of {len(images)} image(s): no pose from '
             f'{pose_topic} within {config.pose_tolerance_s} s of their stamp '
             f'(first at stamp {first})')
    if skipped['invalid_pose']:
        bad = found & ~(finite & level)
        reason = ('NaN or infinite values or a zero quaternion' if (found & ~finite).any()
                  else 'the camera looks straight up or down')
        warn(f'skipped {skipped["invalid_pose"]} of {len(images)} image(s): their pose from '
             f'{pose_topic} is invalid ({reason}; first at stamp {int(stamps[bad][0])})')
    tilt = np.degrees(np.arccos(np.clip(base_r[:, 2, 2], -1.0, 1.0)))
    tilted = valid & (tilt > config.max_tilt_deg)
    if tilted.any():
        warn(f'{int(tilted.sum())} of {int(valid.sum())} pose(s) are not planar '
             f'({config.base_frame} tilted up to {tilt[tilted].max():.1f} deg, more than '
             f'{config.max_tilt_deg} deg); using the heading of its x axis')
    if not valid.any():
        raise VbnCommonError(
            f'no usable images in bag {path}: none of the {total} on {image_topic} has a '
            f'valid pose from {pose_topic} (skipped: '
            f'{", ".join(f"{k} {v}" for k, v in skipped.items() if v)})')
    frame_tilts = _frame_tilts(camera_r, valid, camera_tilt) if axis == 2 else \
        [None] * len(stamps)
    frames = tuple(
        Frame(stamp_ns=int(stamps[i]), image=images[i][1], base_pose=_planar(base_pose[i]),
              camera_pose=_planar(camera_pose[i]), topic=image_topic,
              camera_tilt=frame_tilts[i])
        for i in np.flatnonzero(valid))
    _LOG.info('read %d frames from %s (%s poses); skipped %s', len(frames), path, source,
              skipped)
    return Exploration(
        frames=frames, camera_info=info, pose_source=source, frame_ids=frame_ids,
        topics={'image': image_topic, 'camera_info': config.camera_info_topic,
                'pose': pose_topic},
        skipped=skipped, warnings=tuple(warn.messages), path=path, camera_tilt=camera_tilt)


def _frame_tilts(camera_r: np.ndarray, valid: np.ndarray, mount: np.ndarray | None
                 ) -> list[np.ndarray | None]:
    """Return each frame's camera tilt in ``map`` where it differs from the mount's.

    ``None`` where it does not (by less than 0.001 degrees) or the frame is invalid.
    """
    tilts = np.einsum('nji,njk->nik', level_frames(camera_r[:, :, 2]), camera_r)
    mount = np.eye(3) if mount is None else mount
    with np.errstate(invalid='ignore'):
        off = rotation_angles_deg(mount, tilts) > 1e-3
    keep = valid & off & np.isfinite(tilts).all(axis=(1, 2))
    return [tilts[i] if keep[i] else None for i in range(len(camera_r))]


def _mount_tilt(rotations: np.ndarray, found: np.ndarray, camera_frame: str,
                config: ReadConfig, warn: _Warnings) -> np.ndarray | None:
    """Return the camera's pitch and roll on the base (``None``: level).

    From the first frame's ``base_link -> camera``, with a warning if the last frame's
    differs (the mount is taken as fixed).
    """
    usable = np.flatnonzero(found & np.isfinite(rotations).all(axis=(1, 2)))
    if usable.size == 0:
        return None
    try:
        tilts = [level_tilt(rotations[i]) for i in usable[[0, -1]]]
    except VbnCommonError:
        return None     # looking straight up or down: those frames are skipped as invalid
    change = float(rotation_angles_deg(tilts[0], tilts[1]))
    if change > 0.01:
        warn(f'{config.base_frame} -> {camera_frame} changes during the bag (by '
             f'{change:.2f} deg): using its first value')
    pitch, roll = tilt_angles(tilts[0])
    if max(abs(pitch), abs(roll)) < 1e-6:
        return None
    _LOG.info('camera mount: pitch %.3f deg, roll %.3f deg', pitch, roll)
    return tilts[0]


def _ground_truth(path: Path, data: _BagData, stamps: np.ndarray, tolerance_ns: int,
                  config: ReadConfig, warn: _Warnings
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(R, t, found)`` of the base at each image stamp from the ground truth."""
    if not data.pose_stamps:
        raise NoPoseSourceError(
            f'bag {path} has no pose source: no readable message on {config.pose_topic}')
    other = {f: c for f, c in data.pose_frames.items() if f not in ('', config.map_frame)}
    if other:
        warn(f'{sum(other.values())} pose(s) on {config.pose_topic} are in frame(s) '
             f'{", ".join(sorted(other))}, not {config.map_frame}; using them as '
             f'{config.map_frame}')
    pose_stamps = np.asarray(data.pose_stamps, dtype=np.int64)
    values = np.asarray(data.pose_values, dtype=float)
    order = np.argsort(pose_stamps, kind='stable')
    index, gap = nearest_stamps(pose_stamps[order], stamps)
    chosen = values[order[index]]
    return quaternion_matrices(chosen[:, 3:]), chosen[:, :3], gap <= tolerance_ns
