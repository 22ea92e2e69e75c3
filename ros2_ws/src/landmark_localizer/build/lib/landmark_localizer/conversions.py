"""Messages to numpy and back for the localizer node (the glue half; no rclpy).

The node converts what it hears with these functions, hands arrays to the core
(:class:`~landmark_localizer.localizer.Localizer`) and converts the estimate back:

- header stamps to integer nanoseconds and back (:func:`stamp_to_ns`, :func:`ns_to_stamp`);
- ``nav_msgs/Odometry`` to the planar ``odom -> base_link`` pose (:func:`odometry_pose`);
- an :class:`~landmark_localizer.localizer.Estimate` to ``geometry_msgs/PoseStamped`` and
  ``PoseWithCovarianceStamped`` (:func:`pose_messages`), never with a NaN in them;
- ``/initialpose`` to a voting hint (:func:`initial_pose_hint`);
- ``sensor_msgs/CameraInfo`` against the database's camera
  (:func:`~landmark_localizer.camera_check.camera_mismatch`);
- the node's counters to a ``diagnostic_msgs/DiagnosticArray`` (:func:`diagnostic_array`).

Bad content raises :class:`~landmark_localizer.errors.LocalizerError` with one line that
names the problem and the value; the node logs it and drops the message.
"""
from __future__ import annotations

from collections.abc import Mapping
import math
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
import numpy as np

from landmark_localizer.errors import LocalizerError
from landmark_localizer.localizer import Estimate
from vbn_common.geometry.frames import quaternion_yaw, yaw_quaternion

__all__ = [
    'covariance_6x6',
    'diagnostic_array',
    'initial_pose_hint',
    'ns_to_stamp',
    'odometry_pose',
    'planar_pose',
    'pose_messages',
    'stamp_to_ns',
]

#: Indices of x, y and yaw in a row-major 6 x 6 ROS pose covariance (x y z roll pitch yaw).
_PLANAR_INDICES = (0, 1, 5)


def stamp_to_ns(stamp: Any) -> int:
    """Return a ``builtin_interfaces/Time`` as integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(stamp_ns: int) -> Time:
    """Return integer nanoseconds as a ``builtin_interfaces/Time``."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def planar_pose(pose: Any) -> np.ndarray:
    """Return ``(x, y, yaw)`` of a ``geometry_msgs/Pose`` (z, roll and pitch ignored).

    Raises:
        LocalizerError: A non-finite value or a zero quaternion.
    """
    p, q = pose.position, pose.orientation
    quaternion = np.array([q.x, q.y, q.z, q.w], float)
    values = np.array([p.x, p.y], float)
    if not (np.all(np.isfinite(values)) and np.all(np.isfinite(quaternion))):
        raise LocalizerError(f'pose is not finite: position ({p.x}, {p.y}), orientation '
                             f'({q.x}, {q.y}, {q.z}, {q.w})')
    if np.linalg.norm(quaternion) < 1e-9:
        raise LocalizerError('pose has a zero quaternion')
    return np.array([values[0], values[1], float(quaternion_yaw(quaternion))])


def odometry_pose(msg: Any) -> tuple[int, np.ndarray]:
    """Return ``(stamp_ns, (x, y, yaw))`` of a ``nav_msgs/Odometry``: base_link in odom.

    Raises:
        LocalizerError: A non-finite pose or a zero quaternion.
    """
    return stamp_to_ns(msg.header.stamp), planar_pose(msg.pose.pose)


def covariance_6x6(covariance: np.ndarray) -> list[float]:
    """Return the 36 row-major values of a ROS pose covariance from ``(x, y, yaw)``'s.

    z, roll and pitch are not estimated (the robot moves in the plane) and stay zero,
    as nav2's AMCL leaves them.
    """
    out = np.zeros((6, 6))
    cov = np.asarray(covariance, float).reshape(3, 3)
    for i, a in enumerate(_PLANAR_INDICES):
        for j, b in enumerate(_PLANAR_INDICES):
            out[a, b] = cov[i, j]
    return [float(v) for v in out.ravel()]


