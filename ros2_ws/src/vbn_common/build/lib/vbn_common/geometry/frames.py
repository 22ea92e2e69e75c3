"""Frames and planar poses: ``map``, ``odom``, ``base_link`` and the optical ``camera`` frame.

Frame names follow REP 105 (:data:`MAP_FRAME`, :data:`ODOM_FRAME`,
:data:`BASE_FRAME`) plus :data:`CAMERA_FRAME`, the frame of the image headers.
``base_link`` follows REP 103 (``x`` forward, ``y`` left, ``z`` up) and sits on the
floor; the robot moves in the plane with a pose ``(x, y, yaw)`` in ``map``; yaw is
counter-clockwise about ``z``, and a planar pose's quaternion is a rotation about
``z`` only (:func:`yaw_quaternion`, :func:`quaternion_yaw`). The
``camera`` frame is the optical frame (``z`` forward, ``x`` right, ``y`` down) at
``camera_height`` metres above ``base_link``, looking along the robot's ``x`` axis
(panorama: azimuth zero; pinhole: the optical axis). A pinhole image taken at a
*heading* ``h`` is rendered from the base pose ``(x, y, yaw + h)``: the exploration
bags turn the robot in place, as the thesis's robot did at 0, 90, 180 and 270 degrees.

Planar poses compose as ``a (+) b`` (:func:`compose_poses`: ``b`` given in the frame
of ``a``), invert with :func:`invert_pose` and carry points with
:func:`transform_points`.
"""
from __future__ import annotations

import math

import numpy as np

from vbn_common.names import BASE_FRAME, CAMERA_FRAME, MAP_FRAME, ODOM_FRAME

__all__ = [
    'BASE_FRAME',
    'BASE_TO_CAMERA_QUATERNION',
    'BASE_TO_CAMERA_ROTATION',
    'CAMERA_FRAME',
    'MAP_FRAME',
    'ODOM_FRAME',
    'camera_points_to_world',
    'compose_poses',
    'invert_pose',
    'quaternion_yaw',
    'transform_points',
    'wrap_angle',
    'world_points_to_camera',
    'yaw_quaternion',
]

#: Columns are the optical axes expressed in ``base_link``: x_opt = -y_base,
#: y_opt = -z_base, z_opt = x_base. ``p_base = R @ p_camera``.
BASE_TO_CAMERA_ROTATION = np.array([[0.0, 0.0, 1.0],
                                    [-1.0, 0.0, 0.0],
                                    [0.0, -1.0, 0.0]])

#: The same rotation as a quaternion ``(x, y, z, w)`` (the usual optical-frame one).
BASE_TO_CAMERA_QUATERNION = (-0.5, 0.5, -0.5, 0.5)


def yaw_quaternion(yaw: float | np.ndarray) -> np.ndarray:
    """Return the quaternion ``(x, y, z, w)`` of a rotation by ``yaw`` about ``z``.

    Args:
        yaw: angle(s) in radians, scalar or ``(n,)``.

    Returns:
        ``(4,)`` or ``(n, 4)`` quaternions.
    """
    if np.ndim(yaw) == 0:
        # Scalars go through libm (math.sin), whose results the recorded bags hold:
        # numpy's vectorised sin may differ in the last bit on some CPUs.
        half = float(yaw) / 2.0
        return np.array([0.0, 0.0, math.sin(half), math.cos(half)])
    yaw = np.asarray(yaw, dtype=float)
    zeros = np.zeros_like(yaw)
    return np.stack([zeros, zeros, np.sin(yaw / 2.0), np.cos(yaw / 2.0)], axis=-1)


