"""The compiled kernels of a tracked frame's refinements against their numpy definitions."""
from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from landmark_localizer.angular_kernels import (
    SINGULAR,
    gauss_newton,
    normal_equations,
    solve_in_place,
)
from landmark_localizer.planar_kernels import planar_residuals, refine_planar
from vbn_common.geometry.epipolar import pointwise_planar_residuals
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION, wrap_angle


def _unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _ray_problem(seed: int, n: int) -> tuple[np.random.Generator, np.ndarray, np.ndarray,
                                             np.ndarray]:
    """``(rng, points, rays, state)``: random points and rays, a state with tilt and height."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-3, 3, (n, 3))
    rays = _unit(rng, n)
    state = np.r_[rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi),
                  rng.uniform(-0.1, 0.1, 2), rng.uniform(-0.2, 0.2)]
    return rng, points, rays, state


def test_the_small_solver_matches_lapack_and_reports_a_singular_matrix() -> None:
    rng = np.random.default_rng(3)
    for n in (3, 4, 6):
        a = rng.normal(size=(n, n))
        b = rng.normal(size=n)
        x = b.copy()
        assert solve_in_place(a.copy(), x, SINGULAR)
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-10, atol=1e-12)
    # Needs a row swap: the first pivot is 0.
    x = np.array([2.0, 3.0])
    assert solve_in_place(np.array([[0.0, 1.0], [1.0, 0.0]]), x, 0.0)
    np.testing.assert_array_equal(x, [3.0, 2.0])
    singular = np.array([[1.0, 2.0], [2.0, 4.0]])
    assert not solve_in_place(singular.copy(), np.ones(2), 0.0)
    # Below OpenCV's DECOMP_LU threshold: singular for it, not for an exact test.
    tiny = np.diag([1.0, 1e-15])
    assert not solve_in_place(tiny.copy(), np.ones(2), SINGULAR)
    x = np.ones(2)
    assert solve_in_place(tiny.copy(), x, 0.0) and x[1] == pytest.approx(1e15)


def _numpy_normal_equations(state, rays, points, threshold, weights):
    from landmark_localizer.absolute_pose import _residuals

    r = _residuals(state, rays, points)
    jac = np.empty((len(rays), 3, 6))
    for k in range(6):
        step = np.zeros(6)
        step[k] = 1e-7
        jac[:, :, k] = (_residuals(state + step, rays, points)
                        - _residuals(state - step, rays, points)) / 2e-7
    norms = np.linalg.norm(r, axis=1)
    w = np.minimum(1.0, threshold / norms) * weights
    hessian = np.einsum('n,nki,nkj->ij', w, jac, jac)
    gradient = np.einsum('n,nki,nk->i', w, jac, r)
    return hessian, gradient, float(np.sum(weights * norms ** 2))


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.integers(0, 10**6))
def test_the_normal_equations_are_the_huber_weighted_least_squares_ones(seed: int) -> None:
    """J^T W J, J^T W r and the weighted squares, with J by central differences."""
    rng, points, rays, state = _ray_problem(seed, 15)
    weights = rng.uniform(0.2, 2.0, 15)
    threshold = 0.3   # some rays within it (weight 1), some beyond (Huber)
    hessian, gradient = np.empty((6, 6)), np.empty(6)
    squares = normal_equations(state, rays, points, threshold, weights, hessian, gradient)
    h, g, s = _numpy_normal_equations(state, rays, points, threshold, weights)
    np.testing.assert_allclose(hessian, h, atol=1e-6)
    np.testing.assert_allclose(gradient, g, atol=1e-6)
    assert squares == pytest.approx(s, rel=1e-12)


def test_gauss_newton_holds_the_unknowns_not_free_and_reports_a_failure() -> None:
    rng = np.random.default_rng(5)
    truth = np.array([0.4, -0.3, 0.7, 0.0, 0.0, 0.0])
    points = rng.uniform(-3, 3, (30, 3)) + [0, 0, 1.0]
    v = points - [truth[0], truth[1], 0.0]
    c, s = math.cos(truth[2]), math.sin(truth[2])
    rays = np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]])
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    state = truth + [0.05, -0.04, 0.03, 0.0, 0.0, 0.0]
    free = np.array([0, 1, 2])
    steps = gauss_newton(state, rays, points, 1.0, np.ones(30), free, np.zeros(3), np.zeros(6),
                         20, 1e-9, 1e-10)
    assert 1 <= steps < 20
    np.testing.assert_allclose(state, truth, atol=1e-10)   # pitch, roll, dz stay 0
    # A ray that is not finite: no state.
    rays[3] = np.nan
    assert gauss_newton(truth.copy(), rays, points, 1.0, np.ones(30), free, np.zeros(3),
                        np.zeros(6), 5, 1e-9, 1e-10) == -1


def _planar_setup(rng: np.random.Generator, n: int):
    view_poses = np.column_stack([rng.uniform(-2, 2, (3, 2)), rng.uniform(-np.pi, np.pi, 3)])
    view = rng.integers(0, 3, n)
    return view_poses, view, _unit(rng, n), _unit(rng, n)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.integers(0, 10**6))
def test_planar_residuals_are_the_sampson_errors_of_each_views_motion(seed: int) -> None:
    rng = np.random.default_rng(seed)
    view_poses, view, model, current = _planar_setup(rng, 40)
    pose = np.r_[rng.uniform(-2, 2, 2), rng.uniform(-np.pi, np.pi)]
    dx, dy = pose[0] - view_poses[:, 0], pose[1] - view_poses[:, 1]
    c, s = np.cos(view_poses[:, 2]), np.sin(view_poses[:, 2])
    theta = wrap_angle(pose[2] - view_poses[:, 2])
    phi = np.arctan2(-s * dx + c * dy, c * dx + s * dy)
    expected = pointwise_planar_residuals(model, current, theta[view], phi[view])
    out = np.empty(40)
    planar_residuals(pose, view_poses, view, model @ BASE_TO_CAMERA_ROTATION.T,
                     current @ BASE_TO_CAMERA_ROTATION.T, out)
    np.testing.assert_allclose(out, expected, atol=1e-12)


def test_the_planar_refinement_finds_the_pose_the_views_saw() -> None:
    """Rays of 3-D points seen from three model views and the true pose: the pose back."""
    rng = np.random.default_rng(8)
    view_poses = np.array([[0.0, 0.0, 0.2], [1.0, 0.3, -0.4], [0.2, 1.1, 1.0]])
    truth = np.array([0.6, 0.5, 0.3])
    points = np.column_stack([rng.uniform(-4, 4, (60, 2)), rng.uniform(-1, 1, 60)])
    view = np.repeat([0, 1, 2], 20)

    def rays(pose, pts):
        v = pts - [pose[0], pose[1], 0.0]
        c, s = math.cos(pose[2]), math.sin(pose[2])
        out = np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]])
        return out / np.linalg.norm(out, axis=1, keepdims=True)

    g1 = np.concatenate([rays(view_poses[k], points[view == k]) for k in range(3)])
    g2 = rays(truth, points)
    pose = truth + [0.03, -0.02, 0.01]
    r, jac = np.empty(60), np.empty((60, 3))
    assert refine_planar(pose, view_poses, view, g1, g2, 0.01, 20, r, jac)
    np.testing.assert_allclose(pose, truth, atol=1e-6)
    assert np.abs(r).max() < 1e-8
    # The Jacobian returned is the residuals' forward difference at the pose.
    probe = pose + [1e-4, 0.0, 0.0]
    moved = np.empty(60)
    planar_residuals(probe, view_poses, view, g1, g2, moved)
    np.testing.assert_allclose(jac[:, 0], (moved - r) / 1e-4, atol=1e-9)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.integers(0, 10**6))
def test_angular_errors_are_the_angles_at_the_tilted_state(seed: int) -> None:
    from landmark_localizer.absolute_pose import _angular_errors
    from landmark_localizer.angular_kernels import angular_errors
    from landmark_localizer.index import tilt_rotation

    _, points, rays, state = _ray_problem(seed, 20)
    expected = _angular_errors(state[None, :3], rays @ tilt_rotation(state[3], state[4]).T,
                               points - [0.0, 0.0, state[5]])[0]
    np.testing.assert_allclose(angular_errors(state, rays, points), expected, atol=1e-9)
    # Exact rays: 0 (the half-angle form keeps small angles exact, unlike arccos).
    exact = points - [state[0], state[1], state[5]]
    c, s = math.cos(state[2]), math.sin(state[2])
    level = np.column_stack([c * exact[:, 0] + s * exact[:, 1], -s * exact[:, 0]
                             + c * exact[:, 1], exact[:, 2]])
    level /= np.linalg.norm(level, axis=1, keepdims=True)
    turned = level @ tilt_rotation(state[3], state[4])   # R^T: the rays the tilt sees
    assert angular_errors(state, turned, points).max() < 1e-12


def test_coarse_inliers_are_the_numpy_definitions() -> None:
    """Azimuth, elevation with the tilt and height slack, in front: against numpy."""
    from landmark_localizer.absolute_pose import _coarse_inliers, _predicted

    rng = np.random.default_rng(12)
    poses = np.column_stack([rng.uniform(-1, 1, (7, 2)), rng.uniform(-np.pi, np.pi, 7)])
    points = rng.uniform(-4, 4, (50, 3))
    rays = _predicted(poses[:1], points)[0] + rng.normal(0, 0.02, (50, 3))
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    threshold, tilt, height = 0.02, 0.005, 0.05
    v = _predicted(poses, points)
    azimuth = np.arctan2(v[..., 1], v[..., 0]) - np.arctan2(rays[:, 1], rays[:, 0])
    azimuth = np.abs((azimuth + math.pi) % (2 * math.pi) - math.pi)
    horizontal = np.hypot(v[..., 0], v[..., 1])
    elevation = np.abs(np.arctan2(v[..., 2], horizontal)
                       - np.arctan2(rays[:, 2], np.hypot(rays[:, 0], rays[:, 1])))
    distance = np.hypot(points[None, :, 0] - poses[:, None, 0],
                        points[None, :, 1] - poses[:, None, 1])
    slack = threshold + 3.0 * tilt + 3.0 * height / np.maximum(distance, 0.5)
    expected = (azimuth * horizontal <= threshold) & (elevation <= slack) & \
        (np.einsum('mnk,nk->mn', v, rays) > 0)
    got = _coarse_inliers(poses, rays, points, threshold, tilt, height)
    assert got.shape == (7, 50) and np.array_equal(got, expected)
    assert 10 < got[0].sum() < 50   # the first pose explains most of its noisy rays


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.integers(0, 10**6))
def test_tilted_errors_are_the_numpy_coplanarity_errors(seed: int) -> None:
    from landmark_localizer.tilt_kernels import tilted_errors
    from landmark_localizer.tilt_refinement import _Problem, tilted_residuals

    rng = np.random.default_rng(seed)
    view_poses, view, model, current = _planar_setup(rng, 30)
    state = np.r_[rng.uniform(-2, 2, 2), rng.uniform(-np.pi, np.pi),
                  rng.uniform(-0.05, 0.05, 2), rng.uniform(-0.2, 0.2)]
    problem = _Problem(view_poses, view, model, current)
    out = np.empty(30)
    tilted_errors(state, BASE_TO_CAMERA_ROTATION, np.ascontiguousarray(problem.vx),
                  np.ascontiguousarray(problem.vy), np.stack(problem.a1, axis=1), problem.g2,
                  out)
    np.testing.assert_allclose(out, tilted_residuals(state[None], view_poses, view, model,
                                                     current)[0], atol=1e-12)


def test_the_tilted_refinement_returns_the_forward_differences_at_its_state() -> None:
    from landmark_localizer.tilt_kernels import STEP, refine_tilted_in_place, tilted_errors

    rng = np.random.default_rng(9)
    view_poses, view, model, current = _planar_setup(rng, 40)
    vx, vy = view_poses[view, 0].copy(), view_poses[view, 1].copy()
    a1, g2 = _unit(rng, 40), _unit(rng, 40)
    state, r, jac = np.array([0.3, 0.1, 0.2, 0.0, 0.0, 0.0]), np.empty(40), np.empty((40, 6))
    prior = np.array([0.0, 0.0, 0.0, 50.0, 50.0, 10.0])
    assert refine_tilted_in_place(state, np.eye(3), vx, vy, a1, g2, 0.05, prior, 3, r, jac)
    expected = np.empty(40)
    tilted_errors(state, np.eye(3), vx, vy, a1, g2, expected)
    np.testing.assert_array_equal(r, expected)
    for k in (0, 3, 5):
        probe = state.copy()
        probe[k] += STEP[k]
        tilted_errors(probe, np.eye(3), vx, vy, a1, g2, expected)
        np.testing.assert_allclose(jac[:, k], (expected - r) / STEP[k], atol=1e-9)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.integers(0, 10**6))
def test_optical_points_turn_shift_and_tilt_as_the_matrices_do(seed: int) -> None:
    from landmark_localizer.index import _optical_points, tilt_rotation

    _, points, _, state = _ray_problem(seed, 12)
    points[3] = [np.nan, 1.0, 1.0]
    c, s = math.cos(state[2]), math.sin(state[2])
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])   # base -> world
    base = (points - [state[0], state[1], state[5]]) @ turn          # R_z^T (p - t)
    expected = base @ tilt_rotation(state[3], state[4]) @ BASE_TO_CAMERA_ROTATION
    optical, finite = _optical_points(state, points, BASE_TO_CAMERA_ROTATION)
    assert finite.tolist() == [i != 3 for i in range(12)]
    np.testing.assert_allclose(optical[finite], expected[finite], atol=1e-12)
    # A level state leaves the height alone.
    level = np.r_[state[:3], 0.0, 0.0, 0.0]
    flat, _ = _optical_points(level, points, np.eye(3))
    np.testing.assert_allclose(flat[finite], ((points - [state[0], state[1], 0.0]) @ turn)[
        finite], atol=1e-12)


def test_the_warm_up_compiles_every_kernel_a_tracked_frame_calls() -> None:
    from landmark_localizer import angular_kernels, index, planar_kernels, tilt_kernels, tracking
    from landmark_localizer.compiled import warm_up
    from vbn_common import patch_alignment
    from vbn_common.geometry import lens

    warm_up()
    kernels = [angular_kernels.gauss_newton, angular_kernels.normal_equations,
               angular_kernels.angular_errors, angular_kernels.coarse_inliers,
               planar_kernels.refine_planar, tilt_kernels.refine_tilted_in_place,
               index._optical_points,
               tracking.disc_mask, tracking._nearest_keypoint,
               lens._equidistant_newton, lens.brown_invert, lens.brown_project,
               patch_alignment._brightness_kernel,
               patch_alignment._correlation_kernel, patch_alignment._mosaic,
               patch_alignment._remap_sources]
    assert [k.py_func.__name__ for k in kernels if not k.signatures] == []
