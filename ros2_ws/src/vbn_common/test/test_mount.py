"""A camera's pitch and roll on its mount (vbn_common.geometry.mount)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.camera import PanoramicCamera, PinholeCamera
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION
from vbn_common.geometry.mount import (
    TiltedCamera,
    level_tilt,
    tilt_angles,
    tilt_matrix,
    tilted,
)


def test_a_camera_pitched_up_sees_the_level_forward_point_below_its_centre() -> None:
    camera = TiltedCamera(PinholeCamera(640, 480, 400.0, 400.0, 319.5, 239.5),
                          tilt_matrix(10.0, 0.0))
    uv, ok = camera.project(np.array([[0.0, 0.0, 5.0]]))   # level, straight ahead
    assert ok[0] and uv[0] == pytest.approx([319.5, 239.5 + 400.0 * math.tan(
        math.radians(10.0))])
    # And the centre pixel's ray points 10 degrees up (-y in the level frame).
    ray = camera.unproject(np.array([[319.5, 239.5]]))[0]
    assert ray == pytest.approx([0.0, -math.sin(math.radians(10)), math.cos(math.radians(10))])
    # Roll 90 degrees about the optical axis: image right is level down.
    rolled = TiltedCamera(PinholeCamera(640, 480, 400.0, 400.0, 319.5, 239.5),
                          tilt_matrix(0.0, 90.0))
    assert rolled.unproject(np.array([[719.5, 239.5]]))[0] == pytest.approx(
        np.array([0.0, 1.0, 1.0]) / math.sqrt(2))


@pytest.mark.parametrize(('pitch', 'roll'), [(2.0, 0.0), (-1.5, 0.7), (30.0, -12.0)])
def test_tilt_round_trips_through_angles_and_the_static_transform(pitch, roll) -> None:
    tilt = tilt_matrix(pitch, roll)
    assert tilt_angles(tilt) == pytest.approx((pitch, roll), abs=1e-9)
    # base_link -> camera as the renderer writes it, read back as the builder does.
    assert level_tilt(BASE_TO_CAMERA_ROTATION @ tilt) == pytest.approx(tilt, abs=1e-12)
    camera = TiltedCamera(PanoramicCamera(1024, 256), tilt)
    rng = np.random.default_rng(0)
    rays = rng.normal(size=(200, 3))
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    uv, ok = camera.project(rays)
    assert camera.unproject(uv[ok]) == pytest.approx(rays[ok], abs=1e-9)
    assert camera.kind == 'panoramic' and camera.f_az == pytest.approx(1024 / (2 * math.pi))
    assert camera.camera_info() == PanoramicCamera(1024, 256).camera_info()


def test_level_is_the_camera_itself_and_bad_tilts_are_refused() -> None:
    camera = PanoramicCamera(1024, 256)
    assert tilted(camera, None) is camera and tilted(camera, np.eye(3)) is camera
    assert isinstance(tilted(camera, tilt_matrix(1.0, 0.0)), TiltedCamera)
    with pytest.raises(VbnCommonError, match='must be a rotation'):
        TiltedCamera(camera, np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(VbnCommonError, match='straight up or down'):
        level_tilt(BASE_TO_CAMERA_ROTATION @ tilt_matrix(90.0, 0.0))
    with pytest.raises(VbnCommonError, match='no column geometry'):
        TiltedCamera(camera, tilt_matrix(1.0, 0.0)).column_geometry(np.zeros(1))
