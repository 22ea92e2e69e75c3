"""Whether a camera's ``CameraInfo`` is the camera a database was built with (pure).

The localizer (node and ``vbn localize``) reads each run's frames with the run's own
``CameraInfo``: another resolution or calibration is fine; another kind of
camera (cylindrical panorama, pinhole, fisheye) or another distortion model is refused,
in one line naming both cameras (:func:`frame_camera`, :func:`camera_mismatch`).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.camera import CameraModel, camera_from_info
from vbn_common.geometry.mount import tilted

__all__ = ['camera_mismatch', 'describe_camera', 'frame_camera']


def describe_camera(width: int, height: int, kind: str, k: np.ndarray,
                    distortion: str = '') -> str:
    """Return ``WxH kind (fx, fy, cx, cy[, distortion])``, how the errors name a camera."""
    fx, cx, fy, cy = k[0], k[2], k[4], k[5]
    lens = f', {distortion}' if distortion else ''
    return f'{width}x{height} {kind} (fx {fx:g}, fy {fy:g}, cx {cx:g}, cy {cy:g}{lens})'


def _distortion(camera: CameraModel) -> str:
    d = tuple(getattr(camera, 'd', ()))
    if not any(d):
        return ''
    return f'{camera.distortion_model} d=[{", ".join(f"{v:g}" for v in d)}]'  # type: ignore


def frame_camera(info: Any, expected: CameraModel, tilt: np.ndarray | None = None
                 ) -> tuple[CameraModel | None, str]:
    """Return the camera of a run's ``CameraInfo``, or why the database cannot take it.

    A run camera may differ from the database's in image size, ``K`` and distortion
    coefficients (another resolution, another calibration of the same kind of lens):
    its frames are then read with their own model, with the run's mount ``tilt``
    (``base_link -> camera`` from its ``/tf_static``; ``None``: the database camera's,
    :mod:`vbn_common.geometry.mount`). Refused: a CameraInfo that cannot be read,
    another kind of camera (cylindrical panorama, pinhole, fisheye) or another
    distortion model.

    Returns:
        ``(camera, '')`` (``expected`` itself when the two are the same camera), or
        ``(None, one line naming both cameras)``.
    """
    k_expected = np.asarray(expected.camera_info().k, float)
    wanted = describe_camera(expected.width, expected.height, expected.kind, k_expected,
                             _distortion(expected))
    try:
        camera = camera_from_info(info)
    except VbnCommonError as error:
        return None, f'CameraInfo cannot be used ({error}); the database camera is {wanted}'
    k = np.asarray(camera.camera_info().k, float)
    got = describe_camera(camera.width, camera.height, camera.kind, k, _distortion(camera))
    if camera.kind != expected.kind:
        return None, f'CameraInfo {got} is not the kind of the database camera {wanted}'
    lens, lens_expected = _model(camera), _model(expected)
    if lens != lens_expected:
        return None, (f'CameraInfo {got} has {lens or "no"} distortion, the database camera '
                      f'{wanted} {lens_expected or "none"}')
    d_expected = np.asarray(expected.camera_info().d, float)
    d = np.asarray(camera.camera_info().d, float)
    expected_tilt = getattr(expected, 'tilt', np.eye(3))
    tilt = expected_tilt if tilt is None else np.asarray(tilt, float).reshape(3, 3)
    if (np.allclose(tilt, expected_tilt, atol=1e-9) and camera.width == expected.width
            and camera.height == expected.height
            and np.allclose(k, k_expected, rtol=1e-6, atol=1e-6)
            and d.shape == d_expected.shape and np.allclose(d, d_expected, rtol=1e-6,
                                                            atol=1e-9)):
        return expected, ''
    return tilted(camera, tilt), ''


def _model(camera: CameraModel) -> str:
    """Return the distortion model, ``''`` without distortion."""
    return str(getattr(camera, 'distortion_model', '')) if any(getattr(camera, 'd', ())) \
        else ''


def camera_mismatch(info: Any, expected: CameraModel) -> str:
    """Say why a ``sensor_msgs/CameraInfo`` cannot be used with the database's camera.

    :func:`frame_camera`'s reason, ``''`` when it can (the same camera, or one of the
    same kind and distortion model at another size or calibration).
    """
    return frame_camera(info, expected)[1]
