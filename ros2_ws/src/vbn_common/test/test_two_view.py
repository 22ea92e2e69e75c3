"""Tests of the two-view solvers on synthetic correspondences with known answers."""
from __future__ import annotations

import math

import cv2
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from two_view_samples import random_pose_near, render_views

from vbn_common.errors import VbnCommonError
from vbn_common.geometry import (
    compose_poses,
    invert_pose,
    make_camera,
    world_points_to_camera,
    wrap_angle,
)
from vbn_common.geometry.epipolar import (
    planar_epipolar_residuals,
    planar_sampson,
    pointwise_planar_residuals,
)
from vbn_common.geometry.essential import general_essential
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION
from vbn_common.geometry.linear_combination import linear_combination_of_views
from vbn_common.geometry.motion import TwoViewConfig
from vbn_common.geometry.panoramic_planar import panoramic_planar_motion
from vbn_common.geometry.pinhole_planar import pinhole_planar_essential
from vbn_common.geometry.two_view import relative_motion

PANO = make_camera('panoramic')
PIN = make_camera('pinhole')
PANO_METHODS = ('panoramic_planar', 'pinhole_planar', 'general_essential')
PIN_METHODS = ('pinhole_planar', 'general_essential')


def _pano_poses(rng: np.random.Generator) -> np.ndarray:
    model = np.array([rng.uniform(1.0, 5.0), rng.uniform(0.7, 2.3), rng.uniform(-3, 3)])
    while True:
        current = random_pose_near(rng, model, 1.0, math.pi)
        inside = 0.4 < current[0] < 5.6 and 0.4 < current[1] < 2.6
        if inside and math.hypot(*(current[:2] - model[:2])) > 0.2:
            return np.stack([model, current])


def _pin_poses(rng: np.random.Generator) -> np.ndarray:
    # Looking along the room: far wall and both side walls (a plane alone is degenerate).
    facing = float(rng.choice([0.0, math.pi]))
    x = rng.uniform(0.8, 1.6) if facing == 0.0 else rng.uniform(4.4, 5.2)
    model = np.array([x, rng.uniform(1.0, 2.0), facing + rng.uniform(-0.2, 0.2)])
    current = random_pose_near(rng, model + [0.4 * math.cos(facing), 0, 0], 0.4, 0.25)
    return np.stack([model, current])


def _errors(motion, views) -> tuple[float, float]:
    theta, phi = views.truth(0, 1)
    return (abs(float(wrap_angle(motion.theta - theta))),
            abs(float(wrap_angle(motion.phi - phi))))


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('method', PANO_METHODS)
def test_panoramic_views_are_recovered_exactly_without_noise(method, seed):
    rng = np.random.default_rng(seed)
    views = render_views(PANO, _pano_poses(rng), rng)
    motion = relative_motion(views.uv[0], views.uv[1], PANO, method=method, rng=seed)
    assert max(_errors(motion, views)) < 1e-6
    assert motion.method == method
    assert motion.residual < 1e-6
    np.testing.assert_allclose(np.linalg.norm(motion.direction), 1.0)


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('method', PIN_METHODS)
def test_pinhole_views_are_recovered_exactly_without_noise(method, seed):
    rng = np.random.default_rng(seed)
    views = render_views(PIN, _pin_poses(rng), rng)
    motion = relative_motion(views.uv[0], views.uv[1], PIN, method=method, rng=seed)
    assert max(_errors(motion, views)) < 1e-6
    assert motion.inliers.all()


def test_the_camera_kind_picks_the_method_and_a_parameter_overrides_it():
    rng = np.random.default_rng(3)
    pano = render_views(PANO, _pano_poses(rng), rng)
    pin = render_views(PIN, _pin_poses(rng), rng)
    assert relative_motion(pano.uv[0], pano.uv[1], PANO, rng=0).method == 'panoramic_planar'
    assert relative_motion(pin.uv[0], pin.uv[1], PIN, rng=0).method == 'pinhole_planar'
    assert relative_motion(pin.uv[0], pin.uv[1], PIN, rng=0,
                           method='general_essential').method == 'general_essential'
    assert relative_motion(pano.uv[0], pano.uv[1], PANO, rng=0,
                           method='general_essential').direction.shape == (3,)


