"""Rigid transforms between named frames (REP 105), as a broadcasting node needs them.

A :class:`StampedTransform` is ``parent -> child`` at a time: the pose of the child frame
expressed in the parent frame, with the translation in metres and the rotation as a unit
quaternion ``(x, y, z, w)``, exactly the content of a ``geometry_msgs/TransformStamped``.
The functions here are pure (numpy only) so that the localizer's core computes the
``map -> odom`` correction that its node then broadcasts
(:mod:`vbn_common.ros_tools.tf_broadcast`):

``map -> odom = (map -> base_link) * (odom -> base_link)^-1``

which is how a localization source (nav2's AMCL, REP 105) publishes its estimate without
ever breaking the ``odom -> base_link`` chain owned by odometry.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.frames import quaternion_yaw, yaw_quaternion

__all__ = ['StampedTransform', 'compose', 'correction', 'inverse', 'quaternion_multiply',
           'rotate']


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of quaternions ``(x, y, z, w)``."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate the 3-vector ``v`` by the unit quaternion ``q`` (``(x, y, z, w)``)."""
    u, w = np.asarray(q[:3], dtype=float), float(q[3])
    v = np.asarray(v, dtype=float)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


@dataclass(frozen=True)
class StampedTransform:
    """``parent -> child`` at ``stamp_ns``: the child frame's pose in the parent frame.

    Attributes:
        stamp_ns: Time in nanoseconds (ROS time: wall or simulated).
        parent: ``header.frame_id``, e.g. ``map``.
        child: ``child_frame_id``, e.g. ``odom``.
        translation: (3,) metres.
        rotation: (4,) unit quaternion ``(x, y, z, w)``; normalised on construction.

    Raises:
        VbnCommonError: Empty or equal frame ids, a non-finite value, or a
            zero quaternion.
    """

    stamp_ns: int
    parent: str
    child: str
    translation: np.ndarray
    rotation: np.ndarray

    def __post_init__(self) -> None:
        if not self.parent or not self.child or self.parent == self.child:
            raise VbnCommonError(
                f'a transform needs two different frame ids, got {self.parent!r} -> '
                f'{self.child!r}')
        t = np.asarray(self.translation, dtype=float).reshape(3)
        q = np.asarray(self.rotation, dtype=float).reshape(4)
        norm = float(np.linalg.norm(q))
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q)) and norm > 1e-12):
            raise VbnCommonError(
                f'transform {self.parent} -> {self.child} is not finite or has a zero '
                f'quaternion: t={t.tolist()}, q={q.tolist()}')
        object.__setattr__(self, 'translation', t)
        object.__setattr__(self, 'rotation', q / norm)
        object.__setattr__(self, 'stamp_ns', int(self.stamp_ns))

    @classmethod
    def planar(cls, stamp_ns: int, parent: str, child: str, x: float, y: float,
               yaw: float) -> StampedTransform:
        """Return a transform in the ground plane: translation ``(x, y, 0)``, yaw about z."""
        return cls(stamp_ns, parent, child, np.array([x, y, 0.0]), yaw_quaternion(yaw))

    @property
    def yaw(self) -> float:
        """Heading about z in radians (the planar part of the rotation)."""
        return float(quaternion_yaw(self.rotation))


def compose(a: StampedTransform, b: StampedTransform) -> StampedTransform:
    """``a.parent -> b.child`` from ``a = P -> C`` and ``b = C -> D``; stamp of ``a``.

    Raises:
        VbnCommonError: ``a.child`` is not ``b.parent``.
    """
    if a.child != b.parent:
        raise VbnCommonError(
            f'cannot chain {a.parent} -> {a.child} with {b.parent} -> {b.child}')
    return StampedTransform(a.stamp_ns, a.parent, b.child,
                            a.translation + rotate(a.rotation, b.translation),
                            quaternion_multiply(a.rotation, b.rotation))


def inverse(a: StampedTransform) -> StampedTransform:
    """``child -> parent`` from ``parent -> child``."""
    q_inv = a.rotation * np.array([-1.0, -1.0, -1.0, 1.0])
    return StampedTransform(a.stamp_ns, a.child, a.parent, -rotate(q_inv, a.translation),
                            q_inv)


def correction(map_to_base: StampedTransform, odom_to_base: StampedTransform,
               stamp_ns: int | None = None) -> StampedTransform:
    """``map -> odom`` such that ``map -> odom -> base`` equals ``map_to_base``.

    Args:
        map_to_base: The localizer's estimate, ``map -> base_link``.
        odom_to_base: Odometry at (or interpolated to) the same time, ``odom -> base_link``.
        stamp_ns: Stamp of the result (default: ``map_to_base``'s). AMCL stamps it
            ``transform_tolerance`` into the future so that tf users can look up
            ``map -> base_link`` at the latest odometry time.

    Raises:
        VbnCommonError: The two transforms do not end in the same child frame.
    """
    if map_to_base.child != odom_to_base.child:
        raise VbnCommonError(
            f'{map_to_base.parent} -> {map_to_base.child} and {odom_to_base.parent} -> '
            f'{odom_to_base.child} do not end in the same frame')
    result = compose(map_to_base, inverse(odom_to_base))
    if stamp_ns is None:
        return result
    return StampedTransform(stamp_ns, result.parent, result.child, result.translation,
                            result.rotation)
