"""Frames without a pose from the images, bridged by the odometry.

Not in the thesis. Where the images give no trustworthy pose (the region's features
hidden by a person, posters taken down, a frame dropped under load), a navigation stack
still needs one, with an honest covariance: the last pose the images gave (the anchor)
moved by the odometry since, its covariance carried through the composition and grown
by the odometry's error over the path driven and turned since the anchor, as AMCL's
motion model does between its updates. Bridging stops, and the localizer reports no
pose, once the position's standard deviation passes ``bridge_max_std_m`` or the anchor
is older than ``bridge_max_s``. The same prediction joins each pose from the images
(:meth:`OdometryBridge.fuse`): their weighted mean where they agree, and where they
disagree beyond their joint uncertainty, the image's pose with its covariance grown by
the disagreement.

The odometry's error model (per metre driven: ``bridge_std_per_m`` of the distance
along and across, ``bridge_yaw_deg_per_m`` of heading; per radian turned:
``bridge_yaw_std_per_rad``) is deliberately wider than a wheel's usual 1 to 2 %: a
covariance that claims less than it knows is what must never be. 8 % per metre
keeps a wheel slipping by 20 % for a stretch within 2.5 standard deviations (a run with
three such bursts and three 1 s odometry dropouts: 97.8 % of its poses within 3 sigma
at 8 %, 96.4 % at 5 %).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from landmark_localizer.config import LocalizerConfig
from vbn_common.geometry.frames import compose_poses, invert_pose, wrap_angle

__all__ = ['INNOVATION_LIMIT', 'SHARPER', 'BridgeModel', 'OdometryBridge', 'search_prior']

#: The 99.9 % quantile of the chi-square distribution with three degrees of freedom.
INNOVATION_LIMIT = 16.27
#: A pose from the images that contradicts the odometry is sharp (a rival, which the next
#: frame may confirm) when its standard deviation is less than this share of the
#: odometry's prediction's.
SHARPER = 0.5


@dataclass(frozen=True)
class BridgeModel:
    """The odometry's error per metre and per radian, and how long to bridge.

    Attributes:
        std_per_m: Position error per metre driven, along and across (fraction).
        yaw_deg_per_m: Heading error per metre driven, degrees.
        yaw_std_per_rad: Heading error per radian turned (fraction).
        max_std_m: Stop bridging beyond this position standard deviation (0: never
            bridge).
        max_s: ... or this long after the anchor, seconds.
    """

    std_per_m: float = 0.05
    yaw_deg_per_m: float = 2.0
    yaw_std_per_rad: float = 0.05
    max_std_m: float = 0.15
    max_s: float = 5.0

    @classmethod
    def of(cls, config: LocalizerConfig) -> BridgeModel:
        """Return the model a localizer's settings give (``bridge_*``)."""
        return cls(config.bridge_std_per_m, config.bridge_yaw_deg_per_m,
                   config.bridge_yaw_std_per_rad, config.bridge_max_std_m, config.bridge_max_s)


