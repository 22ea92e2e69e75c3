"""How well a localizer run went: accuracy, availability, switching, latency, recovery.

The localizer's figures, computed the same way for ``vbn localize`` (the
core over a bag), ``vbn bench-localize`` and ``vbn demo`` (the node over DDS, from a
recording):

- **accuracy**: each published pose against the ground truth with the same stamp
  (nearest within ``max_diff_s``, as ``evo_ape``'s default association): translation
  error (planar distance) median and 95th percentile, heading error median;
- **availability**: frames with a pose over frames;
- **switching**: region changes made by predicted switching against those after the
  features were lost (:func:`count_region_changes`);
- **latency**: per frame, p50 and p95, split between tracking frames and frames that
  voted (LOST, or a lost region's recovery);
- **recovery** after a kidnapping: the teleport found in the ground truth
  (:func:`find_teleports`), frames until a correct pose (:func:`recovery_frames`).

:func:`evo_ape` computes the accuracy again with evo's own reader and APE on the bag,
as ``evo_ape bag2 BAG /ground_truth/pose /localizer/pose`` does, to check ours.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
import logging
import math
import os
from typing import Any

import numpy as np

from landmark_localizer.errors import LocalizerError
from vbn_common import names
from vbn_common.geometry.frames import wrap_angle

__all__ = ['Accuracy', 'Check', 'Latency', 'RegionChanges', 'RunEvaluation', 'Thresholds',
           'associate', 'check_run', 'count_region_changes', 'evaluate_run', 'evo_ape',
           'find_teleports', 'format_checks', 'format_evaluation', 'latency_summary',
           'pose_accuracy', 'recovery_frames', 'VOTING_EVENTS']

_LOG = logging.getLogger(__name__)

#: Events of a frame that voted (its latency is a LOST frame's).
VOTING_EVENTS = frozenset({'vote', 'neighbour_vote', 'global_vote', 'lost'})


@dataclass(frozen=True)
class Accuracy:
    """Pose errors against the ground truth.

    Attributes:
        matched: Poses paired with a ground-truth pose.
        translation_median_m: Median planar position error.
        translation_p95_m: Its 95th percentile.
        translation_max_m: Its largest value.
        heading_median_deg: Median absolute heading error, degrees.
        heading_p95_deg: Its 95th percentile.
    """

    matched: int
    translation_median_m: float
    translation_p95_m: float
    translation_max_m: float
    heading_median_deg: float
    heading_p95_deg: float


@dataclass(frozen=True)
class RegionChanges:
    """Region changes of a run.

    Attributes:
        predicted: Changes made by predicted switching while tracking.
        after_loss: Changes made by voting after the features were lost.
    """

    predicted: int
    after_loss: int

    @property
    def predicted_fraction(self) -> float:
        """Share of the changes made by prediction (NaN without a change)."""
        total = self.predicted + self.after_loss
        return self.predicted / total if total else math.nan


@dataclass(frozen=True)
class Latency:
    """Per-frame latency, seconds.

    Attributes:
        p50: Median over every frame.
        p95: 95th percentile over every frame.
        tracking_p50: Median over the frames that tracked.
        tracking_p95: 95th percentile over the frames that tracked (NaN: none).
        lost_p50: Median over the frames that voted.
        lost_p95: 95th percentile over the frames that voted (NaN: none).
        tracking_frames: Frames that tracked.
        lost_frames: Frames that voted.
    """

    p50: float
    p95: float
    tracking_p50: float
    tracking_p95: float
    lost_p50: float
    lost_p95: float
    tracking_frames: int
    lost_frames: int


@dataclass(frozen=True)
class RunEvaluation:
    """The figures of one run.

    Attributes:
        frames: Frames (images) of the run.
        poses: Frames with a published pose.
        changes: Region changes by prediction and after a loss.
        falls_to_lost: Times the localizer fell to LOST (None when unknown).
        latency: Per-frame latency (None when not measured).
        accuracy: Errors against the ground truth (None without ground truth).
        evo: The same accuracy computed by evo (None when not run).
        recovery: Frames from each teleport to a correct pose (None: never).
        cpu_latency: Per-frame CPU time of the process (offline runs), the cost on one
            core whatever else the machine runs.
        two_view: The accuracy of the model views' poses (7.4, 7.5) before the refinement
            on 3-D points, on the frames posed from them (offline runs).
    """

    frames: int
    poses: int
    changes: RegionChanges
    falls_to_lost: int | None = None
    latency: Latency | None = None
    accuracy: Accuracy | None = None
    evo: Accuracy | None = None
    recovery: list[int | None] = field(default_factory=list)
    cpu_latency: Latency | None = None
    two_view: Accuracy | None = None

    @property
    def availability(self) -> float:
        """Frames with a pose over frames."""
        return self.poses / self.frames if self.frames else math.nan

    def as_dict(self) -> dict[str, Any]:
        """Return the figures as a JSON-ready dict."""
        out = asdict(self)
        out['availability'] = self.availability
        out['changes']['predicted_fraction'] = self.changes.predicted_fraction
        return out


def associate(stamps_a: np.ndarray, stamps_b: np.ndarray, max_diff_s: float = 0.01
              ) -> tuple[np.ndarray, np.ndarray]:
    """Pair each stamp of ``a`` with the nearest stamp of sorted ``b`` within a tolerance.

    Args:
        stamps_a: (n,) stamps, nanoseconds.
        stamps_b: (m,) sorted stamps, nanoseconds.
        max_diff_s: Largest difference of a pair.

    Returns:
        ``(rows of a, rows of b)``, each (p,).
    """
    a = np.asarray(stamps_a, np.int64)
    b = np.asarray(stamps_b, np.int64)
    if len(a) == 0 or len(b) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    right = np.clip(np.searchsorted(b, a), 0, len(b) - 1)
    left = np.clip(right - 1, 0, len(b) - 1)
    nearest = np.where(np.abs(b[left] - a) <= np.abs(b[right] - a), left, right)
    ok = np.abs(b[nearest] - a) <= max_diff_s * 1e9
    return np.flatnonzero(ok), nearest[ok]


def _accuracy(translation: np.ndarray, heading: np.ndarray) -> Accuracy | None:
    if len(translation) == 0:
        return None
    heading_deg = np.degrees(np.abs(heading))
    return Accuracy(len(translation), float(np.median(translation)),
                    float(np.percentile(translation, 95)), float(translation.max()),
                    float(np.median(heading_deg)), float(np.percentile(heading_deg, 95)))


def pose_accuracy(stamps_ns: np.ndarray, poses: np.ndarray, truth_stamps_ns: np.ndarray,
                  truth_poses: np.ndarray, max_diff_s: float = 0.01) -> Accuracy | None:
    """Errors of planar poses against the ground truth at the same stamps.

    Args:
        stamps_ns: (n,) stamps of the estimates.
        poses: (n, 3) estimated ``(x, y, yaw)``.
        truth_stamps_ns: (m,) sorted ground-truth stamps.
        truth_poses: (m, 3) ground-truth poses.
        max_diff_s: Largest stamp difference of a pair.

    Returns:
        The accuracy, or None when no estimate has a ground-truth pose.

    Example:
        >>> acc = pose_accuracy(np.array([0, 1]), np.array([[0.01, 0, 0], [1, 0.02, 0]]),
        ...                     np.array([0, 1]), np.array([[0., 0, 0], [1, 0, 0]]))
        >>> round(acc.translation_median_m, 3)
        0.015
    """
    rows, truth_rows = associate(stamps_ns, truth_stamps_ns, max_diff_s)
    est = np.asarray(poses, float).reshape(-1, 3)[rows]
    ref = np.asarray(truth_poses, float).reshape(-1, 3)[truth_rows]
    translation = np.linalg.norm(est[:, :2] - ref[:, :2], axis=1)
    heading = wrap_angle(est[:, 2] - ref[:, 2])
    return _accuracy(translation, heading)


def count_region_changes(regions: np.ndarray, events: np.ndarray | None = None
                         ) -> RegionChanges:
    """Count the run's region changes by how they were made.

    A change is a frame whose region (>= 0) differs from the last region the run was
    in (LOST frames, -1, in between are skipped). With the localizer's ``events``
    (``vbn localize``), a change whose event is ``'predicted_switch'`` was made by
    prediction and any other (a neighbour or global vote after the features were
    lost) after a loss. Without events (a recording of the node's
    ``/localizer/region``), a change straight from the previous frame's region counts
    as predicted and one after LOST frames as after a loss; a recovery that votes its
    way into a neighbour within one frame then counts as predicted.

    Args:
        regions: (n,) region per frame, -1 when lost.
        events: (n,) event per frame (``Estimate.event``) or None.

    Returns:
        The counts.

    Example:
        >>> count_region_changes(np.array([0, 0, 1, -1, -1, 2, 2]))
        RegionChanges(predicted=1, after_loss=1)
    """
    regions = np.asarray(regions, np.int64)
    predicted = after_loss = 0
    last = -1
    previous = -1
    for i, region in enumerate(regions):
        if region >= 0 and last >= 0 and region != last:
            if events is not None:
                by_prediction = events[i] == 'predicted_switch'
            else:
                by_prediction = previous == last
            if by_prediction:
                predicted += 1
            else:
                after_loss += 1
        if region >= 0:
            last = int(region)
        previous = int(region)
    return RegionChanges(predicted, after_loss)


def latency_summary(seconds: np.ndarray, voted: np.ndarray) -> Latency:
    """Latency percentiles over every frame, the tracking frames and the voting frames.

    Args:
        seconds: (n,) per-frame latency.
        voted: (n,) bool, the frames that voted (LOST or recovering).

    Returns:
        The summary (NaN where a class has no frame).
    """
    seconds = np.asarray(seconds, float)
    voted = np.asarray(voted, bool)

    def pct(values: np.ndarray, q: float) -> float:
        return float(np.percentile(values, q)) if len(values) else math.nan

    tracking, lost = seconds[~voted], seconds[voted]
    return Latency(pct(seconds, 50), pct(seconds, 95), pct(tracking, 50), pct(tracking, 95),
                   pct(lost, 50), pct(lost, 95), int(len(tracking)), int(len(lost)))


def find_teleports(truth_stamps_ns: np.ndarray, truth_poses: np.ndarray,
                   min_jump_m: float = 0.5, factor: float = 10.0) -> np.ndarray:
    """Rows of the ground truth just after a teleport (a kidnapping).

    A teleport is a step between consecutive ground-truth poses longer than both
    ``min_jump_m`` and ``factor`` times the median step.

    Args:
        truth_stamps_ns: (m,) sorted stamps.
        truth_poses: (m, 3) poses.
        min_jump_m: Shortest teleport.
        factor: Shortest teleport as a multiple of the median step.

    Returns:
        (t,) rows ``i`` such that the robot jumped between ``i - 1`` and ``i``.

    Example:
        >>> xy = np.array([[0, 0, 0], [0.05, 0, 0], [2, 1, 0], [2.05, 1, 0]])
        >>> find_teleports(np.arange(4), xy).tolist()
        [2]
    """
    poses = np.asarray(truth_poses, float).reshape(-1, 3)
    if len(poses) < 2:
        return np.zeros(0, np.int64)
    steps = np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1)
    limit = max(min_jump_m, factor * float(np.median(steps)))
    return np.flatnonzero(steps > limit) + 1


def recovery_frames(frame_stamps_ns: np.ndarray, frame_poses: np.ndarray,
                    truth_stamps_ns: np.ndarray, truth_poses: np.ndarray,
                    teleport_stamp_ns: int, tolerance_m: float = 0.05,
                    max_diff_s: float = 0.01) -> int | None:
    """Frames from a teleport until the localizer gives a correct pose again.

    Args:
        frame_stamps_ns: (n,) stamps of every frame, sorted.
        frame_poses: (n, 3) the pose of each frame, NaN rows where none was given.
        truth_stamps_ns: (m,) sorted ground-truth stamps.
        truth_poses: (m, 3) ground truth.
        teleport_stamp_ns: Stamp of the first ground-truth pose after the teleport.
        tolerance_m: A pose within this of the truth is correct.
        max_diff_s: Largest stamp difference between a frame and its ground truth.

    Returns:
        1 when the first frame at or after the teleport is correct, 2 for the next,
        and so on; None when no later frame is.
    """
    stamps = np.asarray(frame_stamps_ns, np.int64)
    poses = np.asarray(frame_poses, float).reshape(-1, 3)
    after = np.flatnonzero(stamps >= teleport_stamp_ns)
    if len(after) == 0:
        return None
    rows, truth_rows = associate(stamps[after], truth_stamps_ns, max_diff_s)
    error = np.full(len(after), np.inf)
    diff = poses[after[rows], :2] - np.asarray(truth_poses, float)[truth_rows, :2]
    error[rows] = np.where(np.isfinite(diff).all(axis=1), np.linalg.norm(diff, axis=1), np.inf)
    good = np.flatnonzero(error <= tolerance_m)
    return int(good[0]) + 1 if len(good) else None


def evaluate_run(frame_stamps_ns: np.ndarray, regions: np.ndarray, frame_poses: np.ndarray,
                 truth_stamps_ns: np.ndarray, truth_poses: np.ndarray, *,
                 events: np.ndarray | None = None, latency_s: np.ndarray | None = None,
                 voted: np.ndarray | None = None, falls_to_lost: int | None = None,
                 n_frames: int | None = None, max_diff_s: float = 0.01,
                 tolerance_m: float = 0.05) -> RunEvaluation:
    """Compute every figure of a run from its per-frame output.

    Args:
        frame_stamps_ns: (n,) stamps of the frames with output, sorted.
        regions: (n,) region per frame, -1 when lost.
        frame_poses: (n, 3) poses, NaN rows where no pose was given.
        truth_stamps_ns: (m,) sorted ground-truth stamps (may be empty).
        truth_poses: (m, 3) ground truth.
        events: (n,) the localizer's events, when known.
        latency_s: (n,) per-frame latency, when measured.
        voted: (n,) bool, frames that voted; default from ``events`` and ``regions``.
        falls_to_lost: The localizer's count, when known.
        n_frames: Frames of the run when some gave no output (default n).
        max_diff_s: Stamp tolerance against the ground truth.
        tolerance_m: Largest error of a correct pose after a teleport.

    Returns:
        The evaluation.
    """
    stamps = np.asarray(frame_stamps_ns, np.int64)
    poses = np.asarray(frame_poses, float).reshape(-1, 3)
    has_pose = np.isfinite(poses).all(axis=1)
    accuracy = None
    recovery: list[int | None] = []
    if len(truth_stamps_ns):
        accuracy = pose_accuracy(stamps[has_pose], poses[has_pose], truth_stamps_ns,
                                 truth_poses, max_diff_s)
        for row in find_teleports(truth_stamps_ns, truth_poses):
            recovery.append(recovery_frames(stamps, poses, truth_stamps_ns, truth_poses,
                                            int(np.asarray(truth_stamps_ns)[row]),
                                            tolerance_m, max_diff_s))
    latency = None
    if latency_s is not None:
        if voted is None:
            lost = np.asarray(regions) < 0
            voted = lost if events is None else lost | np.isin(events, list(VOTING_EVENTS))
        latency = latency_summary(latency_s, voted)
    return RunEvaluation(int(n_frames if n_frames is not None else len(stamps)),
                         int(has_pose.sum()), count_region_changes(regions, events),
                         falls_to_lost, latency, accuracy, None, recovery)


def evo_ape(bag: str | os.PathLike[str], reference: str = names.GROUND_TRUTH_POSE,
            estimate: str = names.LOCALIZER_POSE, max_diff_s: float = 0.01) -> Accuracy:
    """Compute the accuracy as evo does from a bag (``evo_ape bag2 BAG REF EST``).

    evo's bag reader loads both topics, :func:`evo.core.sync.associate_trajectories`
    pairs them (``t_max_diff`` as evo's default), and APE gives the translation
    (``trans_part``) and rotation-angle (``angle_deg``) errors, without alignment.

    Args:
        bag: The pose bag.
        reference: Ground-truth topic.
        estimate: Estimate topic.
        max_diff_s: evo's ``t_max_diff``.

    Returns:
        evo's figures.

    Raises:
        LocalizerError: evo cannot read the bag or pair the trajectories.
    """
    from evo.core import metrics, sync
    from evo.core.metrics import PoseRelation
    from evo.tools import file_interface
    from rosbags.rosbag2 import Reader

    try:
        with Reader(bag) as reader:
            ref = file_interface.read_bag_trajectory(reader, reference)
            est = file_interface.read_bag_trajectory(reader, estimate)
        ref, est = sync.associate_trajectories(ref, est, max_diff=max_diff_s)
    except Exception as error:  # noqa: BLE001 - evo raises many kinds
        raise LocalizerError(f'evo cannot evaluate {bag}: {error}') from error
    errors = {}
    for relation in (PoseRelation.translation_part, PoseRelation.rotation_angle_deg):
        ape = metrics.APE(relation)
        ape.process_data((ref, est))
        errors[relation] = np.asarray(ape.error, float)
    translation = errors[PoseRelation.translation_part]
    heading = np.abs(errors[PoseRelation.rotation_angle_deg])
    return Accuracy(len(translation), float(np.median(translation)),
                    float(np.percentile(translation, 95)), float(translation.max()),
                    float(np.median(heading)), float(np.percentile(heading, 95)))


@dataclass(frozen=True)
class Thresholds:
    """The targets.

    Attributes:
        translation_median_m: Largest median translation error.
        translation_p95_m: Largest 95th percentile of the translation error.
        heading_median_deg: Largest median heading error.
        availability: Least share of frames with a pose.
        predicted_fraction: Least share of region changes made by prediction.
        recovery_frames: Most frames from a teleport to a correct pose.
        tracking_p95_s: Largest p95 latency of a tracking frame.
        lost_p95_s: Largest p95 latency of a voting frame.
    """

    translation_median_m: float = 0.01
    translation_p95_m: float = 0.05
    heading_median_deg: float = 0.2
    availability: float = 0.98
    predicted_fraction: float = 0.90
    recovery_frames: int = 3
    tracking_p95_s: float = 0.010
    lost_p95_s: float = 0.120


@dataclass(frozen=True)
class Check:
    """One figure against its target.

    Attributes:
        name: What is measured.
        value: The measurement (NaN: not measured).
        limit: The target.
        at_most: Whether the value must be at most (else at least) the limit.
        text: The value as printed.
    """

    name: str
    value: float
    limit: float
    at_most: bool
    text: str

    @property
    def passed(self) -> bool:
        """Whether the target is met (a missing measurement fails)."""
        if not math.isfinite(self.value):
            return False
        return self.value <= self.limit if self.at_most else self.value >= self.limit


def check_run(evaluation: RunEvaluation, thresholds: Thresholds = Thresholds(), *,
              accuracy: bool = True, switching: bool = True, latency: bool = False,
              recovery: bool = False) -> list[Check]:
    """Check the run's figures against the targets.

    Args:
        evaluation: The run.
        thresholds: Targets.
        accuracy: Check accuracy and availability (evo's accuracy when present).
        switching: Check the share of predicted region changes.
        latency: Check the tracking and voting latencies.
        recovery: Check the recovery after each teleport (a run without a teleport fails).

    Returns:
        The checks, in the targets' order.
    """
    t = thresholds
    checks: list[Check] = []
    if accuracy:
        acc = evaluation.evo or evaluation.accuracy
        source = 'evo_ape' if evaluation.evo else 'ours'
        nan = math.nan
        med = acc.translation_median_m if acc else nan
        p95 = acc.translation_p95_m if acc else nan
        head = acc.heading_median_deg if acc else nan
        checks += [
            Check(f'translation median ({source})', med, t.translation_median_m, True,
                  f'{med * 100:.2f} cm'),
            Check(f'translation p95 ({source})', p95, t.translation_p95_m, True,
                  f'{p95 * 100:.2f} cm'),
            Check(f'heading median ({source})', head, t.heading_median_deg, True,
                  f'{head:.3f} deg'),
            Check('availability', evaluation.availability, t.availability, False,
                  f'{evaluation.availability * 100:.1f} % ({evaluation.poses}/'
                  f'{evaluation.frames})')]
    if switching:
        ch = evaluation.changes
        checks.append(Check('region changes by prediction', ch.predicted_fraction,
                            t.predicted_fraction, False,
                            f'{ch.predicted_fraction * 100:.1f} % ({ch.predicted} predicted, '
                            f'{ch.after_loss} after loss)'))
    if latency:
        lat = evaluation.latency
        tp = lat.tracking_p95 if lat else math.nan
        lp = lat.lost_p95 if lat else math.nan
        checks += [Check('latency TRACKING p95', tp, t.tracking_p95_s, True,
                         f'{tp * 1e3:.1f} ms'),
                   Check('latency LOST p95', lp, t.lost_p95_s, True, f'{lp * 1e3:.1f} ms')]
    if recovery:
        frames = [r for r in evaluation.recovery]
        worst = math.nan if not frames or any(r is None for r in frames) else max(frames)
        checks.append(Check('frames to recover after teleport', worst, t.recovery_frames,
                            True, ', '.join('never' if r is None else str(r)
                                            for r in frames) or 'no teleport found'))
    return checks


def format_checks(checks: list[Check], title: str = '') -> str:
    """Format the checks as a table, one PASS or FAIL per row."""
    lines = [title] if title else []
    for c in checks:
        op = '<=' if c.at_most else '>='
        limit = c.limit
        if 'translation' in c.name:
            bound = f'{limit * 100:g} cm'
        elif 'latency' in c.name:
            bound = f'{limit * 1e3:g} ms'
        elif 'heading' in c.name:
            bound = f'{limit:g} deg'
        elif 'frames' in c.name:
            bound = f'{limit:g}'
        else:
            bound = f'{limit * 100:g} %'
        lines.append(f'  {"PASS" if c.passed else "FAIL"}  {c.name:<36} {c.text:<34} '
                     f'(target {op} {bound})')
    return '\n'.join(lines)


def format_evaluation(evaluation: RunEvaluation, title: str = '') -> str:
    """Format the run's figures as a few aligned lines."""
    e = evaluation
    lines = [title] if title else []
    lines.append(f'  frames            {e.frames}')
    lines.append(f'  poses             {e.poses} (availability {e.availability * 100:.1f} %)')
    ch = e.changes
    lost = '' if e.falls_to_lost is None else f', {e.falls_to_lost} falls to LOST'
    lines.append(f'  region changes    {ch.predicted} by prediction, {ch.after_loss} after '
                 f'loss ({ch.predicted_fraction * 100:.1f} % predicted){lost}')
    for name, lat in (('latency', e.latency), ('CPU per frame', e.cpu_latency)):
        if lat is None:
            continue
        if lat.tracking_frames + lat.lost_frames == 0:  # not split by state (the node's)
            lines.append(f'  {name:<17} p50 {lat.p50 * 1e3:.1f} ms, p95 {lat.p95 * 1e3:.1f} ms')
            continue
        lines.append(f'  {name:<17} p50 {lat.p50 * 1e3:.1f} ms, p95 {lat.p95 * 1e3:.1f} ms;'
                     f' TRACKING p50 {lat.tracking_p50 * 1e3:.1f} / p95 '
                     f'{lat.tracking_p95 * 1e3:.1f} ms ({lat.tracking_frames} frames); LOST '
                     f'p50 {lat.lost_p50 * 1e3:.1f} / p95 {lat.lost_p95 * 1e3:.1f} ms '
                     f'({lat.lost_frames} frames)')
    for name, acc in (('accuracy (ours)', e.accuracy), ('accuracy (evo)', e.evo),
                      ('  two-view seed', e.two_view)):
        if acc is not None:
            lines.append(f'  {name:<17} translation median {acc.translation_median_m * 100:.2f}'
                         f' cm, p95 {acc.translation_p95_m * 100:.2f} cm, max '
                         f'{acc.translation_max_m * 100:.1f} cm; heading median '
                         f'{acc.heading_median_deg:.3f} deg ({acc.matched} poses)')
    if e.recovery:
        lines.append('  teleports         recovered after ' + ', '.join(
            'never' if r is None else f'{r} frame(s)' for r in e.recovery))
    return '\n'.join(lines)
