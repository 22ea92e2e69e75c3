"""Tracks from pairwise matches and the bundle adjustment with odometry."""
from __future__ import annotations

import math

import numpy as np

from vbn_common.geometry.camera import PanoramicCamera
from vbn_common.geometry.frames import compose_poses, invert_pose, wrap_angle
from visibility_builder.estimation.refinement import refine_poses, tracks_from_pairs


def test_tracks_join_chains_and_drop_conflicts() -> None:
    # image 0 feature 1 ~ image 1 feature 0 ~ image 2 feature 3: one track of three;
    # image 0 feature 2 ~ image 1 feature 1 and ~ image 1 feature 2 (two features of one
    # image in one track): dropped.
    pairs = np.array([[0, 1], [1, 2], [0, 1]])
    matches = [np.array([[1, 0], [2, 1]]), np.array([[0, 3]]), np.array([[2, 2]])]
    rows, count = tracks_from_pairs([3, 3, 4], pairs, matches)
    assert count == 1
    assert sorted(map(tuple, rows[:, 1:].tolist())) == [(0, 1), (1, 0), (2, 3)]


def _scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    points = np.c_[rng.uniform(-3, 3, 300), rng.uniform(-3, 3, 300), rng.uniform(-1, 1, 300)]
    points = points[np.abs(points[:, :2]).max(axis=1) > 2.0]
    poses = np.array([[x, y, rng.uniform(-math.pi, math.pi)] for y in (0.0, 0.3)
                      for x in (0.0, 0.25, 0.5, 0.75)])
    poses[0, 2] = 0.0
    obs, rays = [], []
    for i, (x, y, yaw) in enumerate(poses):
        d = points - [x, y, 0.0]
        c, s = math.cos(yaw), math.sin(yaw)
        local = np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]]
        local /= np.linalg.norm(local, axis=1, keepdims=True)
        obs += [(t, i) for t in range(len(points))]
        rays.append(local)
    return poses, points, np.array(obs), np.concatenate(rays)


def _odometry(poses: np.ndarray, std: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = len(poses)
    rel = np.array([compose_poses(invert_pose(poses[i]), poses[i + 1]) for i in range(n - 1)])
    return np.stack([np.arange(n - 1), np.arange(1, n)], 1), rel, np.full((n - 1, 3), std)


def test_exact_rays_pull_perturbed_poses_back_exactly() -> None:
    rng = np.random.default_rng(1)
    poses, _, obs, rays = _scene(rng)
    start = poses + np.c_[rng.normal(0, 0.01, (len(poses), 2)),
                          rng.normal(0, 0.005, len(poses))]
    start[0] = poses[0]
    result = refine_poses(start, obs, rays, PanoramicCamera(), _odometry(poses, 0.01))
    assert np.abs(result.camera_poses[:, :2] - poses[:, :2]).max() < 1e-6
    assert np.abs(wrap_angle(result.camera_poses[:, 2] - poses[:, 2])).max() < 1e-6
    assert result.rms_px < 1e-3 and result.removed == 0
    assert result.error_after < result.error_before


def test_noise_and_outliers_stay_bounded() -> None:
    rng = np.random.default_rng(2)
    poses, _, obs, rays = _scene(rng)
    camera = PanoramicCamera()
    noise = 0.5 / (camera.width / (2 * math.pi))           # half a pixel, in radians
    rays = rays + rng.normal(0, noise, rays.shape)
    wrong = rng.choice(len(rays), size=len(rays) // 50, replace=False)
    rays[wrong] = rng.normal(size=(len(wrong), 3))         # 2 % of observations anywhere
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    result = refine_poses(poses, obs, rays, camera, _odometry(poses, 0.01))
    # the scale rests on 1 cm odometry steps between eight views: millimetres
    assert np.abs(result.camera_poses[:, :2] - poses[:, :2]).max() < 0.006
    assert np.degrees(np.abs(wrap_angle(result.camera_poses[:, 2] - poses[:, 2]))).max() < 0.05
    assert result.observations <= len(rays) - len(wrong)   # the wrong ones left out