def test_directions_and_angles_follow_rep_103_in_the_model_cameras_frame():
    # A ring of points around the origin; hand-checkable motions of the camera.
    angles = np.linspace(-np.pi, np.pi, 60, endpoint=False)
    heights = np.where(np.arange(60) % 2 == 0, 2.2, 0.3)
    points = np.stack([4 * np.cos(angles), 4 * np.sin(1.3 * angles) + 0.1, heights], axis=1)

    def motion(model, current):
        uv = [PANO.project(world_points_to_camera(p, 1.2, points))[0] for p in (model, current)]
        return relative_motion(uv[0], uv[1], PANO, rng=0)

    ahead = motion(np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.0, 0.0]))
    np.testing.assert_allclose(ahead.direction, [1.0, 0.0], atol=1e-9)
    assert ahead.theta == pytest.approx(0.0, abs=1e-9)
    left = motion(np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.5, math.pi / 2]))
    np.testing.assert_allclose(left.direction, [0.0, 1.0], atol=1e-9)
    assert left.theta == pytest.approx(math.pi / 2, abs=1e-9)
    # A model camera facing +y: moving +y in map is straight ahead in its frame,
    # moving -x in map is to its left.
    turned = motion(np.array([0.0, 0.0, math.pi / 2]), np.array([0.0, 0.6, math.pi / 2]))
    np.testing.assert_allclose(turned.direction, [1.0, 0.0], atol=1e-9)
    assert turned.theta == pytest.approx(0.0, abs=1e-9)
    turned_left = motion(np.array([0.0, 0.0, math.pi / 2]), np.array([-0.6, 0.0, 2.0]))
    np.testing.assert_allclose(turned_left.direction, [0.0, 1.0], atol=1e-9)
    assert turned_left.theta == pytest.approx(2.0 - math.pi / 2, abs=1e-9)
    th = 2.0 - math.pi / 2      # x_current = rotation @ x_model: a turn by -theta
    np.testing.assert_allclose(turned_left.rotation[:2, :2],
                               [[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]],
                               atol=1e-9)


@pytest.mark.parametrize('method', PANO_METHODS)
def test_panoramic_error_is_bounded_with_half_a_pixel_of_noise(method):
    rng = np.random.default_rng(11)
    errors = []
    for _ in range(12):
        views = render_views(PANO, _pano_poses(rng), rng, noise_px=0.5)
        errors.append(_errors(relative_motion(views.uv[0], views.uv[1], PANO, method=method,
                                              rng=0), views))
    theta_err, phi_err = np.median(errors, axis=0)
    assert theta_err < 0.005
    assert phi_err < 0.03


@pytest.mark.parametrize('method', PIN_METHODS)
def test_pinhole_error_is_bounded_with_half_a_pixel_of_noise(method):
    rng = np.random.default_rng(12)
    errors = []
    for _ in range(12):
        views = render_views(PIN, _pin_poses(rng), rng, noise_px=0.5)
        errors.append(_errors(relative_motion(views.uv[0], views.uv[1], PIN, method=method,
                                              rng=0), views))
    theta_err, phi_err = np.median(errors, axis=0)
    assert theta_err < 0.005
    assert phi_err < 0.05


@pytest.mark.parametrize('camera,method', [(PANO, m) for m in PANO_METHODS]
                         + [(PIN, m) for m in PIN_METHODS])
@pytest.mark.parametrize('outliers', [0.2, 0.3])
def test_robust_methods_reject_20_to_30_percent_outliers(camera, method, outliers):
    rng = np.random.default_rng(21)
    make_poses = _pano_poses if camera is PANO else _pin_poses
    errors, rejected, kept = [], [], []
    for _ in range(6):
        clean = render_views(camera, make_poses(rng), rng, noise_px=0.5)
        views = render_views(camera, clean.poses, rng, noise_px=0.5, outliers=outliers)
        wrong = np.linalg.norm(views.uv[1] - _project(camera, views), axis=1) > 5.0
        motion = relative_motion(views.uv[0], views.uv[1], camera, method=method, rng=1)
        errors.append(_errors(motion, views))
        rejected.append(np.mean(~motion.inliers[wrong]))
        kept.append(np.mean(motion.inliers[~wrong]))
    theta_err, phi_err = np.median(errors, axis=0)
    assert theta_err < 0.01
    assert phi_err < 0.06
    assert np.mean(rejected) > 0.9
    assert np.mean(kept) > 0.8


def _project(camera, views):
    return camera.project(world_points_to_camera(views.poses[1], 1.2, views.points))[0]


