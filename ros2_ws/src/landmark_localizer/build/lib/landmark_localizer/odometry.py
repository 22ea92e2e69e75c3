"""Odometry between its messages: the ``odom -> base_link`` pose at an image's stamp.

The node keeps the last seconds of ``/odom`` in an :class:`OdometryBuffer` and asks it
for the pose at each image's stamp (linear interpolation, the yaw along the shorter
arc), which the core uses to predict motion and the node to compute the ``map -> odom``
correction (REP 105). Odometry arrives faster than images (50 Hz against 10 Hz in the
sample bags), so an image's stamp normally lies between two messages; a stamp a little
after the newest message (the image was taken before its odometry arrived) is
extrapolated at the last velocity, within ``max_extrapolation_s``.

Bad odometry never reaches the core: a message with a non-finite pose is refused and
empties the buffer (nothing is interpolated across it); a message further than
``max_jump_m`` from the previous one, or older than it (a bag that loops), empties the
buffer too, and a new track starts only once two consecutive messages agree, so that a
single outlier is never used. :meth:`OdometryBuffer.add` says which of these happened.
"""
from __future__ import annotations

from collections import deque
import math

import numpy as np

__all__ = ['ACCEPTED', 'JUMP', 'NOT_FINITE', 'TIME_BACK', 'OdometryBuffer']

ACCEPTED = ''
NOT_FINITE = 'not_finite'
JUMP = 'jump'
TIME_BACK = 'time_back'


class OdometryBuffer:
    """The recent planar odometry poses, interpolated at any stamp in between.

    Args:
        horizon_s: How much history to keep, seconds.
        max_jump_m: Largest distance between consecutive messages; further is a jump.
        max_extrapolation_s: How far past the newest message (or before the oldest) a
            stamp may lie and still get a pose.

    Example:
        >>> buffer = OdometryBuffer()
        >>> _ = buffer.add(0, np.zeros(3)), buffer.add(100_000_000, np.array([0.1, 0, 0]))
        >>> buffer.at(50_000_000).round(3).tolist()
        [0.05, 0.0, 0.0]
    """

    def __init__(self, horizon_s: float = 2.0, max_jump_m: float = 1.0,
                 max_extrapolation_s: float = 0.1) -> None:
        self.horizon_ns = int(horizon_s * 1e9)
        self.max_jump_m = float(max_jump_m)
        self.max_extrapolation_ns = int(max_extrapolation_s * 1e9)
        self._stamps: deque[int] = deque()
        self._poses: deque[np.ndarray] = deque()
        self._pending: tuple[int, np.ndarray] | None = None

    def __len__(self) -> int:
        return len(self._stamps)

    @property
    def latest_stamp(self) -> int | None:
        """Stamp of the newest accepted message, or None."""
        return self._stamps[-1] if self._stamps else None

    def clear(self) -> None:
        """Forget everything."""
        self._stamps.clear()
        self._poses.clear()
        self._pending = None

    def add(self, stamp_ns: int, pose: np.ndarray) -> str:
        """Add one message; return :data:`ACCEPTED` or why it restarted the buffer.

        Args:
            stamp_ns: The message's stamp.
            pose: (3,) ``(x, y, yaw)`` of ``base_link`` in ``odom``.

        Returns:
            ``ACCEPTED`` (``''``), ``NOT_FINITE``, ``JUMP`` or ``TIME_BACK``. After a jump
            or time going back the message is kept as the candidate start of a new track.
        """
        pose = np.asarray(pose, float).reshape(3)
        if not np.all(np.isfinite(pose)):
            self.clear()
            return NOT_FINITE
        last = (self._stamps[-1], self._poses[-1]) if self._stamps else self._pending
        if last is None:
            self._pending = (stamp_ns, pose)
            return ACCEPTED
        if stamp_ns < last[0]:
            self.clear()
            self._pending = (stamp_ns, pose)
            return TIME_BACK
        if math.hypot(*(pose[:2] - last[1][:2])) > self.max_jump_m:
            self.clear()
            self._pending = (stamp_ns, pose)
            return JUMP
        if not self._stamps:
            self._stamps.append(last[0])
            self._poses.append(last[1])
            self._pending = None
        if stamp_ns == self._stamps[-1]:
            self._poses[-1] = pose
        else:
            self._stamps.append(stamp_ns)
            self._poses.append(pose)
        while len(self._stamps) > 2 and stamp_ns - self._stamps[0] > self.horizon_ns:
            self._stamps.popleft()
            self._poses.popleft()
        return ACCEPTED

    def at(self, stamp_ns: int) -> np.ndarray | None:
        """Return the pose at ``stamp_ns``, or None outside what the buffer covers."""
        if not self._stamps:
            return None
        stamps = self._stamps
        if stamp_ns <= stamps[0]:
            return self._poses[0].copy() if stamps[0] - stamp_ns <= \
                self.max_extrapolation_ns else None
        if stamp_ns >= stamps[-1]:
            if stamp_ns - stamps[-1] > self.max_extrapolation_ns:
                return None
            if len(stamps) < 2 or stamp_ns == stamps[-1]:
                return self._poses[-1].copy()
            return _interpolate(stamps[-2], self._poses[-2], stamps[-1], self._poses[-1],
                                stamp_ns)
        i = int(np.searchsorted(np.fromiter(stamps, np.int64, len(stamps)), stamp_ns))
        return _interpolate(stamps[i - 1], self._poses[i - 1], stamps[i], self._poses[i],
                            stamp_ns)


def _interpolate(t0: int, a: np.ndarray, t1: int, b: np.ndarray, t: int) -> np.ndarray:
    """Pose at ``t`` on the line through ``(t0, a)`` and ``(t1, b)`` (yaw: shorter arc)."""
    s = (t - t0) / (t1 - t0)
    turn = math.remainder(float(b[2] - a[2]), math.tau)
    yaw = math.remainder(float(a[2]) + s * turn, math.tau)
    return np.array([a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), yaw])
