"""What the localizer takes and gives per frame: :class:`Frame`, :class:`Estimate`, :class:`Stats`.

The state machine that turns one into the other is :mod:`landmark_localizer.localizer`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vbn_common.images import MAX_EXPOSURE_GAIN, exposed

__all__ = ['MAX_EXPOSURE_GAIN', 'Estimate', 'Frame', 'Stats', 'exposed', 'pose_quality']

@dataclass(frozen=True)
class Frame:
    """One camera image and what else is known at its time.

    Attributes:
        stamp_ns: The image's stamp.
        image: (H, W) uint8 grey image.
        odom: (3,) ``odom -> base_link`` planar pose at the image's stamp, or None.
    """

    stamp_ns: int
    image: np.ndarray
    odom: np.ndarray | None = None


@dataclass(frozen=True)
class Estimate:
    """What one step found.

    Attributes:
        stamp_ns: The frame's stamp.
        state: ``LOST`` or ``TRACKING`` after the step.
        region: The current region, -1 when lost.
        pose: (3,) ``base_link`` pose in ``map``, or None (no trustworthy pose).
        covariance: (3, 3) covariance of ``(x, y, yaw)``, or None.
        camera_pose: (3,) the camera's pose in ``map``, or None.
        two_view_pose: (3,) the ``base_link`` pose the model views gave (7.4, 7.5)
            before any refinement on 3-D points, where the pose came from them.
        tracked: Region features used this frame.
        event: ``'vote'``, ``'predicted_switch'``, ``'neighbour_vote'`` or
            ``'global_vote'`` (a region change after the features were lost),
            ``'absolute'`` (a pose from the class points while lost), ``'odometry'``
            (bridged by the odometry, :mod:`.bridging`), ``'lost'``, ``'reset'`` or ``''``.
        seconds: Time the step took.
    """

    stamp_ns: int
    state: str
    region: int
    pose: np.ndarray | None
    covariance: np.ndarray | None
    camera_pose: np.ndarray | None
    tracked: int
    event: str
    seconds: float
    two_view_pose: np.ndarray | None = None


@dataclass
class Stats:
    """Counters over the run."""

    frames: int = 0
    poses: int = 0
    votes: int = 0
    predicted_switches: int = 0
    lost_switches: int = 0
    falls_to_lost: int = 0
    resets: int = 0
    absolute_poses: int = 0
    bridged: int = 0
    events: dict[str, int] = field(default_factory=dict)


def pose_quality(estimate: Estimate | None) -> str:
    """Return what a supervisor can act on for the last frame (``/diagnostics`` ``quality``).

    ``'good'``: a pose from the images; ``'odometry'``: the last pose from the images
    carried by the odometry (:mod:`landmark_localizer.bridging`), its covariance growing
    with the path: trust it less as it does, and slow down; ``'lost'``: no pose (none
    trustworthy, or one withheld because it contradicts the odometry): stop, or give
    ``/initialpose``.

    Example:
        >>> pose_quality(None)
        'lost'
    """
    if estimate is None or estimate.pose is None:
        return 'lost'
    return 'odometry' if estimate.event == 'odometry' else 'good'