def test_general_essential_agrees_with_opencv():
    rng = np.random.default_rng(5)
    for _ in range(3):
        views = render_views(PIN, _pin_poses(rng), rng, noise_px=0.5, n=80)
        mine = relative_motion(views.uv[0], views.uv[1], PIN, method='general_essential',
                               rng=0)
        K = np.array([[PIN.fx, 0, PIN.cx], [0, PIN.fy, PIN.cy], [0, 0, 1]])
        E, mask = cv2.findEssentialMat(views.uv[0], views.uv[1], K, method=cv2.RANSAC,
                                       prob=0.999, threshold=1.0)
        _, R, t, _ = cv2.recoverPose(E, views.uv[0], views.uv[1], K, mask=mask)
        M = BASE_TO_CAMERA_ROTATION
        orientation = M @ R.T @ M.T
        cv_theta = math.atan2(orientation[1, 0], orientation[0, 0])
        centre = M @ (-R.T @ t.ravel())
        cv_dir = centre / np.linalg.norm(centre)
        theta, phi = views.truth(0, 1)
        assert abs(wrap_angle(cv_theta - theta)) < 0.03
        assert abs(wrap_angle(mine.theta - cv_theta)) < 0.03
        assert np.degrees(np.arccos(np.clip(mine.direction @ cv_dir, -1, 1))) < 5.0


def test_covariance_is_positive_definite_and_grows_with_noise():
    rng = np.random.default_rng(8)
    poses = _pano_poses(rng)
    traces = []
    for noise in (0.25, 1.0, 3.0):
        views = render_views(PANO, poses, np.random.default_rng(9), noise_px=noise)
        motion = relative_motion(views.uv[0], views.uv[1], PANO, rng=0,
                                 config=TwoViewConfig(threshold_px=max(1.5, 3 * noise)))
        assert np.all(np.linalg.eigvalsh(motion.covariance) > 0)
        traces.append(np.trace(motion.covariance))
    assert traces[0] < traces[1] < traces[2]


def test_planar_epipolar_residuals_vanish_at_the_truth_only():
    rng = np.random.default_rng(4)
    views = render_views(PANO, _pano_poses(rng), rng)
    rays = [PANO.unproject(views.uv[k]) for k in range(2)]
    theta, phi = views.truth(0, 1)
    assert np.abs(planar_epipolar_residuals(rays[0], rays[1], theta, phi)).max() < 1e-12
    assert np.abs(planar_epipolar_residuals(rays[0], rays[1], theta + 0.01, phi)).max() > 1e-3


# -- degenerate input -------------------------------------------------------------------
def test_too_few_correspondences_are_refused():
    rng = np.random.default_rng(6)
    views = render_views(PANO, _pano_poses(rng), rng)
    rays = [PANO.unproject(views.uv[k]) for k in range(2)]
    with pytest.raises(VbnCommonError, match='at least 3 correspondences, got 2'):
        panoramic_planar_motion(rays[0][:2], rays[1][:2])
    with pytest.raises(VbnCommonError, match='at least 4 correspondences, got 3'):
        pinhole_planar_essential(rays[0][:3], rays[1][:3])
    with pytest.raises(VbnCommonError, match='at least 8 correspondences, got 7'):
        general_essential(rays[0][:7], rays[1][:7])
    with pytest.raises(VbnCommonError, match='same shape'):
        general_essential(rays[0][:9], rays[1][:8])


def test_points_on_the_horizon_are_refused_by_the_panoramic_method():
    rng = np.random.default_rng(7)
    poses = _pano_poses(rng)
    points = np.column_stack([rng.uniform(0, 6, 40), np.full(40, 3.0), np.full(40, 1.2)])
    uv = [PANO.project(world_points_to_camera(p, 1.2, points))[0] for p in poses]
    with pytest.raises(VbnCommonError, match='off the horizon.*got 0 of 40'):
        relative_motion(uv[0], uv[1], PANO, rng=0)


@pytest.mark.parametrize('camera,method', [(PANO, m) for m in PANO_METHODS]
                         + [(PIN, m) for m in PIN_METHODS])
