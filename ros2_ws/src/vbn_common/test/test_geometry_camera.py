"""Tests of the camera models: projection, bearings, CameraInfo in both directions."""
from __future__ import annotations

import dataclasses
import math
import types

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
from paths import REPO
import pytest

from vbn_common.bags import deserialize, messages, open_bag, serialize
from vbn_common.errors import VbnCommonError
from vbn_common.geometry.camera import (
    PanoramicCamera,
    PinholeCamera,
    camera_from_info,
    make_camera,
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


def test_bad_camera_parameters_are_refused():
    with pytest.raises(VbnCommonError):
        make_camera('catadioptric')
    with pytest.raises(VbnCommonError):
        PanoramicCamera(4, 256)
    with pytest.raises(VbnCommonError):
        PinholeCamera.from_fov(640, 480, 180.0)


# -- pixel <-> bearing ---------------------------------------------------------------
def test_panorama_bearings_hand_checked():
    # middle column: forward; three quarters across: 90 degrees right (bearing -pi/2,
    # counter-clockwise positive); one quarter: left; the horizon row has elevation 0.
    uv = np.array([[512.0, 128.0], [768.0, 128.0], [256.0, 128.0], [512.0, 128.0 - PANO.f_az]])
    bearing, elevation = PANO.pixel_to_bearing(uv)
    assert bearing == pytest.approx([0.0, -math.pi / 2, math.pi / 2, 0.0])
    # one cylinder radius above the horizon row is 45 degrees up
    assert elevation == pytest.approx([0.0, 0.0, 0.0, math.pi / 4])


def test_pinhole_bearing_of_the_right_image_edge_is_half_the_field_of_view():
    bearing, elevation = PIN.pixel_to_bearing(np.array([[PIN.cx + PIN.fx, PIN.cy]]))
    assert bearing[0] == pytest.approx(-math.pi / 4)
    assert elevation[0] == pytest.approx(0.0)


@settings(max_examples=60, deadline=None)
@given(u=st.floats(0, 1023), v=st.floats(0, 255))
def test_panorama_bearing_round_trip(u, v):
    bearing, elevation = PANO.pixel_to_bearing(np.array([[u, v]]))
    uv, ok = PANO.bearing_to_pixel(bearing, elevation)
    assert ok[0]
    # column 0 and column 1024 are the same azimuth (straight behind)
    du = math.remainder(uv[0, 0] - u, PANO.width)
    assert du == pytest.approx(0.0, abs=1e-6)
    assert uv[0, 1] == pytest.approx(v, abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(u=st.floats(0, 639), v=st.floats(0, 479))
def test_pinhole_bearing_round_trip(u, v):
    uv, ok = PIN.bearing_to_pixel(*PIN.pixel_to_bearing(np.array([[u, v]])))
    assert ok[0]
    assert uv[0] == pytest.approx([u, v], abs=1e-6)


def test_bearing_behind_a_pinhole_camera_is_not_in_the_image():
    _, ok = PIN.bearing_to_pixel(np.array([0.0, math.pi]))
    assert ok.tolist() == [True, False]


# -- camera models from CameraInfo ---------------------------------------------------
@pytest.mark.parametrize('camera', [
    PANO, PanoramicCamera(2048, 512, f_y=300.0, y0=200.5), PIN,
    PinholeCamera(320, 240, 250.0, 260.0, 150.0, 110.0)], ids=str)
def test_camera_from_info_inverts_camera_info(camera):
    assert camera_from_info(camera.camera_info()) == camera


def test_camera_from_info_reads_the_sample_bag():
    bag_path = REPO / 'bags' / 'room_exploration'
    infos = []
    with open_bag(bag_path) as bag:
        for _, msgtype, _, raw in bag.messages(topics=['/camera/camera_info']):
            infos.append(deserialize(raw, msgtype))
    assert len(infos) > 0
    cameras = {camera_from_info(info) for info in infos}
    # every message describes the project's default panorama, 1024 x 256
    assert cameras == {make_camera('panoramic')}
    camera = cameras.pop()
    assert isinstance(camera, PanoramicCamera)
    assert (camera.f_az, camera.cx, camera.horizon_row) == pytest.approx(
        (infos[0].k[0], infos[0].k[2], infos[0].k[5]))


def test_camera_from_info_reads_rosbags_and_rclpy_messages():
    # rosbags: the message the bag synthesis writes, through CDR and back
    msg = messages.camera_info_message(5, PIN.camera_info())
    raw = serialize(msg, 'sensor_msgs/msg/CameraInfo')
    assert camera_from_info(deserialize(raw, 'sensor_msgs/msg/CameraInfo')) == PIN
    # rclpy: the generated Python message class (arrays, array.array for d)
    sensor_msgs = pytest.importorskip('sensor_msgs.msg')
    info = PANO.camera_info()
    ros_msg = sensor_msgs.CameraInfo(width=info.width, height=info.height,
                                     distortion_model=info.distortion_model, d=list(info.d),
                                     k=list(info.k), r=list(info.r), p=list(info.p))
    assert camera_from_info(ros_msg) == PANO


def _info(**changes):
    return dataclasses.replace(PIN.camera_info(), **changes)


@pytest.mark.parametrize(('changes', 'message'), [
    ({'distortion_model': 'kannala_brandt'}, 'unknown camera info distortion_model'),
    ({'distortion_model': 'equidistant'}, 'equidistant distortion takes 4 coefficients'),
    ({'d': (0.1, float('nan'), 0.0, 0.0, 0.0)}, 'must be finite'),
    ({'d': (0.1, 0.0, 0.0)}, 'plumb_bob distortion takes 5 coefficients, got 3'),
    ({'k': (320.0, 0.0, 319.5)}, 'k must hold 9 finite numbers'),
    ({'k': (320.0, 1.0, 319.5, 0.0, 320.0, 239.5, 0.0, 0.0, 1.0)}, 'k must be'),
    ({'k': (0.0, 0.0, 319.5, 0.0, 320.0, 239.5, 0.0, 0.0, 1.0)}, 'focal lengths'),
    ({'width': 640.5}, 'image size must be integers'),
    ({'width': 4}, 'at least 8 x 8'),
    ({'distortion_model': 'cylindrical'}, 'span 360 degrees'),
])
def test_camera_from_info_refuses_bad_input(changes, message):
    with pytest.raises(VbnCommonError, match=message):
        camera_from_info(_info(**changes))


def test_camera_from_info_names_a_missing_field():
    with pytest.raises(VbnCommonError, match='lacks a CameraInfo field'):
        camera_from_info(types.SimpleNamespace(width=640, height=480, k=[0.0] * 9))


def test_panorama_projects_the_seam_into_the_image():
    # Regression: a point a hair to the left of the seam (azimuth just under -pi) gave
    # u = 512.0 exactly (np.mod of -1e-14), outside a 512-pixel-wide panorama.
    camera = PanoramicCamera(512, 128)
    uv, inside = camera.project(np.array([[-1e-16, 0.0, -1.0], [1e-16, 0.0, -1.0]]))
    assert inside.all() and np.all((uv[:, 0] >= -0.5) & (uv[:, 0] < 511.5))
    # the last half pixel before the seam is column 0's left half
    uv, inside = camera.project(camera.unproject(np.array([[511.75, 64.0]])))
    assert inside.all() and uv[0, 0] == pytest.approx(-0.25)


@pytest.mark.parametrize('camera, hfov', [('pinhole', 90.0), ('pinhole', 60.0),
                                          ('fisheye', 180.0), ('fisheye', 200.0)])
def test_horizontal_fov_of_the_camera_models(camera: str, hfov: float) -> None:
    from vbn_common.geometry.camera import horizontal_fov, make_camera

    model = make_camera(camera, 640, 480, hfov_deg=hfov)
    assert math.degrees(horizontal_fov(model)) == pytest.approx(hfov, abs=1e-6)
    assert horizontal_fov(make_camera('panoramic', 640, 120)) == pytest.approx(2 * math.pi)
