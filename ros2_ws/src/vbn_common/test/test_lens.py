"""Lens distortion: plumb_bob, rational_polynomial and the equidistant fisheye."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from vbn_common.errors import VbnCommonError
from vbn_common.geometry import lens
from vbn_common.geometry.camera import PinholeCamera, camera_from_info, make_camera
from vbn_common.geometry.fisheye import FisheyeCamera
from vbn_common.geometry.two_view import relative_motion

PLUMB_BOB = ('plumb_bob', (-0.28, 0.07, 0.001, -0.0005, 0.0))
RATIONAL = ('rational_polynomial', (0.5, -0.1, 0.001, 0.0005, 0.01, 0.8, 0.0, 0.02))
FISHEYE = ('equidistant', (0.05, -0.01, 0.002, -0.0003))


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), (a * b).sum(axis=1))


def test_plumb_bob_hand_checked() -> None:
    # k1 only: the point (x, y) = (0.5, 0) moves to 0.5 (1 + k1 0.25) = 0.475 at k1 = -0.2.
    camera = PinholeCamera(640, 480, 400.0, 400.0, 320.0, 240.0, distortion_model='plumb_bob',
                           d=(-0.2, 0.0, 0.0, 0.0, 0.0))
    uv, ok = camera.project(np.array([[1.0, 0.0, 2.0]]))
    assert ok[0] and uv[0] == pytest.approx([320.0 + 400.0 * 0.475, 240.0])
    ray = camera.unproject(uv)[0]
    assert ray == pytest.approx(np.array([0.5, 0.0, 1.0]) / math.hypot(0.5, 1.0), abs=1e-12)
    # r (1 - 0.5 r^2) stops growing at r = sqrt(2 / 3): a point beyond is not in the image.
    assert lens.brown_limit(np.array([-0.5, 0, 0, 0, 0])) == pytest.approx(
        math.sqrt(2 / 3), abs=1e-3)
    steep = PinholeCamera(640, 480, 100.0, 100.0, 320.0, 240.0, d=(-0.5, 0, 0, 0, 0))
    assert steep.project(np.array([[0.7, 0.0, 1.0], [0.9, 0.0, 1.0]]))[1].tolist() == [
        True, False]


@pytest.mark.parametrize('d', [PLUMB_BOB[1], (-0.5, 0.0, 0.0, 0.0, 0.0),
                               (-0.35, 0.12, 0.002, 0.001, -0.02)])
def test_brown_inversion_finds_the_undistorted_point_up_to_the_limit(d) -> None:
    """Back to machine precision, also near the radius where the mapping stops growing.

    Under k1 = -0.5 the former inversion (OpenCV's ``undistortPoints``, then five Newton
    steps) ended 4e-5 short of points near the limit; the halved Newton steps do not.
    """
    d = np.asarray(d)
    rng = np.random.default_rng(4)
    radius = rng.uniform(0.0, 0.999 * min(lens.brown_limit(d), 1.5), 3000)
    angle = rng.uniform(-np.pi, np.pi, 3000)
    truth = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    xd, yd = lens.brown_distort(truth[:, 0], truth[:, 1], d)
    k = np.array([[400.0, 0.0, 320.0], [0.0, 410.0, 240.0], [0.0, 0.0, 1.0]])
    uv = np.column_stack([320.0 + 400.0 * xd, 240.0 + 410.0 * yd])
    np.testing.assert_allclose(lens.brown_undistort(uv, k, d), truth, rtol=0, atol=1e-13)
    assert lens.brown_undistort(np.zeros((0, 2)), k, d).shape == (0, 2)
    # A pixel that is not finite stays NaN rather than looping.
    assert np.isnan(lens.brown_undistort(np.array([[np.nan, 3.0]]), k, d)).all()


@pytest.mark.parametrize('distortion', [PLUMB_BOB, RATIONAL])
def test_pinhole_distortion_is_opencvs_and_inverts(distortion) -> None:
    camera = make_camera('pinhole', distortion=distortion)
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(-1, 1, (400, 2)), np.ones(400)]) * rng.uniform(
        1, 5, (400, 1))
    uv, ok = camera.project(points)
    assert ok.sum() > 300
    reference, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), camera.k_matrix,
                                     np.array(distortion[1]))
    np.testing.assert_allclose(uv, reference.reshape(-1, 2), atol=1e-9)
    assert _angles(camera.unproject(uv[ok]), points[ok]).max() < 1e-10
    assert camera_from_info(camera.camera_info()) == camera


@pytest.mark.parametrize('d', [(), FISHEYE[1]])
def test_fisheye_is_opencvs_in_front_and_sees_behind_up_to_its_field(d) -> None:
    camera = make_camera('fisheye', hfov_deg=200.0, distortion=('equidistant', d))
    assert isinstance(camera, FisheyeCamera) and camera.kind == 'fisheye'
    rng = np.random.default_rng(2)
    rays = rng.normal(size=(3000, 3))
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    uv, ok = camera.project(rays)
    front = rays[:, 2] > 0.1
    reference, _ = cv2.fisheye.projectPoints(
        rays[front].reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
        np.array([[camera.fx, 0, camera.cx], [0, camera.fy, camera.cy], [0, 0, 1.0]]),
        np.array(d or (0.0,) * 4, float))
    np.testing.assert_allclose(uv[front], reference.reshape(-1, 2), atol=1e-9)
    # 200 degrees across the width: rays behind the camera are in the image, none
    # further off axis than the image corner's.
    corner = camera.unproject(np.array([[-0.5, -0.5]]))[0]
    behind = ok & (rays[:, 2] < 0)
    assert behind.any() and np.all(rays[behind, 2] >= corner[2] - 1e-9)
    assert _angles(camera.unproject(uv[ok]), rays[ok]).max() < 1e-10
    edge = camera.unproject(np.array([[camera.cx + camera.width / 2.0, camera.cy]]))[0]
    assert math.degrees(math.acos(edge[2])) == pytest.approx(100.0, abs=1e-9)
    assert camera_from_info(camera.camera_info()) == camera


def test_distortion_bad_input() -> None:
    with pytest.raises(VbnCommonError, match='plumb_bob distortion takes 5'):
        PinholeCamera(640, 480, 400.0, 400.0, 320.0, 240.0, d=(0.1,))
    with pytest.raises(VbnCommonError, match='must be finite'):
        FisheyeCamera(640, 480, 200.0, 200.0, 320.0, 240.0, d=(0.1, math.inf, 0.0, 0.0))
    with pytest.raises(VbnCommonError, match='fisheye field of view'):
        FisheyeCamera.from_fov(640, 480, 250.0)
    with pytest.raises(VbnCommonError, match='a pinhole camera takes plumb_bob'):
        make_camera('pinhole', distortion=FISHEYE)
    with pytest.raises(VbnCommonError, match='no lens distortion'):
        make_camera('panoramic', distortion=PLUMB_BOB)
    with pytest.raises(VbnCommonError, match='no column geometry'):
        make_camera('pinhole', distortion=PLUMB_BOB).column_geometry(np.zeros(1))


@pytest.mark.parametrize(('kind', 'distortion'), [('pinhole', PLUMB_BOB),
                                                  ('fisheye', FISHEYE)])
def test_planar_motion_from_distorted_pixels(kind, distortion) -> None:
    """The planar two-view solver on rays of a distorted lens recovers the motion."""
    camera = make_camera(kind, hfov_deg=None, distortion=distortion)
    rng = np.random.default_rng(3)
    # Scene points 2 to 5 m ahead and to the sides, 1 m below to 1 m above the camera
    # (planar frame: x forward, y left, z up).
    n = 300
    angle = rng.uniform(-1.2, 1.2, n)
    distance = rng.uniform(2.0, 5.0, n)
    planar = np.column_stack([distance * np.cos(angle), distance * np.sin(angle),
                              rng.uniform(-1.0, 1.0, n)])
    theta, t = 0.15, np.array([0.3, 0.1])

    def optical(points: np.ndarray) -> np.ndarray:
        return np.column_stack([-points[:, 1], -points[:, 2], points[:, 0]])

    c, s = math.cos(theta), math.sin(theta)
    moved = planar.copy()
    moved[:, :2] = (planar[:, :2] - t) @ np.array([[c, -s], [s, c]])  # R(-theta) (p - t)
    uv_model, ok_model = camera.project(optical(planar))
    uv_current, ok_current = camera.project(optical(moved))
    both = ok_model & ok_current
    assert both.sum() > 100
    motion = relative_motion(uv_model[both], uv_current[both], camera, rng=0)
    assert motion.theta == pytest.approx(theta, abs=1e-6)
    assert motion.direction[:2] == pytest.approx(t / np.linalg.norm(t), abs=1e-6)


def test_compiled_brown_projection_is_the_numpy_arithmetic() -> None:
    """Point by point the values of brown_distort on (X / Z, Y / Z), behind the camera too."""
    from vbn_common.geometry.lens import (
        brown_coefficients,
        brown_distort,
        brown_limit,
        brown_project,
    )

    rng = np.random.default_rng(9)
    d = np.array([-0.28, 0.09, 0.001, -0.0005, -0.012])
    points = np.column_stack([rng.uniform(-2, 2, (200, 2)), rng.uniform(-0.5, 3, 200)])
    points[:3, 2] = 0.0   # in the camera's plane: infinite or undefined
    limit = brown_limit(d)
    uv, valid = brown_project(points, 500.0, 501.0, 319.5, 239.5,
                              np.array(brown_coefficients(d)), limit)
    with np.errstate(divide='ignore', invalid='ignore'):
        x, y = points[:, 0] / points[:, 2], points[:, 1] / points[:, 2]
        xd, yd = brown_distort(x, y, d)
        expected = np.column_stack([319.5 + 500.0 * xd, 239.5 + 501.0 * yd])
        expected_valid = (points[:, 2] > 0) & (np.hypot(x, y) <= limit)
    np.testing.assert_array_equal(valid, expected_valid)
    np.testing.assert_array_equal(uv[valid], expected[valid])
    assert 0 < valid.sum() < 200
