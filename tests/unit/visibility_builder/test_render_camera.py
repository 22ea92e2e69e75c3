from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.render.camera import PanoramicCamera, PinholeCamera, make_camera
from visibility_builder.render.frames import (
    BASE_TO_CAMERA_QUATERNION,
    BASE_TO_CAMERA_ROTATION,
    camera_points_to_world,
    compose_poses,
    invert_pose,
    world_points_to_camera,
)

PANO = PanoramicCamera(1024, 256)
PIN = PinholeCamera.from_fov(640, 480, 90.0)


def test_panorama_intrinsics_follow_the_documented_convention():
    assert PANO.f_az == pytest.approx(1024 / (2 * math.pi))
    info = PANO.camera_info()
    assert info.distortion_model == 'cylindrical'
    assert info.k == pytest.approx((PANO.f_az, 0, 512, 0, PANO.f_az, 128, 0, 0, 1))
    assert info.d == ()
    # forward (optical +z) is the middle column on the horizon row
    uv, ok = PANO.project(np.array([[0.0, 0.0, 3.0]]))
    assert ok[0] and uv[0] == pytest.approx([512, 128])
    # a point to the right (optical +x) is 90 degrees = width/4 columns to the right
    uv, _ = PANO.project(np.array([[2.0, 0.0, 0.0]]))
    assert uv[0, 0] == pytest.approx(768)
    # straight behind is column 0 (azimuth -pi)
    uv, _ = PANO.project(np.array([[-1e-12, 0.0, -1.0]]))
    assert uv[0, 0] == pytest.approx(0.0, abs=1e-6)
    # a point 1 m above the optical centre at 2 m range: v = y0 - f_y * 1 / 2
    uv, _ = PANO.project(np.array([[0.0, -1.0, 2.0]]))
    assert uv[0, 1] == pytest.approx(128 - PANO.f_az / 2)


def test_pinhole_intrinsics_are_plumb_bob_without_distortion():
    info = PIN.camera_info()
    assert info.distortion_model == 'plumb_bob'
    assert info.d == (0, 0, 0, 0, 0)
    assert PIN.fx == pytest.approx(320.0)  # 90 degrees over 640 pixels
    uv, ok = PIN.project(np.array([[1.0, 0.5, 2.0]]))
    assert ok[0] and uv[0] == pytest.approx([PIN.cx + 160, PIN.cy + 80])
    _, ok = PIN.project(np.array([[0.0, 0.0, -1.0]]))
    assert not ok[0]


@settings(max_examples=60, deadline=None)
@given(u=st.floats(0, 1023), v=st.floats(0, 255), depth=st.floats(0.2, 20))
def test_panorama_unproject_then_project_recovers_the_pixel(u, v, depth):
    ray = PANO.unproject(np.array([[u, v]]))
    assert np.linalg.norm(ray) == pytest.approx(1.0)
    uv, ok = PANO.project(ray * depth)
    assert ok[0]
    assert uv[0] == pytest.approx([u, v], abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(u=st.floats(0, 639), v=st.floats(0, 479), depth=st.floats(0.2, 20))
def test_pinhole_unproject_then_project_recovers_the_pixel(u, v, depth):
    uv, ok = PIN.project(PIN.unproject(np.array([[u, v]])) * depth)
    assert ok[0]
    assert uv[0] == pytest.approx([u, v], abs=1e-6)


def test_optical_frame_quaternion_matches_rotation():
    matrix = Rotation.from_quat(BASE_TO_CAMERA_QUATERNION).as_matrix()
    assert matrix == pytest.approx(BASE_TO_CAMERA_ROTATION)
    # camera z (forward) is base x, camera x (right) is base -y, camera y (down) is base -z
    assert BASE_TO_CAMERA_ROTATION @ [0, 0, 1] == pytest.approx([1, 0, 0])
    assert BASE_TO_CAMERA_ROTATION @ [1, 0, 0] == pytest.approx([0, -1, 0])
    assert BASE_TO_CAMERA_ROTATION @ [0, 1, 0] == pytest.approx([0, 0, -1])


def test_world_to_camera_for_a_robot_facing_plus_y():
    pose = np.array([1.0, 2.0, math.pi / 2])
    # a point 3 m ahead (+y), 1 m to the robot's right (+x), at floor level
    cam = world_points_to_camera(pose, 1.2, np.array([[2.0, 5.0, 0.0]]))
    assert cam[0] == pytest.approx([1.0, 1.2, 3.0])
    back = camera_points_to_world(pose, 1.2, cam)
    assert back[0] == pytest.approx([2.0, 5.0, 0.0])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=6, max_size=6))
def test_pose_composition_and_inverse(values):
    a, b = np.array(values[:3]), np.array(values[3:])
    identity = compose_poses(a, invert_pose(a))
    assert identity == pytest.approx([0, 0, 0], abs=1e-9)
    back = compose_poses(invert_pose(a), compose_poses(a, b))
    assert back[:2] == pytest.approx(b[:2], abs=1e-9)
    assert math.remainder(back[2] - b[2], 2 * math.pi) == pytest.approx(0, abs=1e-9)


def test_bad_camera_parameters_are_refused():
    with pytest.raises(VisibilityBuilderError):
        make_camera('fisheye')
    with pytest.raises(VisibilityBuilderError):
        PanoramicCamera(4, 256)
    with pytest.raises(VisibilityBuilderError):
        PinholeCamera.from_fov(640, 480, 180.0)