@pytest.mark.parametrize('noise', [0.0, 0.5])
def test_identical_poses_are_refused(camera, method, noise):
    for seed in range(5):
        rng = np.random.default_rng(seed)
        pose = (_pano_poses if camera is PANO else _pin_poses)(rng)[0]
        views = render_views(camera, np.stack([pose, pose]), rng, noise_px=noise)
        with pytest.raises(VbnCommonError, match='same place'):
            relative_motion(views.uv[0], views.uv[1], camera, method=method, rng=seed)


def test_the_parallax_ratio_can_be_disabled():
    rng = np.random.default_rng(10)
    pose = _pano_poses(rng)[0]
    views = render_views(PANO, np.stack([pose, pose]), rng, noise_px=0.5)
    with pytest.raises(VbnCommonError, match='same place'):
        relative_motion(views.uv[0], views.uv[1], PANO, rng=0)
    motion = relative_motion(views.uv[0], views.uv[1], PANO, rng=0,
                             config=TwoViewConfig(min_parallax_ratio=0.0))
    assert motion.inliers.sum() > 40
    with pytest.raises(VbnCommonError, match='min_parallax_ratio must be >= 0'):
        TwoViewConfig(min_parallax_ratio=-1.0)


@pytest.mark.parametrize('method', PANO_METHODS)
def test_two_centimetres_apart_are_not_refused_without_noise(method):
    rng = np.random.default_rng(9)
    pose = _pano_poses(rng)[0]
    views = render_views(PANO, np.stack([pose, pose + [0.02, 0.0, 0.1]]), rng)
    motion = relative_motion(views.uv[0], views.uv[1], PANO, method=method, rng=0)
    assert max(_errors(motion, views)) < 1e-6


def test_unknown_method_and_wrong_camera_are_refused():
    uv = np.zeros((10, 2))
    with pytest.raises(VbnCommonError, match="unknown two-view method 'eight'"):
        relative_motion(uv, uv, PANO, method='eight')
    with pytest.raises(VbnCommonError, match='needs a panoramic camera'):
        relative_motion(uv, uv, PIN, method='panoramic_planar')
    with pytest.raises(VbnCommonError, match='threshold_px must be a positive'):
        TwoViewConfig(threshold_px=0.0)


# -- 7.3: linear combination of views ---------------------------------------------------
def _lcv_scene(rng, distance, size, n=60, outliers=0.0):
    points = np.column_stack([distance + rng.uniform(-size / 2, size / 2, n),
                              rng.uniform(-size / 2, size / 2, n),
                              1.2 + rng.uniform(-size / 2, size / 2, n)])
    scale = distance / 5.0
    poses = np.array([[0.0, -0.5 * scale, 0.15], [0.2 * scale, 0.5 * scale, -0.15],
                      [0.3 * scale, 0.1 * scale, 0.05]])
    uv = [PIN.project(world_points_to_camera(p, 1.2, points))[0] for p in poses]
    if outliers:
        bad = rng.choice(n, int(outliers * n), replace=False)
        uv[2][bad] = rng.uniform([0, 0], [639, 479], (len(bad), 2))
    rays = [PIN.unproject(u) for u in uv]
    return poses, rays


def test_linear_combination_of_views_converges_as_weak_perspective_becomes_exact():
    # Weak perspective is exact in the limit of a shallow scene: the error falls with
    # the scene's depth range over its distance (10 m here).
    errors = np.zeros((4, 3))
    for seed in range(4):
        for j, size in enumerate((4.0, 1.0, 0.25)):
            poses, rays = _lcv_scene(np.random.default_rng(seed), 10.0, size)
            pose_b_in_a = compose_poses(invert_pose(poses[0]), poses[1])
            motion_a, motion_b = linear_combination_of_views(*rays, pose_b_in_a, threshold=1.0)
            truth_a = compose_poses(invert_pose(poses[0]), poses[2])
            truth_b = compose_poses(invert_pose(poses[1]), poses[2])
            errors[seed, j] = max(
                abs(wrap_angle(motion_a.theta - truth_a[2])),
                abs(wrap_angle(motion_a.phi - math.atan2(truth_a[1], truth_a[0]))),
                abs(wrap_angle(motion_b.theta - truth_b[2])),
                abs(wrap_angle(motion_b.phi - math.atan2(truth_b[1], truth_b[0]))))
    mean = errors.mean(axis=0)
    assert mean[0] > mean[1] > mean[2]
    assert mean[2] < mean[0] / 5
    assert mean[2] < 2e-3