def pose_messages(estimate: Estimate, frame_id: str
                  ) -> tuple[PoseStamped, PoseWithCovarianceStamped] | None:
    """Return the ``/localizer/pose`` and ``/localizer/pose_with_covariance`` messages.

    Both carry the image's stamp and ``frame_id`` (``map``).

    Args:
        estimate: What the localizer found for one frame.
        frame_id: The global frame.

    Returns:
        The two messages, or None when the estimate has no pose, or a pose or
        covariance that is not finite (the node never publishes a NaN).
    """
    if estimate.pose is None or estimate.covariance is None:
        return None
    pose = np.asarray(estimate.pose, float)
    cov = np.asarray(estimate.covariance, float)
    if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(cov))):
        return None
    stamped = PoseStamped()
    stamped.header.stamp = ns_to_stamp(estimate.stamp_ns)
    stamped.header.frame_id = frame_id
    stamped.pose.position.x, stamped.pose.position.y = float(pose[0]), float(pose[1])
    qx, qy, qz, qw = (float(v) for v in yaw_quaternion(float(pose[2])))
    o = stamped.pose.orientation
    o.x, o.y, o.z, o.w = qx, qy, qz, qw
    with_cov = PoseWithCovarianceStamped()
    with_cov.header = stamped.header
    with_cov.pose.pose = stamped.pose
    with_cov.pose.covariance = covariance_6x6(cov)
    return stamped, with_cov


def initial_pose_hint(msg: Any, global_frame_id: str, default_radius: float
                      ) -> tuple[float, float, float]:
    """Return ``(x, y, radius)`` of an ``/initialpose`` for :meth:`Localizer.set_hint`.

    The radius is the larger of ``default_radius`` and three standard deviations of the
    pose's position covariance (RViz's "2D Pose Estimate" sends 0.25 m^2, i.e. 1.5 m).

    Args:
        msg: A ``geometry_msgs/PoseWithCovarianceStamped``.
        global_frame_id: The frame the pose must be in (an empty frame id is taken as it).
        default_radius: The localizer's ``hint_radius_m``.

    Raises:
        LocalizerError: Another frame, or a position that is not finite.
    """
    frame = msg.header.frame_id
    if frame and frame != global_frame_id:
        raise LocalizerError(f'initial pose is in frame {frame!r}, expected '
                             f'{global_frame_id!r}')
    x, y = float(msg.pose.pose.position.x), float(msg.pose.pose.position.y)
    if not (math.isfinite(x) and math.isfinite(y)):
        raise LocalizerError(f'initial pose position is not finite: ({x}, {y})')
    cov = np.asarray(msg.pose.covariance, float)
    radius = float(default_radius)
    if cov.size == 36 and np.all(np.isfinite(cov[[0, 7]])) and max(cov[0], cov[7]) > 0:
        radius = max(radius, 3.0 * math.sqrt(max(cov[0], cov[7])))
    return x, y, radius






def diagnostic_array(stamp: Time, name: str, hardware_id: str, level: bytes, message: str,
                     values: Mapping[str, Any]) -> DiagnosticArray:
    """Return a ``diagnostic_msgs/DiagnosticArray`` with one status.

    Args:
        stamp: Header stamp (the node's clock).
        name: Status name (``localizer``).
        hardware_id: What the status is about (the database file).
        level: ``DiagnosticStatus.OK``, ``WARN`` or ``ERROR`` (bytes, as rclpy has them).
        message: One line summary.
        values: Key-value pairs; values are shown with ``str`` (floats with 4 digits).
    """
    status = DiagnosticStatus(level=level, name=name, hardware_id=hardware_id,
                              message=message)
    status.values = [KeyValue(key=str(key), value=_format(value))
                     for key, value in values.items()]
    msg = DiagnosticArray(status=[status])
    msg.header.stamp = stamp
    return msg


def _format(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:.4g}' if math.isfinite(value) else 'n/a'
    return str(value)
