"""What the robot drove and turned between its images, from the bag's ``/odom`` stream.

An odometry's error grows with the path it integrates, not with the straight line
between its ends (the motion model of any odometry, Thrun et al., Probabilistic
Robotics, Section 5.4): a drive through a door and round a corner is metres and half a
turn of wheel motion between two images 1.5 m apart. Judged by the straight line, the
odometry's relative poses on the 0.75 m floor missed the truth by up to 13.6 of their
standard deviations (43 cm on 1.5 m, 8.5 degrees), and their pull moved whole rooms
by 8 to 12 cm. :func:`odometry_steps` integrates ``/odom`` between consecutive images:
the path's length and its total turning set each step's standard deviations
(:func:`step_stds`) in the fits (:mod:`.global_fit`), the bundle adjustment and the
bound on joining pieces (:mod:`.linking`).
"""
from __future__ import annotations

import logging
import os
from typing import TYPE_CHECKING

import numpy as np

from vbn_common import names
from vbn_common.bags import open_bag
from vbn_common.errors import VbnCommonError
from vbn_common.geometry.frames import quaternion_yaw, wrap_angle

if TYPE_CHECKING:
    from visibility_builder.estimation.pipeline import EstimationSettings

__all__ = ['odometry_steps', 'read_track', 'samples_at', 'step_stds', 'straight_steps',
           'track_steps']

_LOG = logging.getLogger(__name__)
_TYPES = ('nav_msgs/msg/Odometry', 'geometry_msgs/msg/PoseStamped',
          'geometry_msgs/msg/PoseWithCovarianceStamped')


def straight_steps(poses: np.ndarray) -> np.ndarray:
    """Return ``(n - 1, 2)`` metres and radians between consecutive ``(x, y, yaw)`` poses.

    The straight line and the net turn: what the images' own odometry poses say when the
    bag has no odometry stream between them (a lower bound on the path).
    """
    poses = np.asarray(poses, float)
    return np.stack([np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1),
                     np.abs(wrap_angle(np.diff(poses[:, 2])))], axis=1)


def read_track(bag: str | os.PathLike[str], topic: str = names.ODOM) -> np.ndarray | None:
    """Return the odometry stream ``(m, 4)`` ``(stamp_ns, x, y, yaw)`` in time order.

    None (and a log line saying why) when the bag has no such stream, it cannot be read,
    or it holds fewer than two samples.
    """
    samples: list[tuple[int, float, float, float]] = []
    try:
        with open_bag(bag) as reader:
            if topic not in reader.topics or reader.topics[topic].msgtype not in _TYPES:
                _LOG.info('%s: no odometry stream on %s; steps are the straight lines '
                          'between images', bag, topic)
                return None
            for _, msgtype, bag_ns, raw in reader.messages(topics=[topic]):
                msg = reader.deserialize(raw, msgtype)
                pose = getattr(msg.pose, 'pose', msg.pose)
                q = pose.orientation
                stamp = int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)
                samples.append((stamp or bag_ns, float(pose.position.x),
                                float(pose.position.y),
                                float(quaternion_yaw((q.x, q.y, q.z, q.w)))))
    except VbnCommonError as error:
        _LOG.warning('%s: odometry stream unreadable (%s); steps are the straight lines '
                     'between images', bag, error)
        return None
    if len(samples) < 2:
        return None
    return np.array(sorted(samples))


def odometry_steps(bag: str | os.PathLike[str], stamps_ns: np.ndarray,
                   poses: np.ndarray, topic: str = names.ODOM) -> np.ndarray:
    """Return ``(n - 1, 2)`` path length (m) and total turning (rad) between images.

    The ``/odom`` samples between the stamps of consecutive images (and the images' own
    odometry poses at either end) are integrated: the sum of their planar steps and of
    their absolute turns. Where the stream has no sample between two images (or the bag
    no stream) the straight line and net turn between ``poses`` are kept: never less
    than them.

    Args:
        bag: The exploration bag.
        stamps_ns: ``(n,)`` image stamps, non-decreasing.
        poses: ``(n, 3)`` the images' odometry poses ``(x, y, yaw)`` of ``base_link``.
        topic: The odometry topic.
    """
    return track_steps(read_track(bag, topic), stamps_ns, poses)


def samples_at(track: np.ndarray, stamps_ns: np.ndarray) -> np.ndarray:
    """Return the index of the last sample of ``track`` at or before each stamp (-1: none)."""
    return np.searchsorted(track[:, 0].astype(np.int64), np.asarray(stamps_ns, np.int64),
                           side='right') - 1


def track_steps(track: np.ndarray | None, stamps_ns: np.ndarray,
                poses: np.ndarray) -> np.ndarray:
    """Return :func:`odometry_steps` from a stream already read (:func:`read_track`)."""
    straight = straight_steps(poses)
    if track is None:
        return straight
    step_len = np.linalg.norm(np.diff(track[:, 1:3], axis=0), axis=1)
    step_turn = np.abs(wrap_angle(np.diff(track[:, 3])))
    cum_len = np.concatenate([[0.0], np.cumsum(step_len)])
    cum_turn = np.concatenate([[0.0], np.cumsum(step_turn)])
    # Sample index at or before each image stamp; the path between two images is the
    # cumulative difference of the samples inside their interval.
    at = samples_at(track, stamps_ns)
    inside = np.clip(at, 0, len(track) - 1)
    path = np.stack([np.diff(cum_len[inside]), np.diff(cum_turn[inside])], axis=1)
    path[(at[1:] < 0) | (at[:-1] < 0)] = 0.0
    return np.maximum(path, straight)


def step_stds(steps: np.ndarray, settings: EstimationSettings
              ) -> tuple[np.ndarray, np.ndarray]:
    """Return the standard deviations of odometry steps' displacement (m) and turn (rad).

    ``steps`` ``(k, 2)`` are the path lengths and turnings (:func:`odometry_steps`). The
    turn's deviation grows with the turning and the path (``odometry_turn_std``,
    ``odometry_yaw_drift_std``), the displacement's with the path
    (``odometry_std_per_m``). (A term across the displacement for the heading error of
    the step's turns, tried: the shaking room's images 1.82 -> 3.22 cm at most.)
    """
    driven, turned = steps[:, 0], steps[:, 1]
    sig_yaw = settings.odometry_yaw_floor + settings.odometry_turn_std * turned + \
        settings.odometry_yaw_drift_std * driven
    return settings.odometry_std_floor_m + settings.odometry_std_per_m * driven, sig_yaw
