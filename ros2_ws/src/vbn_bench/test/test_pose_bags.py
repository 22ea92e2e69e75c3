"""Tests of the pose bag: written by vbn localize, read back by us and by evo."""
from __future__ import annotations

import math
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from vbn_bench.localization.evaluation import evo_ape, pose_accuracy
from vbn_bench.localization.pose_bags import PoseRecord, read_pose_bag, write_pose_bag
from vbn_common.bags import TYPESTORE, serialize
from vbn_common.geometry.frames import wrap_angle, yaw_quaternion

T = TYPESTORE.types
POSE = 'geometry_msgs/msg/PoseStamped'


def truth_message(stamp_ns: int, pose: np.ndarray) -> tuple[int, str, bytes]:
    q = yaw_quaternion(float(pose[2]))
    msg = T[POSE](
        header=T['std_msgs/msg/Header'](
            stamp=T['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9,
                                                   nanosec=stamp_ns % 10**9),
            frame_id='map'),
        pose=T['geometry_msgs/msg/Pose'](
            position=T['geometry_msgs/msg/Point'](x=float(pose[0]), y=float(pose[1]), z=0.0),
            orientation=T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=float(q[2]),
                                                          w=float(q[3]))))
    return stamp_ns, POSE, serialize(msg, POSE)


def sample(tmp_path: Path) -> tuple[Path, np.ndarray, np.ndarray, np.ndarray]:
    """40 frames on a circle; poses 2 cm off radially and 0.3 deg off; frames 10-14 lost."""
    n = 40
    stamps = 1_735_689_600 * 10**9 + np.arange(n, dtype=np.int64) * 100_000_000
    angle = np.linspace(0, 1.5 * math.pi, n)
    truth = np.stack([np.cos(angle), np.sin(angle), angle + math.pi / 2], axis=1)
    est = truth.copy()
    est[:, :2] *= 1.02  # radius 1 m: exactly 2 cm off
    est[:, 2] += math.radians(0.3)
    lost = np.zeros(n, bool)
    lost[10:15] = True
    records = [PoseRecord(int(s), -1 if lost[i] else i // 8,
                          None if lost[i] else est[i],
                          None if lost[i] else np.diag([1e-4, 2e-4, 1e-5]))
               for i, s in enumerate(stamps)]
    out = tmp_path / 'poses'
    assert write_pose_bag(out, records, [truth_message(int(s), p)
                                         for s, p in zip(stamps, truth, strict=True)]) == 35
    return out, stamps, truth, est


def test_pose_bag_round_trip(tmp_path: Path) -> None:
    out, stamps, truth, est = sample(tmp_path)
    bag = read_pose_bag(out)
    keep = np.r_[0:10, 15:40]
    assert bag.pose_stamps_ns.tolist() == stamps[keep].tolist()
    assert bag.poses[:, :2] == pytest.approx(est[keep, :2])
    assert np.abs(wrap_angle(bag.poses[:, 2] - est[keep, 2])).max() < 1e-9
    assert bag.truth_poses[:, :2] == pytest.approx(truth[:, :2])
    assert len(bag.regions) == 40 and (bag.regions[10:15] == -1).all()
    assert bag.covariances[0] == pytest.approx(np.diag([1e-4, 2e-4, 1e-5]))
    acc = pose_accuracy(bag.pose_stamps_ns, bag.poses, bag.truth_stamps_ns, bag.truth_poses)
    assert acc.translation_median_m == pytest.approx(0.02)
    assert acc.heading_median_deg == pytest.approx(0.3)


def test_evo_reads_the_bag(tmp_path: Path) -> None:
    out, *_ = sample(tmp_path)
    evo = evo_ape(out)
    assert evo.matched == 35
    assert evo.translation_median_m == pytest.approx(0.02, abs=1e-9)
    assert evo.heading_median_deg == pytest.approx(0.3, abs=1e-6)


def test_evo_ape_command_reads_the_bag(tmp_path: Path) -> None:
    out, *_ = sample(tmp_path)
    evo_ape_cli = Path(sys.executable).parent / 'evo_ape'
    result = subprocess.run([str(evo_ape_cli), 'bag2', str(out), '/ground_truth/pose',
                             '/localizer/pose', '--no_warnings'],
                            capture_output=True, text=True, timeout=120, check=True)
    median = next(float(line.split()[1]) for line in result.stdout.splitlines()
                  if line.strip().startswith('median'))
    assert median == pytest.approx(0.02, abs=1e-6)
