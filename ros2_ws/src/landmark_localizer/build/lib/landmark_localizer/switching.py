"""Switching region by predicted motion, before the features fade (thesis 7.1).

"Before a motion command is executed, the current location and direction of motion of
the robot should be used to predict the position to which the robot will arrive ...
If such a position is near the boundary of the current region or outside of it
altogether, the robot should switch, before moving, to a region that contains both the
current and the predicted new position ... If more than one region containing both
positions exist, the one that spans most of the path that the robot will follow should
be selected."

:class:`MotionPredictor` predicts from odometry when there is some (the change of the
``odom -> base_link`` pose over the last frames, rotated into ``map``), else from the
history of estimated poses (constant velocity over the last half second).
:func:`choose_region` applies the rule above on the sampled poses: "near the boundary"
means a sampled pose outside the region within ``border_margin`` grid spacings of the
predicted position; the path is sampled from the current position to twice the
prediction, and each candidate scores the samples whose nearest pose it contains.

In a heading pose space (cameras that do not see all around) a turn is a step in the
pose space like a move: where the pose graph joins neighbouring sectors (the builder's
``sampling.turns``) regions span turns and the rule applies as written. Where the
sectors are layers of their own (the default) no region holds two sectors and a turn
into the next sector has no region "containing both positions": the candidates are then
the regions of the predicted pose, and the switch happens while the current region still
gives the pose (the turn's make before break).
"""
from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from landmark_localizer.index import DatabaseIndex
from vbn_common.geometry.frames import compose_poses, invert_pose

__all__ = ['MotionPredictor', 'TrackedCounts', 'choose_region']


class MotionPredictor:
    """Predicts the robot's position ahead of time.

    Args:
        history_s: Length of the pose history for the constant-velocity model.
    """

    def __init__(self, history_s: float = 0.5) -> None:
        self.history_s = history_s
        self.poses: deque[tuple[int, np.ndarray]] = deque()
        self.odom: deque[tuple[int, np.ndarray]] = deque()

    def reset(self) -> None:
        """Forget the history (a jump in time or position)."""
        self.poses.clear()
        self.odom.clear()

    def add(self, stamp_ns: int, pose: np.ndarray | None, odom: np.ndarray | None) -> None:
        """Record the estimated base pose and the odometry pose of a frame."""
        for queue, value in ((self.poses, pose), (self.odom, odom)):
            if value is None or not np.all(np.isfinite(value)):
                continue
            queue.append((stamp_ns, np.asarray(value, float)))
            while len(queue) > 2 and (stamp_ns - queue[0][0]) / 1e9 > self.history_s:
                queue.popleft()

    def velocity(self) -> np.ndarray | None:
        """(vx, vy, vyaw) in ``map`` per second, or None without enough history."""
        # The odometry's velocity where it reaches the last pose (not across a dropout).
        if len(self.odom) >= 2 and len(self.poses) >= 1 and \
                self.odom[-1][0] == self.poses[-1][0]:
            (t0, a), (t1, b) = self.odom[0], self.odom[-1]
            dt = (t1 - t0) / 1e9
            if dt > 0:
                delta = compose_poses(invert_pose(a), b)  # motion in the odom base frame
                yaw = self.poses[-1][1][2]
                c, s = np.cos(yaw - delta[2]), np.sin(yaw - delta[2])
                return np.array([c * delta[0] - s * delta[1], s * delta[0] + c * delta[1],
                                 delta[2]]) / dt
        if len(self.poses) >= 2:
            (t0, a), (t1, b) = self.poses[0], self.poses[-1]
            dt = (t1 - t0) / 1e9
            if dt > 0:
                d = b - a
                d[2] = (d[2] + np.pi) % (2 * np.pi) - np.pi
                return d / dt
        return None

    def by_odometry(self, odom: np.ndarray | None) -> np.ndarray | None:
        """Return the base pose now: the last pose moved by the odometry since (or None).

        Exact for any motion the odometry measures, over seconds, where the constant
        velocity of :meth:`velocity` drifts; None without an odometry pose now or at the
        last pose.
        """
        if odom is None or not np.all(np.isfinite(odom)) or not self.poses or not self.odom:
            return None
        (t_pose, pose), (t_odom, then) = self.poses[-1], self.odom[-1]
        if t_pose != t_odom:
            return None
        return compose_poses(pose, compose_poses(invert_pose(then), np.asarray(odom, float)))

    def predict(self, pose: np.ndarray, horizon_s: float) -> np.ndarray:
        """Return the base pose ``horizon_s`` ahead (the pose itself without a velocity)."""
        v = self.velocity()
        if v is None:
            return np.asarray(pose, float)
        return np.asarray(pose, float) + v * horizon_s


#: Where along twice the predicted motion the candidate regions are scored.
_PATH_STEPS = np.linspace(0.0, 2.0, 9)[1:]


def choose_region(index: DatabaseIndex, region: int, current: np.ndarray,
                  predicted: np.ndarray, margin: float, tracked: Any
                  ) -> int | None:
    """Return the region to switch to before moving, or None to stay (module docstring).

    Args:
        index: The database index.
        region: The current region.
        current: The current base pose ``(x, y, yaw)``.
        predicted: The predicted base pose.
        margin: "Near the border", in grid spacings (a turn by one heading sector
            counts as one spacing).
        tracked: Per region, how many of its features are tracked now (tie-breaker;
            anything with ``get(region, default)``).
    """
    # A position alone (enough without heading sectors) is a pose at heading 0.
    current = np.r_[np.asarray(current, float)[:3], 0.0][:3]
    predicted = np.r_[np.asarray(predicted, float)[:3], 0.0][:3]
    delta = predicted - current
    delta[2] = (delta[2] + np.pi) % (2 * np.pi) - np.pi
    path = current + _PATH_STEPS[:, None] * delta
    # One query of the tree for the predicted pose, the current one and the path.
    points = index.pose_points(np.vstack([predicted, current, path]))
    _, nearest = index.tree.query(points)
    predicted_pose, current_pose, path_poses = int(nearest[0]), int(nearest[1]), nearest[2:]
    near = index.tree.query_ball_point(points[0], r=margin * index.spacing)
    if index.region_contains(region, np.r_[np.asarray(near, np.int64), predicted_pose]).all():
        return None
    ahead = index.regions_of_pose(predicted_pose)
    both = np.intersect1d(index.regions_of_pose(current_pose), ahead)
    both = both[both != region]
    if both.size == 0 and not index.same_sector(current_pose, predicted_pose):
        both = ahead[ahead != region]   # a turn into the next sector (module docstring)
    if both.size == 0:
        return None
    scores = [(int(index.region_contains(r, path_poses).sum()), tracked.get(int(r), 0),
               -int(r)) for r in both]
    best = int(np.argmax([s[0] * 1000 + s[1] for s in scores]))
    current_score = int(index.region_contains(region, path_poses).sum())
    if scores[best][0] <= current_score and index.region_contains(region, [predicted_pose])[0]:
        return None
    return int(both[best])


class TrackedCounts:
    """Per region, its features among ``class_ids``: counted only when asked (a tie)."""

    def __init__(self, index: DatabaseIndex, class_ids: np.ndarray) -> None:
        self.index, self.class_ids = index, class_ids

    def get(self, region: int, default: int = 0) -> int:
        features = self.index.regions[region].features
        return int(np.isin(features, self.class_ids).sum()) if len(features) else default
