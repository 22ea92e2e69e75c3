"""The localizer core over a recorded run, offline and as fast as it can (``vbn localize``).

:func:`localize_run` feeds every image of a :class:`~vbn_bench.localization.pose_bags.RunBag`
to one :class:`~landmark_localizer.localizer.Localizer`, in the bag's order, with the
odometry interpolated at the image's stamp (:func:`interpolate_poses`), and times each
frame as the robot would see it: deserializing and decoding the image included.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
import logging
import math
import time

import numpy as np

from landmark_localizer.camera_check import frame_camera
from landmark_localizer.errors import LocalizerError
from landmark_localizer.index import DatabaseIndex
from landmark_localizer.localizer import LOST, Estimate, Frame, Localizer
from vbn_bench.localization.evaluation import (
    VOTING_EVENTS,
    RunEvaluation,
    evaluate_run,
    latency_summary,
    pose_accuracy,
)
from vbn_bench.localization.pose_bags import PoseRecord, RunBag
from vbn_common.bags import deserialize
from vbn_common.errors import VbnCommonError
from vbn_common.geometry.camera import CameraModel
from vbn_common.geometry.frames import wrap_angle
from vbn_common.geometry.mount import tilt_angles
from vbn_common.images import decode_image

__all__ = ['OfflineRun', 'check_run_camera', 'coverage_split', 'evaluate_offline',
           'interpolate_poses', 'localize_run', 'never_recognised']

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class OfflineRun:
    """What the localizer found on every frame of a run.

    Attributes:
        estimates: One per frame, in bag order.
        decode_seconds: (n,) time to deserialize and decode each image.
        latency_seconds: (n,) decoding plus the localizer's step, wall-clock time.
        wall_seconds: The whole run.
        cpu_seconds: (n,) the same as CPU time of the process (every thread): what the
            frame costs on one core, whatever else the machine runs.
    """

    estimates: list[Estimate]
    decode_seconds: np.ndarray
    latency_seconds: np.ndarray
    wall_seconds: float
    cpu_seconds: np.ndarray | None = None

    def records(self) -> list[PoseRecord]:
        """Return the estimates as pose-bag records."""
        return [PoseRecord(e.stamp_ns, e.region, e.pose, e.covariance) for e in self.estimates]


def interpolate_poses(stamps_ns: np.ndarray, poses: np.ndarray, query_ns: np.ndarray,
                      max_gap_s: float = 0.5) -> np.ndarray:
    """Planar poses interpolated linearly in time (yaw along the shorter arc).

    Args:
        stamps_ns: (m,) sorted stamps of the poses.
        poses: (m, 3) ``(x, y, yaw)``.
        query_ns: (q,) stamps wanted.
        max_gap_s: a query further than this from the nearest pose, or between two poses
            further apart than twice this, gets NaN (no odometry there).

    Returns:
        (q, 3) poses; rows of NaN where there is no odometry.

    Example:
        >>> interpolate_poses(np.array([0, 10**9]), np.array([[0., 0, 3.1], [1, 0, -3.1]]),
        ...                   np.array([5 * 10**8])).round(3).tolist()
        [[0.5, 0.0, -3.142]]
    """
    stamps = np.asarray(stamps_ns, np.int64)
    poses = np.asarray(poses, float).reshape(-1, 3)
    query = np.asarray(query_ns, np.int64)
    out = np.full((len(query), 3), np.nan)
    if len(stamps) == 0:
        return out
    if len(stamps) == 1:
        ok = np.abs(query - stamps[0]) <= max_gap_s * 1e9
        out[ok] = poses[0]
        return out
    right = np.clip(np.searchsorted(stamps, query), 1, len(stamps) - 1)
    left = right - 1
    t0, t1 = stamps[left], stamps[right]
    span = np.maximum(t1 - t0, 1).astype(float)
    w = np.clip((query - t0) / span, 0.0, 1.0)
    p0, p1 = poses[left], poses[right]
    out[:, :2] = p0[:, :2] + w[:, None] * (p1[:, :2] - p0[:, :2])
    out[:, 2] = wrap_angle(p0[:, 2] + w * wrap_angle(p1[:, 2] - p0[:, 2]))
    nearest = np.minimum(np.abs(query - t0), np.abs(query - t1))
    bad = (nearest > max_gap_s * 1e9) | ((t1 - t0) > 2 * max_gap_s * 1e9)
    out[bad] = np.nan
    return out


def localize_run(localizer: Localizer, run: RunBag, *,
                 progress: Callable[[int, int], None] | None = None) -> OfflineRun:
    """Run the localizer over every image of a run.

    Args:
        localizer: A fresh (or reset) localizer.
        run: The run's images, odometry and ground truth.
        progress: Called with ``(frames done, frames)`` after each frame.

    Returns:
        The estimates and per-frame timings.
    """
    odom = interpolate_poses(run.odom_stamps_ns, run.odom_poses, run.stamps_ns)
    estimates: list[Estimate] = []
    decode = np.zeros(run.n_frames)
    latency = np.zeros(run.n_frames)
    cpu = np.zeros(run.n_frames)
    start = time.perf_counter()
    for i in range(run.n_frames):
        c0 = time.process_time()
        t0 = time.perf_counter()
        image = run.decode(i)
        decode[i] = time.perf_counter() - t0
        frame_odom = odom[i] if np.all(np.isfinite(odom[i])) else None
        estimate = localizer.step(Frame(int(run.stamps_ns[i]), image, frame_odom))
        latency[i] = time.perf_counter() - t0
        cpu[i] = time.process_time() - c0
        estimates.append(estimate)
        if progress is not None:
            progress(i + 1, run.n_frames)
    wall = time.perf_counter() - start
    _LOG.info('localized %d frames in %.1f s', run.n_frames, wall)
    return OfflineRun(estimates, decode, latency, wall, cpu)


def evaluate_offline(result: OfflineRun, run: RunBag, falls_to_lost: int | None = None
                     ) -> RunEvaluation:
    """Compute the figures of an offline run (accuracy against the run's ground truth).

    Args:
        result: The localizer's output.
        run: The run it localized.
        falls_to_lost: The localizer's count (``stats.falls_to_lost``).

    Returns:
        The evaluation (without evo's figures), with the two-view seeds' accuracy.
    """
    estimates = result.estimates
    stamps = np.array([e.stamp_ns for e in estimates], np.int64)
    regions = np.array([e.region for e in estimates], np.int64)
    poses = np.array([e.pose if e.pose is not None else np.full(3, np.nan)
                      for e in estimates], float).reshape(-1, 3)
    events = np.array([e.event for e in estimates], object)
    voted = np.array([e.state == LOST or e.event in VOTING_EVENTS for e in estimates], bool)
    order = np.argsort(stamps, kind='stable')
    evaluation = evaluate_run(stamps[order], regions[order], poses[order],
                              run.truth_stamps_ns, run.truth_poses, events=events[order],
                              latency_s=result.latency_seconds[order], voted=voted[order],
                              falls_to_lost=falls_to_lost)
    seeds = np.array([e.two_view_pose if e.two_view_pose is not None else np.full(3, np.nan)
                      for e in estimates], float).reshape(-1, 3)[order]
    seeded = np.isfinite(seeds).all(axis=1)
    if len(run.truth_stamps_ns) and seeded.any():
        evaluation = replace(evaluation, two_view=pose_accuracy(
            stamps[order][seeded], seeds[seeded], run.truth_stamps_ns, run.truth_poses))
    if result.cpu_seconds is None:
        return evaluation
    return replace(evaluation, cpu_latency=latency_summary(result.cpu_seconds[order],
                                                           voted[order]))


def coverage_split(result: OfflineRun, run: RunBag, index: DatabaseIndex
                   ) -> dict[str, dict[str, float]]:
    """Availability and accuracy inside and outside the database's regions.

    A frame is inside when its true position is within one grid spacing of a sampled
    pose that some region contains: the decomposition may leave k-coverable poses in no
    region (the sigma rule, Section 5.5), and a run through them measures the database
    as much as the localizer.

    Returns:
        ``{'inside': {...}, 'outside': {...}}``, each with ``frames``, ``poses``,
        ``availability``, ``translation_median_m`` and ``translation_p95_m`` (NaN
        without poses); empty when the run has no ground truth.
    """
    if not len(run.truth_stamps_ns):
        return {}
    stamps = np.array([e.stamp_ns for e in result.estimates], np.int64)
    truth = interpolate_poses(run.truth_stamps_ns, run.truth_poses, stamps)
    known = np.all(np.isfinite(truth), axis=1)
    covered_pose = np.asarray(index.region_poses.sum(axis=0)).ravel() > 0
    where = np.where(known[:, None], truth, 0.0)
    distance, nearest = index.tree.query(index.pose_points(where))
    inside = known & covered_pose[nearest] & (distance <= index.spacing)
    poses = np.array([e.pose if e.pose is not None else np.full(3, np.nan)
                      for e in result.estimates], float).reshape(-1, 3)
    error = np.hypot(*(poses[:, :2] - truth[:, :2]).T)
    split = {}
    for name, mask in (('inside', inside), ('outside', known & ~inside)):
        found = error[mask & np.isfinite(error)]
        split[name] = {
            'frames': int(mask.sum()), 'poses': int(found.size),
            'availability': float(found.size / mask.sum()) if mask.any() else math.nan,
            'translation_median_m': float(np.median(found)) if found.size else math.nan,
            'translation_p95_m': float(np.percentile(found, 95)) if found.size else math.nan}
    return split


def check_run_camera(run: RunBag, camera: CameraModel, db: str) -> CameraModel:
    """Return the run's camera, or refuse a run whose camera the database cannot take.

    The run's first ``CameraInfo`` gives it (:func:`~landmark_localizer.camera_check.
    frame_camera`: the same kind and distortion model as the database's, at any size
    and calibration) and its ``/tf_static`` the mount's tilt; a run without a
    CameraInfo must have the database camera's image size.

    Raises:
        LocalizerError: the cameras differ, or the first image cannot be decoded.
    """
    if run.camera_tilt is not None:
        pitch, roll = tilt_angles(run.camera_tilt)
        base = tilt_angles(getattr(camera, 'tilt', np.eye(3)))
        if max(abs(pitch - base[0]), abs(roll - base[1])) > 0.01:
            _LOG.info('the run camera is mounted at pitch %.2f, roll %.2f deg (the '
                      "database's: %.2f, %.2f): its rays are levelled with its own mount",
                      pitch, roll, *base)
    if run.camera_info is not None:
        run_camera, problem = frame_camera(run.camera_info, camera, run.camera_tilt)
        if run_camera is None:
            raise LocalizerError(f'{run.path} does not fit {db}: {problem}')
        return run_camera
    try:
        image = decode_image(deserialize(run.images[0], run.image_type))
    except VbnCommonError as error:
        raise LocalizerError(f'{run.path}: the first image cannot be decoded: {error}') \
            from error
    if image.shape[:2] != (camera.height, camera.width):
        raise LocalizerError(
            f'{run.path} does not fit {db}: its images are {image.shape[1]}x{image.shape[0]} '
            f'(no CameraInfo), the database camera {camera.width}x{camera.height} '
            f'{camera.kind}')
    return camera


def never_recognised(result: OfflineRun) -> bool:
    """Whether no frame of the run was ever in a region (no vote ever succeeded)."""
    return not any(e.region >= 0 for e in result.estimates)
