"""Message conversions of the bag synthesis: numpy and dataclasses to rosbags messages.

The only synthesis module that touches ROS message types (through
:data:`vbn_common.bags.TYPESTORE`, ROS 2 Jazzy definitions). Frame names
follow REP 105 and the project's design: ``map``, ``odom``, ``base_link`` and the
optical ``camera`` frame.
"""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from vbn_common.bags import TYPESTORE
from vbn_common.errors import VbnCommonError
from vbn_common.geometry.camera import CameraInfoFields
from vbn_common.geometry.frames import (
    BASE_TO_CAMERA_QUATERNION,
    BASE_TO_CAMERA_ROTATION,
    yaw_quaternion,
)
from vbn_common.names import BASE_FRAME, CAMERA_FRAME, MAP_FRAME, ODOM_FRAME

__all__ = [
    'camera_info_message',
    'camera_static_transform',
    'compressed_image_message',
    'encode_image',
    'header',
    'image_message',
    'odometry_message',
    'planar_transform',
    'pose_stamped_message',
    'tf_message',
    'transform',
]

_T = TYPESTORE.types


def header(stamp_ns: int, frame_id: str) -> Any:
    """Return a ``std_msgs/Header`` for a stamp in nanoseconds."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return _T['std_msgs/msg/Header'](
        stamp=_T['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec), frame_id=frame_id)


def image_message(stamp_ns: int, image: np.ndarray, frame_id: str = CAMERA_FRAME) -> Any:
    """Return a ``sensor_msgs/Image`` (``mono8`` for 2-D, ``bgr8`` for 3-channel arrays)."""
    image = np.ascontiguousarray(image, dtype=np.uint8)
    encoding = 'mono8' if image.ndim == 2 else 'bgr8'
    height, width = image.shape[:2]
    channels = 1 if image.ndim == 2 else image.shape[2]
    return _T['sensor_msgs/msg/Image'](
        header=header(stamp_ns, frame_id), height=height, width=width, encoding=encoding,
        is_bigendian=0, step=width * channels, data=image.reshape(-1))


def encode_image(image: np.ndarray, fmt: str, jpeg_quality: int = 90) -> bytes:
    """Encode an image as JPEG or PNG bytes.

    Raises:
        VbnCommonError: unknown format or encoder failure.
    """
    if fmt == 'jpeg':
        ok, data = cv2.imencode('.jpg', image, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
    elif fmt == 'png':
        ok, data = cv2.imencode('.png', image, [cv2.IMWRITE_PNG_COMPRESSION, 6])
    else:
        raise VbnCommonError(f'unknown image compression {fmt!r} (expected jpeg or png)')
    if not ok:
        raise VbnCommonError(f'cannot encode image as {fmt}')
    return data.tobytes()


def compressed_image_message(stamp_ns: int, image: np.ndarray, fmt: str = 'jpeg',
                             jpeg_quality: int = 90, frame_id: str = CAMERA_FRAME) -> Any:
    """Return a ``sensor_msgs/CompressedImage``.

    The ``format`` field follows image_transport's compressed plugin:
    ``'bgr8; jpeg compressed bgr8'`` (or ``mono8``, or ``png``).
    """
    encoding = 'mono8' if image.ndim == 2 else 'bgr8'
    data = np.frombuffer(encode_image(image, fmt, jpeg_quality), dtype=np.uint8)
    return _T['sensor_msgs/msg/CompressedImage'](
        header=header(stamp_ns, frame_id), format=f'{encoding}; {fmt} compressed {encoding}',
        data=data)


def camera_info_message(stamp_ns: int, info: CameraInfoFields,
                        frame_id: str = CAMERA_FRAME) -> Any:
    """Return a ``sensor_msgs/CameraInfo`` from :class:`CameraInfoFields`."""
    roi = _T['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0, width=0,
                                                 do_rectify=False)
    return _T['sensor_msgs/msg/CameraInfo'](
        header=header(stamp_ns, frame_id), height=info.height, width=info.width,
        distortion_model=info.distortion_model, d=np.array(info.d, dtype=np.float64),
        k=np.array(info.k, dtype=np.float64), r=np.array(info.r, dtype=np.float64),
        p=np.array(info.p, dtype=np.float64), binning_x=0, binning_y=0, roi=roi)


def _pose(x: float, y: float, z: float, quaternion: tuple[float, ...] | np.ndarray) -> Any:
    q = [float(v) for v in quaternion]
    return _T['geometry_msgs/msg/Pose'](
        position=_T['geometry_msgs/msg/Point'](x=float(x), y=float(y), z=float(z)),
        orientation=_T['geometry_msgs/msg/Quaternion'](x=q[0], y=q[1], z=q[2], w=q[3]))


def pose_stamped_message(stamp_ns: int, pose: np.ndarray, frame_id: str = MAP_FRAME,
                         tilt: np.ndarray | None = None) -> Any:
    """Return a ``geometry_msgs/PoseStamped`` for a planar pose ``(x, y, yaw)``.

    ``tilt`` (a camera tilt of :mod:`vbn_common.geometry.mount`, in the optical frame)
    pitches and rolls the base with it: the pose of a shaking robot.
    """
    x, y, yaw = (float(v) for v in pose)
    quaternion = yaw_quaternion(yaw)
    if tilt is not None:
        body = BASE_TO_CAMERA_ROTATION @ np.asarray(tilt, float) @ BASE_TO_CAMERA_ROTATION.T
        c, s = np.cos(yaw), np.sin(yaw)
        rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ body
        quaternion = Rotation.from_matrix(rotation).as_quat()
    return _T['geometry_msgs/msg/PoseStamped'](header=header(stamp_ns, frame_id),
                                               pose=_pose(x, y, 0.0, quaternion))


def transform(stamp_ns: int, parent: str, child: str, translation: tuple[float, float, float],
              quaternion: tuple[float, ...]) -> Any:
    """Return a ``geometry_msgs/TransformStamped`` (``child`` expressed in ``parent``)."""
    q = [float(v) for v in quaternion]
    return _T['geometry_msgs/msg/TransformStamped'](
        header=header(stamp_ns, parent), child_frame_id=child,
        transform=_T['geometry_msgs/msg/Transform'](
            translation=_T['geometry_msgs/msg/Vector3'](
                x=float(translation[0]), y=float(translation[1]), z=float(translation[2])),
            rotation=_T['geometry_msgs/msg/Quaternion'](x=q[0], y=q[1], z=q[2], w=q[3])))


def planar_transform(stamp_ns: int, parent: str, child: str, pose: np.ndarray) -> Any:
    """Return the transform of a planar pose ``(x, y, yaw)`` of ``child`` in ``parent``."""
    x, y, yaw = (float(v) for v in pose)
    return transform(stamp_ns, parent, child, (x, y, 0.0), yaw_quaternion(yaw))


def camera_static_transform(stamp_ns: int, camera_height: float,
                            tilt: np.ndarray | None = None) -> Any:
    """Return ``base_link -> camera``: up ``camera_height``, rotated to the optical frame.

    ``tilt`` (:mod:`vbn_common.geometry.mount`) pitches and rolls the optical frame.
    """
    if tilt is None:
        return transform(stamp_ns, BASE_FRAME, CAMERA_FRAME, (0.0, 0.0, camera_height),
                         BASE_TO_CAMERA_QUATERNION)
    rotation = BASE_TO_CAMERA_ROTATION @ np.asarray(tilt, float).reshape(3, 3)
    quaternion = tuple(float(v) for v in Rotation.from_matrix(rotation).as_quat())
    return transform(stamp_ns, BASE_FRAME, CAMERA_FRAME, (0.0, 0.0, camera_height),
                     quaternion)


def tf_message(transforms: list[Any]) -> Any:
    """Return a ``tf2_msgs/TFMessage``."""
    return _T['tf2_msgs/msg/TFMessage'](transforms=list(transforms))


def odometry_message(stamp_ns: int, pose: np.ndarray, twist: np.ndarray,
                     pose_variance: np.ndarray, twist_variance: np.ndarray) -> Any:
    """Return a ``nav_msgs/Odometry`` (frame ``odom``, child ``base_link``).

    Args:
        stamp_ns: stamp, nanoseconds.
        pose: ``(x, y, yaw)`` of ``base_link`` in ``odom``.
        twist: ``(v, omega)`` in ``base_link``.
        pose_variance: variances of ``x``, ``y``, ``yaw``.
        twist_variance: variances of ``v``, ``omega``.
    """
    x, y, yaw = (float(v) for v in pose)
    big = 1e6  # z, roll, pitch: not measured by planar odometry
    pose_cov = np.diag([pose_variance[0], pose_variance[1], big, big, big,
                        pose_variance[2]]).astype(np.float64).reshape(-1)
    twist_cov = np.diag([twist_variance[0], big, big, big, big,
                         twist_variance[1]]).astype(np.float64).reshape(-1)
    vec = _T['geometry_msgs/msg/Vector3']
    return _T['nav_msgs/msg/Odometry'](
        header=header(stamp_ns, ODOM_FRAME), child_frame_id=BASE_FRAME,
        pose=_T['geometry_msgs/msg/PoseWithCovariance'](
            pose=_pose(x, y, 0.0, yaw_quaternion(yaw)), covariance=pose_cov),
        twist=_T['geometry_msgs/msg/TwistWithCovariance'](
            twist=_T['geometry_msgs/msg/Twist'](
                linear=vec(x=float(twist[0]), y=0.0, z=0.0),
                angular=vec(x=0.0, y=0.0, z=float(twist[1]))),
            covariance=twist_cov))
