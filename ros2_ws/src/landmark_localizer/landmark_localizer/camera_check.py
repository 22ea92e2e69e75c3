"""Whether a camera's ``CameraInfo`` is the camera a database was built with (pure).

The localizer (node and ``vbn localize``) refuses images of another camera than the
database's: the model (cylindrical panorama, pinhole or fisheye), the image size, ``K``
and the lens distortion (model and coefficients) must agree. :func:`camera_mismatch`
says how they differ, naming both cameras, in one line.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.camera import CameraModel, camera_from_info

__all__ = ['camera_mismatch', 'describe_camera']


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


def camera_mismatch(info: Any, expected: CameraModel) -> str:
    """Say how a ``sensor_msgs/CameraInfo`` differs from the database's camera.

    Compared: the camera model (cylindrical panorama, pinhole or fisheye), the image
    size, ``K`` and the distortion coefficients (relative tolerance 1e-6).

    Args:
        info: The camera info message (any object with its fields).
        expected: The database's camera (``DatabaseIndex.camera``).

    Returns:
        ``''`` when they match, else one line naming both cameras.
    """
    k_expected = np.asarray(expected.camera_info().k, float)
    wanted = describe_camera(expected.width, expected.height, expected.kind, k_expected,
                             _distortion(expected))
    try:
        camera = camera_from_info(info)
    except VbnCommonError as error:
        return f'CameraInfo cannot be used ({error}); the database camera is {wanted}'
    k = np.asarray(camera.camera_info().k, float)
    d_expected = np.asarray(expected.camera_info().d, float)
    d = np.asarray(camera.camera_info().d, float)
    same = (camera.kind == expected.kind and camera.width == expected.width
            and camera.height == expected.height
            and np.allclose(k, k_expected, rtol=1e-6, atol=1e-6)
            and d.shape == d_expected.shape and np.allclose(d, d_expected, rtol=1e-6,
                                                            atol=1e-9))
    if same:
        return ''
    got = describe_camera(camera.width, camera.height, camera.kind, k, _distortion(camera))
    return f'CameraInfo {got} does not match the database camera {wanted}'