class OdometryBridge:
    """Carries the last pose from the images by the odometry (module docstring)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the anchor (a reset, a kidnapping, an odometry restart)."""
        self._anchor: tuple[int, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._last_odom: np.ndarray | None = None
        self.path_m = 0.0
        self.turn_rad = 0.0
        self._rival: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.doubt: np.ndarray | None = None

    def settle(self) -> None:
        """Forget the doubt a vote against the odometry left (:meth:`fuse`)."""
        self.doubt = None

    def anchor(self, stamp_ns: int, pose: np.ndarray, covariance: np.ndarray,
               odom: np.ndarray | None) -> None:
        """Take a pose from the images (with its odometry pose) as the new anchor."""
        if odom is None or not np.all(np.isfinite(odom)):
            self.reset()
            return
        self._anchor = (stamp_ns, np.asarray(pose, float).copy(),
                        np.asarray(covariance, float).copy(), np.asarray(odom, float).copy())
        self._last_odom = self._anchor[3]
        self.path_m = self.turn_rad = 0.0

    def bridge(self, stamp_ns: int, odom: np.ndarray | None, model: BridgeModel
               ) -> tuple[np.ndarray, np.ndarray] | None:
        """Return ``(pose, covariance)`` now by the odometry, or None (nothing to bridge).

        Every call integrates the path and the turn since the previous one, so call it
        on every frame without a pose from the images.
        """
        predicted = self._predict(stamp_ns, odom, model, commit=True)
        return None if predicted is None else (predicted[0], self._doubted(predicted[1]))

    def predict(self, stamp_ns: int, odom: np.ndarray | None, model: BridgeModel,
                bounded: bool = True) -> tuple[np.ndarray, np.ndarray] | None:
        """Return ``(pose, covariance)`` the odometry predicts now, without moving on.

        ``bounded``: None once bridging would stop (``max_std_m``, ``max_s``); otherwise
        the prediction however wide and old (a prior to search near).
        """
        return self._predict(stamp_ns, odom, model, commit=False, bounded=bounded)

    def fuse(self, stamp_ns: int, pose: np.ndarray, covariance: np.ndarray,
             odom: np.ndarray | None, model: BridgeModel, fresh: bool = False,
             weak: bool = False
             ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        """Return a pose from the images joined with the odometry's prediction of it.

        The pose from the images and the anchor carried by the odometry are two
        estimates of the same pose. Where they agree (squared Mahalanobis distance of
        their difference ``nu`` at most :data:`INNOVATION_LIMIT`, the 99.9 % quantile
        with three degrees of freedom), the pose is their weighted mean (a Kalman
        update). Where they disagree one of them is wrong, and the odometry's prediction
        is the pose while the anchor stays:

        - a vague image pose (its position's standard deviation at least
          :data:`SHARPER` of the prediction's) gives way: a tracked pose drifts away
          frame after frame when a person walks across its few features (10 cm in 8
          frames on a changed room, claiming 1.5 cm) while the odometry holds;
        - a sharp one is a rival: no pose is published for that frame, and the image
          wins on the next frame that confirms it (the rival carried by the odometry
          agrees with that frame's pose): the robot was carried away, or the odometry
          slipped. One sharp wrong pose (an absolute pose 60 cm off on look-alike
          posters, claiming 0.8 cm) is never published;
        - a ``fresh`` one (a region found anew by its features' votes: the robot may
          have been carried away) wins at once, its covariance grown by ``nu nu^T``.
          Either the robot was carried or the vote found a look-alike (a changed room:
          a vote 40 cm off, and 17 tracked frames after it agreeing with it, claiming 2
          to 4 cm), and the images that follow cannot tell: ``nu nu^T`` stays on every
          published covariance (the :attr:`doubt`) until :meth:`settle` (the localizer
          settles it when the next region's features are found where the pose predicts
          them, or the state is reset);
        - a ``weak`` one (an absolute pose from the class points while no region
          verifies) neither wins nor confirms a rival: on a changed room's look-alike
          posters two consecutive absolute poses agreed on a place 60 cm off (claiming
          1.2 cm), and a robot truly carried away is found by the next votes.

        Unchanged without an anchor or once the prediction is too wide to judge by
        (``max_std_m``).

        Returns:
            ``(pose, covariance to publish, covariance to anchor on)``: the published one
            is the image's (consecutive images share their features and map points, so
            their errors are not independent, and a covariance that shrank frame after
            frame as if they were would claim more than it knows), the anchor's the
            covariance intersection of the two (for the same reason: the odometry's
            prediction carries the earlier images' errors); None for the anchor when the
            anchor stays (the prediction is the pose, or no pose: all three None).
        """
        pose = np.asarray(pose, float)
        predicted = self._predict(stamp_ns, odom, model, commit=False)
        if predicted is None:
            self._rival = None
            return pose, self._doubted(covariance), covariance
        nu = pose - predicted[0]
        nu[2] = float(wrap_angle(nu[2]))
        try:
            joint = covariance + predicted[1]
            d2 = float(nu @ np.linalg.solve(joint, nu))
            gain = predicted[1] @ np.linalg.inv(joint)
        except np.linalg.LinAlgError:
            return pose, covariance, covariance
        if d2 <= INNOVATION_LIMIT:
            self._rival = None
            fused = predicted[0] + gain @ nu
            fused[2] = float(wrap_angle(fused[2]))
            return fused, self._doubted(covariance), _intersection(covariance, predicted[1])
        sharp = np.trace(covariance[:2, :2]) < SHARPER ** 2 * np.trace(predicted[1][:2, :2])
        if fresh:
            self._rival = None
            self.doubt = np.outer(nu, nu)
            wide = covariance + self.doubt
            return pose, wide, wide
        if sharp and not weak and self._confirms(pose, covariance, odom):
            self._rival = None
            return pose, self._doubted(covariance), covariance
        held = self._predict(stamp_ns, odom, model, commit=True)
        if not sharp:
            return held[0], self._doubted(held[1]), None
        if weak:
            return None, None, None
        self._rival = (pose, covariance, np.asarray(odom, float))
        return None, None, None

    def _doubted(self, covariance: np.ndarray) -> np.ndarray:
        return covariance if self.doubt is None else covariance + self.doubt

    def _confirms(self, pose: np.ndarray, covariance: np.ndarray, odom: np.ndarray) -> bool:
        """Whether the last rival, carried by the odometry to now, agrees with ``pose``."""
        if self._rival is None:
            return False
        then, then_cov, then_odom = self._rival
        carried = compose_poses(then, compose_poses(invert_pose(then_odom), odom))
        nu = pose - carried
        nu[2] = float(wrap_angle(nu[2]))
        try:
            return float(nu @ np.linalg.solve(covariance + then_cov, nu)) <= INNOVATION_LIMIT
        except np.linalg.LinAlgError:
            return False

    def _predict(self, stamp_ns: int, odom: np.ndarray | None, model: BridgeModel,
                 commit: bool, bounded: bool = True) -> tuple[np.ndarray, np.ndarray] | None:
        if self._anchor is None or model.max_std_m <= 0 or odom is None or \
                not np.all(np.isfinite(odom)):
            return None
        stamp0, pose0, cov0, odom0 = self._anchor
        age = (stamp_ns - stamp0) / 1e9
        if age < 0:
            return None
        # The path and the turn are counted frame by frame, past the bridge's end too.
        odom = np.asarray(odom, float)
        step = compose_poses(invert_pose(self._last_odom), odom)
        path_m = self.path_m + float(np.hypot(step[0], step[1]))
        turn_rad = self.turn_rad + abs(float(wrap_angle(step[2])))
        if commit:
            self.path_m, self.turn_rad, self._last_odom = path_m, turn_rad, odom
        if bounded and age > model.max_s:
            return None
        delta = compose_poses(invert_pose(odom0), odom)
        pose = compose_poses(pose0, delta)
        c, s = math.cos(pose0[2]), math.sin(pose0[2])
        j_anchor = np.array([[1.0, 0.0, -s * delta[0] - c * delta[1]],
                             [0.0, 1.0, c * delta[0] - s * delta[1]],
                             [0.0, 0.0, 1.0]])
        j_delta = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        yaw_std = math.radians(model.yaw_deg_per_m) * path_m + model.yaw_std_per_rad * turn_rad
        # Along and across the path, and across it again by the heading's drift on the
        # way (a heading error growing along the path moves the end by a third of it).
        xy_var = (model.std_per_m * path_m) ** 2 + (path_m * yaw_std) ** 2 / 3.0
        noise = np.diag([xy_var, xy_var, yaw_std ** 2])
        cov = j_anchor @ cov0 @ j_anchor.T + j_delta @ noise @ j_delta.T
        cov = 0.5 * (cov + cov.T)
        if bounded and math.sqrt(max(cov[0, 0], cov[1, 1])) > model.max_std_m:
            return None
        return pose, cov


def search_prior(bridge: OdometryBridge, stamp_ns: int, odom: np.ndarray | None,
                 config: LocalizerConfig, mount: np.ndarray | None = None
                 ) -> tuple[np.ndarray, float, float, int] | None:
    """Return where to look for an absolute pose by the odometry, or None.

    ``(pose, radius_m, turn_rad, least inliers)``: the bridge's prediction and three of
    its standard deviations; with the camera's ``mount`` ``(x, y, yaw)`` on the base,
    the camera's pose, and a radius widened by the mount's lever arm times the turn (a
    camera 30 cm ahead of the base moves 3 cm as the base turns by 0.1 rad). While the
    bridge lasts, ``absolute_bridged_min_inliers`` suffice so near the prediction (a
    changed world leaves few of the old points: 10 right matches among 200 wrong ones);
    past its end, while three deviations stay within ``max_jump_m``,
    ``absolute_min_inliers`` (a 2 Hz camera passing a changed
    stretch otherwise finds no pose until a region verifies). None when
    ``absolute_bridged_min_inliers`` is 0, without an anchor, or when the base's three
    deviations are wider than ``max_jump_m`` (the lever arm's share is not counted).
    """
    if config.absolute_bridged_min_inliers <= 0:
        return None
    model = BridgeModel.of(config)
    for bounded, need in ((True, config.absolute_bridged_min_inliers),
                          (False, config.absolute_min_inliers)):
        predicted = bridge.predict(stamp_ns, odom, model, bounded)
        if predicted is None:
            continue
        pose, cov = predicted
        radius = 3.0 * math.sqrt(max(cov[0, 0], cov[1, 1]))
        if radius > config.max_jump_m:
            continue
        turn = 3.0 * math.sqrt(cov[2, 2])
        if mount is None:
            return pose, radius, turn, need
        lever = math.hypot(float(mount[0]), float(mount[1]))
        return compose_poses(pose, mount), radius + lever * turn, turn, need
    return None


def _intersection(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return the covariance intersection of two estimates with unknown correlation.

    ``(w a^-1 + (1 - w) b^-1)^-1`` with the weight ``w`` that minimises the position's
    variance: never smaller than what either estimate alone claims, as a Kalman update
    would be once the same image points fix pose after pose (the anchor's covariance
    then shrank frame after frame to a twentieth of a millimetre while the pose was 3 mm
    off).
    """
    try:
        inverse_a, inverse_b = np.linalg.inv(a), np.linalg.inv(b)
    except np.linalg.LinAlgError:
        return 0.5 * (b + b.T)   # a degenerate image covariance claims nothing to keep
    weights = np.linspace(0.0, 1.0, 11)[:, None, None]
    try:   # the eleven weights at once; one by one where one of them is singular
        joined = np.linalg.inv(weights * inverse_a + (1.0 - weights) * inverse_b)
    except np.linalg.LinAlgError:
        found = [_inverse(w * inverse_a + (1.0 - w) * inverse_b) for w in weights]
        joined = np.stack([np.full_like(a, np.nan) if m is None else m for m in found])
    # The first weight of the smallest position variance, where it is below a's.
    traces = joined[:, 0, 0] + joined[:, 1, 1]
    traces[~np.isfinite(traces)] = np.inf
    k = int(np.argmin(traces))
    best = joined[k] if traces[k] < a[0, 0] + a[1, 1] else a
    return 0.5 * (best + best.T)


def _inverse(matrix: np.ndarray) -> np.ndarray | None:
    """Return the inverse of ``matrix``, or None where it is singular."""
    try:
        return np.linalg.inv(matrix)
    except np.linalg.LinAlgError:
        return None

