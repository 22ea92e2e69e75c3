"""Tests of the localizer's evaluation: hand-made trajectories with known errors."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vbn_bench.localization.evaluation import (
    Thresholds,
    associate,
    check_run,
    count_region_changes,
    evaluate_run,
    find_teleports,
    latency_summary,
    pose_accuracy,
    recovery_frames,
)
from vbn_bench.localization.offline import interpolate_poses

MS = 10**6


def straight_run(n: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """A robot driving along x at 5 cm per frame, 10 frames per second."""
    stamps = np.arange(n, dtype=np.int64) * 100 * MS + 10**18
    poses = np.stack([0.05 * np.arange(n), np.zeros(n), np.zeros(n)], axis=1)
    return stamps, poses


def test_accuracy_of_known_offsets() -> None:
    stamps, truth = straight_run(100)
    est = truth.copy()
    # Half the poses 1 cm off in y, the other half 3 cm off; every heading 0.1 deg off.
    est[:50, 1] += 0.01
    est[50:, 1] -= 0.03
    est[:, 2] += math.radians(0.1)
    acc = pose_accuracy(stamps, est, stamps, truth)
    assert acc.matched == 100
    assert acc.translation_median_m == pytest.approx(0.02)  # between 1 and 3 cm
    assert acc.translation_p95_m == pytest.approx(0.03)
    assert acc.translation_max_m == pytest.approx(0.03)
    assert acc.heading_median_deg == pytest.approx(0.1)


def test_heading_error_wraps_around_pi() -> None:
    stamps, truth = straight_run(3)
    truth[:, 2] = math.pi - 0.001
    est = truth.copy()
    est[:, 2] = -math.pi + 0.001  # 0.002 rad away across the cut, not 2 pi
    acc = pose_accuracy(stamps, est, stamps, truth)
    assert acc.heading_median_deg == pytest.approx(math.degrees(0.002), abs=1e-9)


def test_association_tolerance_drops_far_stamps() -> None:
    truth_stamps = np.array([0, 100, 200]) * MS
    rows, truth_rows = associate(np.array([1, 95, 150, 205]) * MS, truth_stamps, 0.01)
    assert rows.tolist() == [0, 1, 3]  # 150 ms is 50 ms from either
    assert truth_rows.tolist() == [0, 1, 2]
    assert pose_accuracy(np.array([150 * MS]), np.zeros((1, 3)), truth_stamps,
                         np.zeros((3, 3))) is None


def test_availability_counts_frames_without_pose() -> None:
    stamps, truth = straight_run(50)
    poses = truth.copy()
    poses[[3, 4, 5, 20]] = np.nan  # four frames without a pose
    regions = np.zeros(50, np.int64)
    regions[[3, 4, 5]] = -1
    evaluation = evaluate_run(stamps, regions, poses, stamps, truth)
    assert evaluation.frames == 50
    assert evaluation.poses == 46
    assert evaluation.availability == pytest.approx(0.92)
    assert evaluation.accuracy.matched == 46
    # Frames that gave no output at all (dropped) count against availability too.
    dropped = evaluate_run(stamps, regions, poses, stamps, truth, n_frames=60)
    assert dropped.availability == pytest.approx(46 / 60)


def test_region_changes_with_events() -> None:
    regions = np.array([0, 0, 1, 1, 2, -1, -1, 3, 3, 1])
    events = np.array(['vote', '', 'predicted_switch', '', 'neighbour_vote', 'lost', '',
                       'global_vote', '', 'predicted_switch'], object)
    changes = count_region_changes(regions, events)
    # 0->1 and 3->1 predicted; 1->2 by a neighbour vote and 2->3 after LOST.
    assert (changes.predicted, changes.after_loss) == (2, 2)
    assert changes.predicted_fraction == pytest.approx(0.5)


def test_region_changes_from_a_recording() -> None:
    # Without events a change straight from the previous frame's region is predicted.
    changes = count_region_changes(np.array([-1, 4, 4, 5, 5, -1, 5, 6, -1, -1, 2]))
    assert (changes.predicted, changes.after_loss) == (2, 1)  # 4->5, 5->6; 6->(lost)->2
    assert math.isnan(count_region_changes(np.array([1, 1, -1, 1])).predicted_fraction)


def test_teleport_found_in_ground_truth() -> None:
    stamps, truth = straight_run(60)
    truth[30:] += np.array([2.0, 1.5, 0.0])  # kidnapped between rows 29 and 30
    assert find_teleports(stamps, truth).tolist() == [30]
    assert find_teleports(*straight_run(60)).size == 0
    # A robot turning on the spot (heading jumps) is not a teleport.
    turning = straight_run(60)[1]
    turning[10:, 2] = 3.0
    assert find_teleports(stamps, turning).size == 0


def test_recovery_frames_after_teleport() -> None:
    stamps, truth = straight_run(60)
    truth[30:] += np.array([2.0, 1.5, 0.0])
    est = truth.copy()
    est[30:] -= np.array([2.0, 1.5, 0.0])  # still believes the old place
    est[31] = np.nan                        # no pose
    est[32] = truth[32] + [0.04, 0.0, 0.0]  # within 5 cm: recovered on the third frame
    est[33:] = truth[33:]
    assert recovery_frames(stamps, est, stamps, truth, int(stamps[30])) == 3
    est[32] = truth[32] + [0.06, 0.0, 0.0]  # 6 cm is not correct
    assert recovery_frames(stamps, est, stamps, truth, int(stamps[30])) == 4
    est[30:] = np.nan
    assert recovery_frames(stamps, est, stamps, truth, int(stamps[30])) is None
    evaluation = evaluate_run(stamps, np.zeros(60), est, stamps, truth)
    assert evaluation.recovery == [None]
    failed = {c.name: c.passed for c in check_run(evaluation, recovery=True)}
    assert failed['frames to recover after teleport'] is False


def test_latency_split_by_state() -> None:
    seconds = np.array([0.005] * 18 + [0.1, 0.2])
    voted = np.array([False] * 18 + [True, True])
    lat = latency_summary(seconds, voted)
    assert lat.tracking_p95 == pytest.approx(0.005)
    assert lat.lost_p50 == pytest.approx(0.15)
    assert (lat.tracking_frames, lat.lost_frames) == (18, 2)
    assert math.isnan(latency_summary(seconds[:3], voted[:3]).lost_p95)


def test_checks_against_the_targets() -> None:
    stamps, truth = straight_run(100)
    est = truth.copy()
    est[:, 0] += 0.004
    est[:5] = np.nan  # 95 % availability: below the 98 % target
    regions = np.repeat(np.arange(10), 10)
    events = np.where(np.r_[True, np.diff(regions) != 0], 'predicted_switch', '').astype(object)
    evaluation = evaluate_run(stamps, regions, est, stamps, truth, events=events,
                              latency_s=np.full(100, 0.004))
    checks = {c.name: c for c in check_run(evaluation, latency=True)}
    assert checks['translation median (ours)'].passed
    assert checks['heading median (ours)'].passed
    assert not checks['availability'].passed
    assert checks['region changes by prediction'].value == pytest.approx(1.0)
    assert checks['latency TRACKING p95'].passed
    assert not checks['latency LOST p95'].passed  # no LOST frame measured: not shown
    tight = check_run(evaluation, Thresholds(translation_median_m=0.003))
    assert not tight[0].passed


def test_interpolated_odometry() -> None:
    stamps = np.array([0, 100, 200, 2000]) * MS
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 0.2], [2.0, 2.0, 0.4], [9.0, 9.0, 0.0]])
    out = interpolate_poses(stamps, poses, np.array([50, 150, 250, 1000, -5000]) * MS)
    assert out[0] == pytest.approx([0.5, 1.0, 0.1])
    assert out[1] == pytest.approx([1.5, 2.0, 0.3])
    assert np.isnan(out[2:]).all()  # in a 1.8 s gap, and before the first pose
    assert np.isnan(interpolate_poses(np.zeros(0), np.zeros((0, 3)), np.array([1]))).all()


def test_the_trajectory_colour_scale_reaches_the_largest_error():
    from vbn_bench.localization.plots import error_scale_cm
    low, high = error_scale_cm(np.array([0.004, 0.008, 0.199]))   # a 19.9 cm outlier
    assert low == 0.1 and high == pytest.approx(19.9)
    assert error_scale_cm(np.array([0.0001])) == (0.1, 0.2)
