"""The fisheye camera: CameraInfo ``'equidistant'`` (OpenCV's fisheye model).

A ray at angle ``theta`` from the optical axis (``z``) and azimuth ``phi`` about it
(``atan2(Y, X)``) lands at ``u = cx + fx theta_d cos(phi)``, ``v = cy + fy theta_d
sin(phi)`` with ``theta_d`` the distorted angle of :mod:`.lens`. Without distortion the
image radius is proportional to the angle (equidistant): ``fx`` pixels per radian at
every angle, so one pixel is the same angle all over the image. Rays at and beyond 90
degrees project (a 180 to 200 degree lens), up to the angle where the distortion stops
growing (:func:`~.lens.equidistant_limit`).

The thesis has no fisheye (its cameras are the panorama of 7.5.2 and the pinhole of
7.5.1); its solvers take the rays :meth:`FisheyeCamera.unproject` returns, like any
camera's.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry import lens
from vbn_common.geometry.camera import (
    CameraInfoFields,
    CameraModel,
    _check_size,
    _coefficients,
    camera_info_fields,
)

__all__ = ['FisheyeCamera']

#: Widest field of view :meth:`FisheyeCamera.from_fov` builds, degrees.
MAX_FOV_DEG = 220.0


@dataclass(frozen=True)
class FisheyeCamera(CameraModel):
    """An equidistant fisheye camera (module docstring).

    Attributes:
        width: image width, pixels.
        height: image height, pixels.
        fx: horizontal focal length, pixels per radian at the centre.
        fy: vertical focal length.
        cx: principal point column.
        cy: principal point row.
        d: ``(k1, k2, k3, k4)``, or empty for none.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    d: tuple[float, ...] = ()
    kind: str = 'fisheye'
    distortion_model: str = 'equidistant'

    def __post_init__(self) -> None:
        _check_size(self.width, self.height)
        if not (self.fx > 0 and self.fy > 0):
            raise VbnCommonError(
                f'fisheye focal lengths must be positive, got fx={self.fx}, fy={self.fy}')
        d = _coefficients(self.distortion_model, self.d, {'equidistant': 4})
        object.__setattr__(self, 'd', d)
        object.__setattr__(self, '_limit', lens.equidistant_limit(np.asarray(d)))

    @staticmethod
    def from_fov(width: int, height: int, hfov_deg: float = 180.0,
                 d: tuple[float, ...] = ()) -> FisheyeCamera:
        """Build a square-pixel fisheye whose image width spans ``hfov_deg``.

        Args:
            width: image width, pixels.
            height: image height, pixels.
            hfov_deg: field of view across the width through the centre, degrees
                (0, 220].
            d: ``(k1, k2, k3, k4)``.
        """
        if not 0.0 < hfov_deg <= MAX_FOV_DEG:
            raise VbnCommonError(f'fisheye field of view must be in (0, {MAX_FOV_DEG:g}] '
                                 f'degrees, got {hfov_deg}')
        half = math.radians(hfov_deg) / 2.0
        if half > lens.equidistant_limit(np.asarray(d, float)):
            raise VbnCommonError(f'the distortion {list(d)} stops growing before '
                                 f'{hfov_deg} degrees')
        f = (width / 2.0) / float(lens.equidistant_theta_d(np.float64(half), np.asarray(d)))
        return FisheyeCamera(width, height, f, f, (width - 1) / 2.0, (height - 1) / 2.0, d)

    @property
    def distorted(self) -> bool:
        """Whether any distortion coefficient is non-zero."""
        return any(self.d)

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Return unit optical-frame rays of pixels (beyond the model's limit: its edge)."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        xd = (uv[:, 0] - self.cx) / self.fx
        yd = (uv[:, 1] - self.cy) / self.fy
        theta_d = np.hypot(xd, yd)
        limit = self._limit  # type: ignore[attr-defined]
        theta = lens.equidistant_theta(theta_d, np.asarray(self.d), limit)
        theta = np.where(np.isnan(theta), limit, theta)
        phi = np.arctan2(yd, xd)
        sin_theta = np.sin(theta)
        return np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), np.cos(theta)],
                        axis=1)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project optical-frame points (module docstring); ``valid`` inside the image."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        lateral = np.hypot(points[:, 0], points[:, 1])
        theta = np.arctan2(lateral, points[:, 2])
        phi = np.arctan2(points[:, 1], points[:, 0])
        theta_d = lens.equidistant_theta_d(theta, np.asarray(self.d))
        uv = np.stack([self.cx + self.fx * theta_d * np.cos(phi),
                       self.cy + self.fy * theta_d * np.sin(phi)], axis=1)
        valid = ((lateral > 0) | (points[:, 2] > 0)) & \
            (theta <= self._limit) & self._inside(uv)  # type: ignore[attr-defined]
        return uv, valid

    def column_geometry(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raise: a fisheye has none (a vertical world line is curved in its image)."""
        raise VbnCommonError('a fisheye camera has no column geometry')

    def camera_info(self) -> CameraInfoFields:
        """Return ``'equidistant'`` CameraInfo fields."""
        return camera_info_fields(self.width, self.height, 'equidistant',
                                  self.d or (0.0, 0.0, 0.0, 0.0), self.fx, self.fy, self.cx,
                                  self.cy)
