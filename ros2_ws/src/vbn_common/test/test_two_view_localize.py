"""Tests of the pose from two or more model views (ray intersection, heading, covariance)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from two_view_samples import render_views

from vbn_common.errors import VbnCommonError
from vbn_common.geometry import (
    compose_poses,
    invert_pose,
    make_camera,
    wrap_angle,
)
from vbn_common.geometry.localize import position_from_two_views, position_from_views
from vbn_common.geometry.motion import RelativeMotion
from vbn_common.geometry.two_view import relative_motion

PANO = make_camera('panoramic')


def _motion(model: np.ndarray, current: np.ndarray, sigma_phi: float = 1e-3,
            sigma_theta: float = 1e-3) -> RelativeMotion:
    """The exact motion from ``model`` to ``current`` (camera poses in map)."""
    rel = compose_poses(invert_pose(model), current)
    direction = rel[:2] / np.hypot(rel[0], rel[1])
    return RelativeMotion(theta=float(rel[2]), direction=direction,
                          inliers=np.ones(10, dtype=bool), residual=0.0, method='exact',
                          covariance=np.diag([sigma_theta ** 2, sigma_phi ** 2]))


def test_two_exact_rays_give_the_current_camera_pose_in_map():
    a, b = np.array([1.0, 1.0, 0.3]), np.array([2.0, 1.2, -2.0])
    current = np.array([1.4, 2.1, 2.5])
    est = position_from_two_views(a, _motion(a, current), b, _motion(b, current))
    np.testing.assert_allclose(est.pose, current, atol=1e-12)
    assert est.n_views == 2 and est.in_front and est.residual < 1e-12
    u, v = _unit(current - a), _unit(current - b)
    assert est.ray_angle == pytest.approx(abs(math.asin(u[0] * v[1] - u[1] * v[0])))


def _unit(v):
    return v[:2] / np.linalg.norm(v[:2])


def test_hand_checkable_intersection():
    # Model a at the origin facing +x sees the robot straight ahead; model b at (2, -2)
    # facing +y sees it straight ahead: the robot is at (2, 0).
    motion_a = RelativeMotion(0.0, np.array([1.0, 0.0]), np.ones(4, bool), 0.0, 'hand',
                              np.diag([1e-6, 1e-6]))
    motion_b = RelativeMotion(-math.pi / 2, np.array([1.0, 0.0]), np.ones(4, bool), 0.0,
                              'hand', np.diag([1e-6, 1e-6]))
    est = position_from_two_views([0, 0, 0], motion_a, [2, -2, math.pi / 2], motion_b)
    np.testing.assert_allclose([est.x, est.y, est.yaw], [2.0, 0.0, 0.0], atol=1e-12)
    assert est.ray_angle == pytest.approx(math.pi / 2)


def test_panoramas_end_to_end_recover_the_pose():
    rng = np.random.default_rng(0)
    poses = np.array([[2.0, 1.0, 0.0], [3.0, 1.3, 0.0], [2.6, 1.9, 1.1]])
    views = render_views(PANO, poses, rng)
    motion_a = relative_motion(views.uv[0], views.uv[2], PANO, rng=0)
    motion_b = relative_motion(views.uv[1], views.uv[2], PANO, rng=0)
    est = position_from_two_views(poses[0], motion_a, poses[1], motion_b)
    np.testing.assert_allclose(est.pose, poses[2], atol=1e-6)
    noisy = render_views(PANO, poses, rng, noise_px=0.5)
    est = position_from_two_views(poses[0], relative_motion(noisy.uv[0], noisy.uv[2], PANO, rng=0),
                                  poses[1], relative_motion(noisy.uv[1], noisy.uv[2], PANO, rng=0))
    assert math.hypot(est.x - 2.6, est.y - 1.9) < 0.03
    assert abs(wrap_angle(est.yaw - 1.1)) < 0.01
    # the reported standard deviation is of the order of the error
    assert 1e-4 < math.sqrt(np.trace(est.covariance[:2, :2])) < 0.1


def test_covariance_grows_as_the_rays_become_parallel():
    a, b = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])
    angles, sizes = [], []
    for y in (0.5, 0.2, 0.05, 0.01):
        current = np.array([0.5, y, 0.0])
        est = position_from_two_views(a, _motion(a, current), b, _motion(b, current))
        np.testing.assert_allclose(est.pose, current, atol=1e-9)
        angles.append(est.ray_angle)
        sizes.append(np.linalg.eigvalsh(est.covariance[:2, :2]).max())
    assert all(np.diff(angles) < 0)
    assert all(np.diff(sizes) > 0)
    # along the baseline the standard deviation grows as 1 / sin(angle)
    assert sizes[-1] > 100 * sizes[0]


def test_parallel_rays_are_refused_and_a_third_view_fixes_the_position():
    a, b, c = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.3]), np.array([0.5, 2.0, -1])
    current = np.array([3.0, 0.0, 0.2])          # on the line through a and b
    with pytest.raises(VbnCommonError, match='parallel'):
        position_from_two_views(a, _motion(a, current), b, _motion(b, current))
    est = position_from_views(np.stack([a, b, c]),
                              [_motion(a, current), _motion(b, current), _motion(c, current)])
    np.testing.assert_allclose(est.pose, current, atol=1e-9)
    assert est.n_views == 3


def test_three_views_weight_the_better_rays_and_report_disagreement():
    a, b, c = np.array([0.0, 0.0, 0.0]), np.array([2.0, 0.0, 0.0]), np.array([1.0, 3.0, 0.0])
    current = np.array([1.0, 1.0, 0.5])
    good = [_motion(a, current), _motion(b, current)]
    bad = _motion(c, current + [0.3, 0.0, 0.0])            # a ray that misses by ~0.2 m
    precise = position_from_views(np.stack([a, b, c]), good + [bad])
    assert precise.residual > 0.01
    assert not np.allclose(precise.pose[:2], current[:2], atol=1e-6)
    # the same wrong ray, declared uncertain, barely moves the estimate
    vague = RelativeMotion(bad.theta, bad.direction, bad.inliers, 0.0, 'exact',
                           np.diag([1e-6, 1e-1 ** 2]))
    weighted = position_from_views(np.stack([a, b, c]), good + [vague])
    assert (np.linalg.norm(weighted.pose[:2] - current[:2])
            < 0.1 * np.linalg.norm(precise.pose[:2] - current[:2]))


def test_heading_is_the_weighted_circular_mean_across_pi():
    a, b = np.array([0.0, 0.0, 3.1]), np.array([1.0, 0.0, -3.1])
    current = np.array([0.5, 1.0, math.pi - 0.01])
    m_a, m_b = _motion(a, current), _motion(b, current)
    m_a = RelativeMotion(m_a.theta + 0.02, m_a.direction, m_a.inliers, 0.0, 'x',
                         np.diag([1e-2, 1e-6]))       # rotation off by 0.02, uncertain
    est = position_from_two_views(a, m_a, b, m_b)
    assert abs(wrap_angle(est.yaw - current[2])) < 0.001
    assert -math.pi <= est.yaw < math.pi


def test_rays_pointing_away_are_flagged():
    a, b = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])
    current = np.array([0.5, 1.0, 0.0])
    flipped = _motion(b, current)
    flipped = RelativeMotion(flipped.theta, -flipped.direction, flipped.inliers, 0.0, 'x',
                             flipped.covariance)
    assert not position_from_two_views(a, _motion(a, current), b, flipped).in_front


def test_bad_input_is_refused():
    a = np.array([0.0, 0.0, 0.0])
    m = _motion(a, np.array([1.0, 1.0, 0.0]))
    with pytest.raises(VbnCommonError, match='at least two model views, got 1'):
        position_from_views(a[None], [m])
    with pytest.raises(VbnCommonError, match='one row per motion'):
        position_from_views(np.stack([a, a]), [m])
    with pytest.raises(VbnCommonError, match=r'\(x, y, yaw\)'):
        position_from_two_views([0.0, 0.0], m, a, m)
    with pytest.raises(VbnCommonError, match='finite'):
        position_from_views(np.array([[0, 0, 0], [np.nan, 0, 0]]), [m, m])