def quaternion_yaw(quaternion: np.ndarray | tuple[float, ...]) -> np.ndarray:
    """Return the yaw (rotation about ``z``) of quaternion(s) ``(x, y, z, w)``.

    Any rotation's yaw, as the ``z`` angle of its ``z-y-x`` (yaw, pitch, roll)
    Euler decomposition; for a pure yaw rotation it inverts :func:`yaw_quaternion`.
    The quaternion need not be normalised.

    Args:
        quaternion: ``(4,)`` or ``(n, 4)`` quaternions ``(x, y, z, w)``.

    Returns:
        Scalar array or ``(n,)`` yaw angles in ``[-pi, pi]``.
    """
    q = np.asarray(quaternion, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.arctan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z)


def wrap_angle(angle: float | np.ndarray) -> np.ndarray:
    """Wrap angles into ``[-pi, pi)``."""
    return np.mod(np.asarray(angle, dtype=float) + math.pi, 2.0 * math.pi) - math.pi


def compose_poses(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return ``a (+) b`` for planar poses ``(x, y, yaw)`` (``b`` expressed in ``a``).

    Args:
        a: ``(3,)`` or ``(n, 3)`` poses.
        b: ``(3,)`` or ``(n, 3)`` poses.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape == b.shape == (3,):   # one pose each (most calls): scalar arithmetic
        c, s = math.cos(a[2]), math.sin(a[2])
        return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1],
                         (a[2] + b[2] + math.pi) % (2.0 * math.pi) - math.pi])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([a[..., 0] + c * b[..., 0] - s * b[..., 1],
                     a[..., 1] + s * b[..., 0] + c * b[..., 1],
                     wrap_angle(a[..., 2] + b[..., 2])], axis=-1)


def invert_pose(a: np.ndarray) -> np.ndarray:
    """Return the inverse of planar pose(s) ``(x, y, yaw)``."""
    a = np.asarray(a, dtype=float)
    if a.shape == (3,):   # one pose (most calls): scalar arithmetic
        c, s = math.cos(a[2]), math.sin(a[2])
        return np.array([-c * a[0] - s * a[1], s * a[0] - c * a[1],
                         (math.pi - a[2]) % (2.0 * math.pi) - math.pi])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([-c * a[..., 0] - s * a[..., 1], s * a[..., 0] - c * a[..., 1],
                     wrap_angle(-a[..., 2])], axis=-1)


def transform_points(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Carry planar points from the frame of ``pose`` into its parent frame.

    Args:
        pose: ``(3,)`` pose ``(x, y, yaw)`` of the child frame in the parent frame.
        points: ``(n, 2)`` points in the child frame.

    Returns:
        ``(n, 2)`` points in the parent frame; use ``invert_pose(pose)`` for the
        other direction.
    """
    x, y, yaw = (float(v) for v in pose)
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack([x + c * points[:, 0] - s * points[:, 1],
                     y + s * points[:, 0] + c * points[:, 1]], axis=1)


def world_points_to_camera(pose: np.ndarray, camera_height: float,
                           points: np.ndarray) -> np.ndarray:
    """Express world points in the optical frame of a camera on a robot at ``pose``.

    Args:
        pose: ``(3,)`` robot pose ``(x, y, yaw)`` in ``map``.
        camera_height: camera height above the floor, metres.
        points: ``(n, 3)`` points in ``map`` (``z`` up from the floor).

    Returns:
        ``(n, 3)`` points ``(X, Y, Z)`` in the optical frame.
    """
    x, y, yaw = (float(v) for v in pose)
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    dx, dy = points[:, 0] - x, points[:, 1] - y
    c, s = math.cos(yaw), math.sin(yaw)
    forward = c * dx + s * dy
    left = -s * dx + c * dy
    return np.stack([-left, camera_height - points[:, 2], forward], axis=1)


def camera_points_to_world(pose: np.ndarray, camera_height: float,
                           points: np.ndarray) -> np.ndarray:
    """Inverse of :func:`world_points_to_camera`."""
    x, y, yaw = (float(v) for v in pose)
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    forward, left = points[:, 2], -points[:, 0]
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack([x + c * forward - s * left, y + s * forward + c * left,
                     camera_height - points[:, 1]], axis=1)