def test_linear_combination_of_views_rejects_outliers():
    rng = np.random.default_rng(1)
    poses, rays = _lcv_scene(rng, 10.0, 0.5, n=80)
    wrong = rng.choice(80, 20, replace=False)
    current = rays[2].copy()
    current[wrong] = PIN.unproject(rng.uniform([0, 0], [639, 479], (20, 2)))
    pose_b_in_a = compose_poses(invert_pose(poses[0]), poses[1])
    clean, _ = linear_combination_of_views(*rays, pose_b_in_a, threshold=2e-3, rng=0)
    robust, _ = linear_combination_of_views(rays[0], rays[1], current, pose_b_in_a,
                                            threshold=2e-3, rng=0)
    truth = compose_poses(invert_pose(poses[0]), poses[2])
    assert abs(wrap_angle(clean.theta - truth[2])) < 3e-3
    assert abs(wrap_angle(robust.theta - truth[2])) < 3e-3
    assert not robust.inliers[wrong].any()
    assert robust.inliers.sum() >= 55


def test_linear_combination_of_views_refuses_degenerate_input():
    rng = np.random.default_rng(2)
    poses, rays = _lcv_scene(rng, 10.0, 1.0)
    with pytest.raises(VbnCommonError, match='directions only'):
        linear_combination_of_views(rays[0], rays[0], rays[2], np.array([0.0, 0.0, 0.0]) +
                                    [0.0, 1e-9, 0.0])
    with pytest.raises(VbnCommonError, match='in front'):
        linear_combination_of_views(-rays[0], rays[1], rays[2], np.array([0.0, 1.0, 0.3]))
    with pytest.raises(VbnCommonError, match='pose_b_in_a'):
        linear_combination_of_views(rays[0], rays[1], rays[2], np.array([0.0, 1.0]))


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_pointwise_residuals_equal_each_motions_own(seed: int) -> None:
    """The closed form per correspondence equals the essential matrix's Sampson error."""
    rng = np.random.default_rng(seed)
    f1, f2 = rng.normal(size=(2, 12, 3))
    f1 /= np.linalg.norm(f1, axis=1, keepdims=True)
    f2 /= np.linalg.norm(f2, axis=1, keepdims=True)
    theta, phi = rng.uniform(-math.pi, math.pi, size=(2, 12))
    each = [planar_epipolar_residuals(f1[i:i + 1], f2[i:i + 1], theta[i], phi[i])[0]
            for i in range(12)]
    assert np.allclose(pointwise_planar_residuals(f1, f2, theta, phi), each, atol=1e-12)
    # (m, n) motions: one row per set, as the localizer scores a pose and its probes.
    rows = pointwise_planar_residuals(f1, f2, np.stack([theta, theta[::-1]]),
                                      np.stack([phi, phi[::-1]]))
    assert rows.shape == (2, 12) and np.allclose(rows[0], each, atol=1e-12)
    assert np.allclose(rows[1], pointwise_planar_residuals(f1, f2, theta[::-1], phi[::-1]))
    # Every motion scored on every correspondence (the robust solvers' form).
    grid = planar_sampson(f1 @ BASE_TO_CAMERA_ROTATION.T, f2 @ BASE_TO_CAMERA_ROTATION.T,
                          theta[:3, None], phi[:3, None])
    assert grid.shape == (3, 12)
    for k in range(3):
        assert np.allclose(grid[k], planar_epipolar_residuals(f1, f2, theta[k], phi[k]),
                           atol=1e-12)


def test_pointwise_residuals_vanish_on_an_exact_planar_motion() -> None:
    # The current camera 1 m ahead of the model camera (phi = 0), turned 90 degrees: a
    # point at (2, 1, 0.5) in the model's planar frame is (1, -1, 0.5) seen from the
    # current camera's position, (1, -1, 0.5) in its own planar frame turned +90 degrees.
    m = BASE_TO_CAMERA_ROTATION
    model = np.array([2.0, 1.0, 0.5])
    current = np.array([1.0, -1.0, 0.5])
    f1 = (m.T @ model / np.linalg.norm(model))[None]
    f2 = (m.T @ current / np.linalg.norm(current))[None]
    assert abs(pointwise_planar_residuals(f1, f2, np.array([math.pi / 2]),
                                          np.array([0.0]))[0]) < 1e-12
    assert abs(pointwise_planar_residuals(f1, f2, np.array([0.0]), np.array([0.0]))[0]) > 0.1
