"""The estimate's scale: the wheels calibrated by the images' turns, or a known distance.

Images measure no length (thesis 6.1.4: the positions are a null vector, known up to
scale), so the odometry sets the estimate's scale, and with it each wheel's constant
calibration error: a wheel 0.3 % larger than its nominal size makes the whole map 0.15 %
larger, 1.5 cm at 10 m, more than every other error of the estimate (beyond the thesis).

**The images' turns calibrate the wheels.** A differential-drive odometry measures each
wheel's travel as ``s_r r`` and ``s_l l`` (``r``, ``l`` the true travels, ``s`` the
wheels' scale errors) and reports ``v_m = (s_l l + s_r r) / 2`` and ``w_m = (s_r r -
s_l l) / b``. Solved for the true motion, with ``a = 1 / s_r`` and ``c = 1 / s_l``::

    w = p w_m + q v_m            v = p v_m + q (b^2 / 4) w_m
    p = (a + c) / 2              q = (a - c) / b

so the factor ``p`` that turns the odometry's distances into true ones is the same that
turns its turns into true ones. The images measure turns to a hundredth of a degree:
between consecutive images, ``true turn = p * odometry turn + q * odometry distance`` is
one linear equation, and the exploration's segments (each turn on the way to the next
place) give ``p`` to a few hundredths of a percent (:func:`calibrate_wheels`;
UMBmark-style calibration, Borenstein and Feng 1996, with the images as the reference).
The odometry is then integrated again with ``p`` and ``q`` (:func:`recalibrated_poses`);
the term ``q b^2 / 4`` (a fraction of a millimetre per turn) is left out, so the wheel
base need not be known.

It assumes the odometry's turns come from its wheels with a right wheel base. An
odometry whose heading is a gyro's, or a wrong wheel base, shows as turns that disagree
with the images by more than a wheel's error: beyond :data:`MAX_TURN_ERROR` the
odometry's distances are kept and a warning says why (``EstimationSettings.
wheel_calibration`` turns it off).

**A known distance** (:func:`scaled_to_distance`): a distance the user measured between
two places of the exploration (the thesis's own way where there is no odometry) fixes
the scale whatever the odometry.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math
from typing import TYPE_CHECKING

import numpy as np

from vbn_common.geometry.frames import compose_poses, invert_pose, wrap_angle
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.estimation.odometry_path import samples_at

if TYPE_CHECKING:
    from visibility_builder.estimation.pipeline import PoseEstimation

__all__ = ['MAX_TURN_ERROR', 'WheelCalibration', 'calibrate_wheels', 'check_known_distance',
           'recalibrated_poses', 'scaled_to_distance', 'signed_motion', 'turn_sigmas']

#: Turns of the odometry more than this share off the images' are not a wheel's error.
MAX_TURN_ERROR = 0.05
#: The calibration is used when its scale's standard deviation is at most this, or when
#: the correction it makes is at least :data:`SIGNIFICANT` of them (the wheels measurably off).
MAX_SCALE_STD = 0.0025
SIGNIFICANT = 3.0
#: ... and the segments used turn at least this much in all, radians.
MIN_TURNED_RAD = 2.0 * math.pi
#: Segments whose turn misses the fit by more than this many robust deviations are left out.
OUTLIER_SIGMAS = 4.0
#: Metres of wheel travel per radian turned in place (half a typical wheel base), for the
#: weights: a wheel's noise grows with its travel, driven or turned.
TRAVEL_PER_RAD = 0.2


@dataclass(frozen=True)
class WheelCalibration:
    """The odometry's scale measured by the images' turns (module docstring).

    Attributes:
        distance_scale: ``p``, true metres per metre of the odometry (and true radians per
            radian turned).
        turn_per_metre: ``q``, true radians turned per metre the odometry drove (the
            wheels' difference).
        distance_scale_std: standard deviation of ``p``.
        segments: consecutive image pairs used.
        rejected: segments left out as outliers.
        turned_rad: total turn of the segments used, radians.
        applied: whether the odometry was integrated again with ``p`` and ``q``.
        note: why not, when not.
    """

    distance_scale: float
    turn_per_metre: float
    distance_scale_std: float
    segments: int
    rejected: int
    turned_rad: float
    applied: bool
    note: str = ''

    def line(self) -> str:
        """Return one line for the command's output."""
        what = (f'distances x {self.distance_scale:.5f} (+- {100 * self.distance_scale_std:.3f} '
                f'%), {math.degrees(self.turn_per_metre):+.3f} deg per metre, from '
                f'{self.segments} segments turning {math.degrees(self.turned_rad):.0f} deg'
                + (f' ({self.rejected} left out)' if self.rejected else ''))
        return f'wheels calibrated by the images: {what}' if self.applied else \
            f'wheels not calibrated ({self.note}): {what}'


def _signed_increments(track: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return each odometry step's forward distance, turn and mid heading."""
    turn = wrap_angle(np.diff(track[:, 3]))
    mid = track[:-1, 3] + 0.5 * turn
    delta = np.diff(track[:, 1:3], axis=0)
    forward = delta[:, 0] * np.cos(mid) + delta[:, 1] * np.sin(mid)
    return forward, turn, mid


def signed_motion(track: np.ndarray, stamps_ns: np.ndarray) -> np.ndarray:
    """Return ``(n - 1, 2)`` the odometry's signed distance (m) and turn (rad) between images.

    ``track`` ``(m, 4)`` is the odometry stream ``(stamp_ns, x, y, yaw)`` in time order
    (:func:`~.odometry_path.read_track`). Distances are forward along the robot's heading;
    turns are summed step by step, so a turn beyond half a circle keeps its size. NaN
    where an image comes before the first sample.
    """
    track = np.asarray(track, float)
    forward, turn, _ = _signed_increments(track)
    cum = np.stack([np.concatenate([[0.0], np.cumsum(forward)]),
                    np.concatenate([[0.0], np.cumsum(turn)])], axis=1)
    at = samples_at(track, stamps_ns)
    out = np.diff(cum[np.clip(at, 0, None)], axis=0)
    out[(at[1:] < 0) | (at[:-1] < 0)] = np.nan
    return out


def turn_sigmas(steps: np.ndarray) -> np.ndarray:
    """Return each segment's relative turn noise: the square root of its wheels' travel.

    ``steps`` ``(n - 1, 2)`` are the path driven (m) and turned (rad) between images
    (:func:`~.odometry_path.odometry_steps`). A wheel's per-sample noise adds up over its
    travel; a turn in place moves each wheel about :data:`TRAVEL_PER_RAD` per radian. Only
    the ratios matter (the fit's residuals set the scale): a model that grew with the
    turn alone gave the straight drives, which say nothing of ``p``, all the weight.
    """
    steps = np.asarray(steps, float)
    return np.sqrt(steps[:, 0] + TRAVEL_PER_RAD * steps[:, 1] + 0.01)


def calibrate_wheels(image_yaw: np.ndarray, motion: np.ndarray, usable: np.ndarray,
                     sigma: np.ndarray) -> WheelCalibration:
    """Fit ``true turn = p * odometry turn + q * odometry distance`` (module docstring).

    Args:
        image_yaw: ``(n,)`` the images' estimated headings (any constant offset).
        motion: ``(n - 1, 2)`` :func:`signed_motion` between consecutive images.
        usable: ``(n - 1,)`` segments whose two images were estimated together.
        sigma: ``(n - 1,)`` the odometry turn's relative noise per segment
            (:func:`turn_sigmas`; weights).

    Returns:
        The calibration; ``applied`` says whether it is good enough to use.
    """
    image_yaw = np.asarray(image_yaw, float)
    motion = np.asarray(motion, float)
    odo_turn, odo_dist = motion[:, 1], motion[:, 0]
    seen = np.diff(image_yaw)
    ok = np.asarray(usable, bool) & np.isfinite(seen) & np.isfinite(motion).all(axis=1) & \
        np.isfinite(sigma) & (np.asarray(sigma) > 0)
    true_turn = odo_turn + wrap_angle(seen - odo_turn)      # the odometry resolves the turns
    weight = 1.0 / np.where(ok, sigma, 1.0)
    keep = ok.copy()
    p, q, std = 1.0, 0.0, math.inf
    for _ in range(4):
        if keep.sum() < 3:
            break
        design = np.stack([odo_turn, odo_dist], axis=1)[keep] * weight[keep, None]
        target = true_turn[keep] * weight[keep]
        (p, q), *_ = np.linalg.lstsq(design, target, rcond=None)
        residual = (true_turn - p * odo_turn - q * odo_dist) * weight
        spread = 1.4826 * float(np.median(np.abs(residual[keep]))) + 1e-12
        new_keep = ok & (np.abs(residual) <= OUTLIER_SIGMAS * spread)
        dof = max(int(keep.sum()) - 2, 1)
        normal = design.T @ design
        chi2 = float(np.sum(residual[keep] ** 2)) / dof
        std = math.sqrt(chi2 * float(np.linalg.pinv(normal)[0, 0]))
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    turned = float(np.abs(odo_turn[keep]).sum()) if keep.any() else 0.0
    note = ''
    if keep.sum() < 10 or turned < MIN_TURNED_RAD:
        note = (f'the images turn {math.degrees(turned):.0f} deg over {int(keep.sum())} '
                f'segments, at least {math.degrees(MIN_TURNED_RAD):.0f} deg over 10 needed')
    elif std > MAX_SCALE_STD and abs(p - 1.0) < SIGNIFICANT * std:
        note = (f'the turns give the scale to {100 * std:.2f} %, and its correction is '
                f'within {SIGNIFICANT:g} of that')
    elif abs(p - 1.0) > MAX_TURN_ERROR:
        note = (f"the odometry's turns are {100 * (1 / p - 1):+.1f} % off the images': more "
                "than a wheel's error (a gyro's heading, a wrong wheel base?); its "
                'distances are kept')
    return WheelCalibration(float(p), float(q), float(std), int(keep.sum()),
                            int(ok.sum() - keep.sum()), turned, not note, note)


def recalibrated_poses(track: np.ndarray, stamps_ns: np.ndarray, poses: np.ndarray,
                       calibration: WheelCalibration) -> np.ndarray:
    """Return the images' odometry poses integrated again with the calibrated wheels.

    Each odometry step's forward distance becomes ``p`` times itself and its turn ``p``
    times itself plus ``q`` times the distance; the track is integrated again (exact
    arcs) and carried to each image's stamp (the image's own pose relative to the sample
    before it is kept). The first image keeps its pose: ``map`` stays the odometry's
    frame at the first image.

    Args:
        track: ``(m, 4)`` the odometry stream ``(stamp_ns, x, y, yaw)``.
        stamps_ns: ``(n,)`` the images' stamps.
        poses: ``(n, 3)`` the images' odometry poses.
        calibration: from :func:`calibrate_wheels`.
    """
    track = np.asarray(track, float)
    poses = np.asarray(poses, float)
    p, q = calibration.distance_scale, calibration.turn_per_metre
    forward, turn, _ = _signed_increments(track)
    new_forward = p * forward
    new_turn = p * turn + q * forward
    yaw = track[0, 3] + np.concatenate([[0.0], np.cumsum(new_turn)])
    mid = yaw[:-1] + 0.5 * new_turn
    with np.errstate(invalid='ignore', divide='ignore'):
        chord = np.where(np.abs(new_turn) > 1e-9, np.sin(new_turn / 2) / (new_turn / 2), 1.0)
    x = track[0, 1] + np.concatenate([[0.0], np.cumsum(new_forward * chord * np.cos(mid))])
    y = track[0, 2] + np.concatenate([[0.0], np.cumsum(new_forward * chord * np.sin(mid))])
    new_track = np.stack([x, y, wrap_angle(yaw)], axis=1)
    at = samples_at(track, stamps_ns)
    out = poses.copy()
    ok = at >= 0
    offset = compose_poses(invert_pose(track[at[ok], 1:]), poses[ok])
    out[ok] = compose_poses(new_track[at[ok]], offset)
    move = compose_poses(poses[0], invert_pose(out[0]))     # the first image stays put
    return compose_poses(move, out).reshape(-1, 3)


def check_known_distance(count: int, first: int, second: int, metres: float) -> None:
    """Raise unless images ``first`` and ``second`` of ``count`` can be ``metres`` apart."""
    if not (0 <= first < count and 0 <= second < count) or first == second:
        raise VisibilityBuilderError(f'--known-distance: {count} images; two different ones '
                                     f'are needed, got {first} and {second}')
    if not (math.isfinite(metres) and metres > 0):
        raise VisibilityBuilderError(f'--known-distance: the distance must be positive, got '
                                     f'{metres}')


def scaled_to_distance(result: PoseEstimation, first: int, second: int,
                       metres: float) -> PoseEstimation:
    """Return ``result`` scaled so that images ``first`` and ``second`` are ``metres`` apart.

    Every estimated position is scaled about the first image's (which stays the ``map``
    origin's pose); the headings are unchanged (a similarity keeps every bearing and
    reprojection). Measured on the room at three times the default drift before the
    wheels were calibrated: the odometry's path came out 0.14 % short and so did the
    estimate, 0.23 cm median of error of which 0.03 cm remain after a similarity
    alignment.

    Raises:
        VisibilityBuilderError: an image index out of range, the same image twice, a
            distance that is not positive, or images without an estimate or at one
            place.
    """
    check_known_distance(len(result.base_poses), first, second, metres)
    base = result.base_poses
    if not (np.isfinite(base[first]).all() and np.isfinite(base[second]).all()):
        raise VisibilityBuilderError(f'image {first} or {second} has no estimated pose')
    estimated = float(np.linalg.norm(base[second, :2] - base[first, :2]))
    if estimated < 1e-6:
        raise VisibilityBuilderError(f'images {first} and {second} were estimated at one '
                                     'place: they cannot give the scale')
    factor = metres / estimated
    origin = base[0, :2].copy()

    def scale(poses: np.ndarray) -> np.ndarray:
        out = np.array(poses, float, copy=True)
        out[:, :2] = origin + factor * (out[:, :2] - origin)
        return out

    return replace(result, base_poses=scale(result.base_poses),
                   thesis_poses=scale(result.thesis_poses),
                   joint_poses=scale(result.joint_poses),
                   unrefined_poses=scale(result.unrefined_poses))
