"""Tests of the frames: optical frame, planar poses, yaw <-> quaternion, frame names."""
from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vbn_common.geometry.frames import (
    BASE_FRAME,
    BASE_TO_CAMERA_QUATERNION,
    BASE_TO_CAMERA_ROTATION,
    CAMERA_FRAME,
    MAP_FRAME,
    ODOM_FRAME,
    camera_points_to_world,
    compose_poses,
    invert_pose,
    quaternion_yaw,
    transform_points,
    world_points_to_camera,
    wrap_angle,
    yaw_quaternion,
)


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


def test_frame_names_follow_rep_105_and_the_design():
    assert (MAP_FRAME, ODOM_FRAME, BASE_FRAME, CAMERA_FRAME) == (
        'map', 'odom', 'base_link', 'camera')


def test_yaw_quaternion_hand_checked_and_scalar_path_uses_libm():
    q = yaw_quaternion(math.pi / 2)
    assert q == pytest.approx([0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)])
    yaw = 0.3
    assert yaw_quaternion(yaw).tolist() == [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]
    many = yaw_quaternion(np.array([0.0, math.pi]))
    assert many.shape == (2, 4)
    np.testing.assert_allclose(many, [[0, 0, 0, 1], [0, 0, 1, 0]], atol=1e-15)


@settings(max_examples=60, deadline=None)
@given(st.floats(-10, 10), st.floats(0.1, 5))
def test_quaternion_yaw_inverts_yaw_quaternion(yaw, scale):
    q = yaw_quaternion(yaw) * scale  # need not be normalised
    assert math.remainder(float(quaternion_yaw(q)) - yaw, 2 * math.pi) == pytest.approx(
        0.0, abs=1e-9)


def test_quaternion_yaw_matches_scipy_for_any_rotation():
    rotations = Rotation.from_euler('ZYX', [[0.7, 0.2, -0.4], [-2.5, -0.3, 1.0]])
    yaws = quaternion_yaw(rotations.as_quat())  # scipy's order is (x, y, z, w) too
    assert yaws == pytest.approx([0.7, -2.5])


def test_transform_points_hand_checked():
    # a frame 1 m along x, turned 90 degrees: its x axis is the parent's y axis
    pose = np.array([1.0, 0.0, math.pi / 2])
    out = transform_points(pose, np.array([[2.0, 0.0], [0.0, 1.0]]))
    assert out == pytest.approx(np.array([[1.0, 2.0], [0.0, 0.0]]))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=5, max_size=5))
def test_transform_points_agrees_with_compose_and_inverse(values):
    pose, point = np.array(values[:3]), np.array(values[3:])
    composed = compose_poses(pose, np.array([point[0], point[1], 0.0]))
    assert transform_points(pose, point[None])[0] == pytest.approx(composed[:2], abs=1e-9)
    back = transform_points(invert_pose(pose), transform_points(pose, point[None]))
    assert back[0] == pytest.approx(point, abs=1e-9)


def test_wrap_angle_range():
    angles = wrap_angle(np.array([math.pi, -math.pi, 3 * math.pi / 2, 0.25]))
    assert angles == pytest.approx([-math.pi, -math.pi, -math.pi / 2, 0.25])


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.lists(st.floats(-20, 20), min_size=6, max_size=6),
       st.sampled_from([None, math.pi, -math.pi, 0.0, 2 * math.pi]))
def test_one_pose_gives_what_the_batch_gives_to_the_last_bit(values, yaw):
    """One pose takes scalar arithmetic (most calls): the batch's numbers (to the last bit
    here; the tolerance is for a numpy whose vector cosine rounds otherwise), the wrap of
    +-pi included (to -pi, as wrap_angle)."""
    a, b = np.array(values[:3]), np.array(values[3:])
    if yaw is not None:
        a[2] = b[2] = yaw
    np.testing.assert_allclose(compose_poses(a, b), compose_poses(a[None], b[None])[0],
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(invert_pose(a), invert_pose(a[None])[0], rtol=0, atol=1e-12)
    assert compose_poses(a, b).shape == invert_pose(a).shape == (3,)
    assert compose_poses([0.0, 0.0, math.pi / 2], [1.0, 0.0, math.pi / 2]) == \
        pytest.approx([0.0, 1.0, -math.pi])
