"""Camera models: cylindrical panorama and pinhole (thesis Section 7.5).

Shared by the renderer, the builder, image pose estimation and the localizer. Pure
numpy: :func:`camera_from_info` reads any ``sensor_msgs/CameraInfo``-like object
(rclpy or rosbags messages, :class:`CameraInfoFields`) by its attributes, without
importing a message module.

Both models live in the camera's *optical* frame (``camera``, REP 103 optical
convention): ``z`` forward, ``x`` right, ``y`` down. The robot moves in the plane
and the camera never pitches or rolls, so ``y`` is the world's downward vertical.
Pixel coordinates follow OpenCV: the centre of pixel ``(u, v)`` (column, row) is at
the integer coordinates ``(u, v)``.

**Pinhole** (Section 7.5.1): ``u = cx + fx X / Z``, ``v = cy + fy Y / Z``; the
``sensor_msgs/CameraInfo`` carries ``K = [fx, 0, cx; 0, fy, cy; 0, 0, 1]`` and
``distortion_model = 'plumb_bob'`` or ``'rational_polynomial'``, whose coefficients
``d`` (:mod:`.lens`) distort the normalised coordinates before ``K``. Keypoints become
undistorted rays (:meth:`~CameraModel.unproject`); images are never undistorted.

**Fisheye** (:class:`~vbn_common.geometry.fisheye.FisheyeCamera`, ``'equidistant'``):
OpenCV's fisheye model, up to 200 degrees across.

**Cylindrical panorama** (Section 7.5.2): a 360-degree image on a vertical
cylinder around the optical centre.

- Column = azimuth: ``alpha = (u - cx) / f_az`` radians, where ``f_az = width /
  (2 pi)`` is the number of pixels per radian of azimuth. ``alpha = 0`` is the
  camera's forward direction (optical ``z``, the robot's ``x`` axis) and lies at
  column ``cx = width / 2``; ``alpha`` grows to the right (clockwise seen from
  above, towards optical ``+x``, the robot's ``-y``), so the left image edge is
  ``alpha = -pi`` (straight behind).
- Rows by elevation about the horizon row ``y0``: ``v = y0 + f_y Y / rho`` with
  ``rho = hypot(X, Z)`` the horizontal range, i.e. ``tan(gamma) = (y0 - v) / f_y``
  for the elevation ``gamma`` above the horizon. This is the projection onto a
  cylinder of radius ``f_y`` pixels; with ``f_y = f_az`` (the default) the
  cylinder's pixels are square. It is the model of the thesis's "Advantages of
  using panoramic cameras" paragraph, ``cot(gamma) = f / (s_y (p_y - y0))``, in
  which ``y0`` is the only calibration needed to recover planar motion.
- ``CameraInfo``: ``distortion_model = 'cylindrical'``, ``d = []``,
  ``K = [f_az, 0, cx; 0, f_y, y0; 0, 0, 1]``, ``R = I``,
  ``P = [f_az, 0, cx, 0; 0, f_y, y0, 0; 0, 0, 1, 0]``.

The renderer uses the fact that, for both models, a vertical world line projects
to one image column: :meth:`column_geometry` gives each column's azimuth and the
factor that turns horizontal range into the depth that divides ``Y``. Pixels and
directions convert both ways: :meth:`~CameraModel.unproject` and
:meth:`~CameraModel.project` for optical-frame rays and points,
:meth:`~CameraModel.pixel_to_bearing` and :meth:`~CameraModel.bearing_to_pixel` for
the robot's planar bearing (counter-clockwise from forward, REP 103) and elevation.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Protocol

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry import lens

__all__ = [
    'CameraInfoFields',
    'CameraInfoLike',
    'CameraModel',
    'PanoramicCamera',
    'PinholeCamera',
    'camera_from_info',
    'camera_info_fields',
    'horizontal_fov',
    'make_camera',
    'pixels_per_radian',
]

_IDENTITY_K_ROW3 = (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class CameraInfoFields:
    """The fields of a ``sensor_msgs/CameraInfo``, without any ROS type.

    Attributes:
        width: image width, pixels.
        height: image height, pixels.
        distortion_model: ``'plumb_bob'`` or ``'cylindrical'``.
        d: distortion coefficients.
        k: row-major 3 x 3 intrinsic matrix (9 values).
        r: row-major 3 x 3 rectification matrix (9 values).
        p: row-major 3 x 4 projection matrix (12 values).
    """

    width: int
    height: int
    distortion_model: str
    d: tuple[float, ...]
    k: tuple[float, ...]
    r: tuple[float, ...]
    p: tuple[float, ...]


class CameraInfoLike(Protocol):
    """The ``sensor_msgs/CameraInfo`` attributes :func:`camera_from_info` reads.

    rclpy messages, rosbags-deserialized messages and :class:`CameraInfoFields` all
    have them.
    """

    width: Any
    height: Any
    distortion_model: Any
    d: Any
    k: Any


class CameraModel:
    """Common interface of :class:`PanoramicCamera` and :class:`PinholeCamera`."""

    width: int
    height: int
    kind: str

    @property
    def horizon_row(self) -> float:
        """Return the image row of elevation zero."""
        raise NotImplementedError

    @property
    def f_vertical(self) -> float:
        """Return the vertical scale: ``v = horizon_row + f_vertical * Y / depth``."""
        raise NotImplementedError

    def column_geometry(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return each column's azimuth and its depth-per-range factor.

        Args:
            u: ``(n,)`` column coordinates (may be fractional).

        Returns:
            ``(alpha, depth_per_range)``: ``alpha`` the azimuth right of forward in
            radians and the factor ``c`` such that a point at horizontal range
            ``rho`` along that column projects to row ``v = y0 + f_y Y / (c rho)``
            (pinhole: ``cos(alpha)``; panorama: 1).
        """
        raise NotImplementedError

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Return ray directions in the optical frame for pixel coordinates.

        Args:
            uv: ``(n, 2)`` pixel coordinates ``(u, v)``.

        Returns:
            ``(n, 3)`` unit vectors ``(X, Y, Z)``.
        """
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        alpha, c = self.column_geometry(uv[:, 0])
        # A ray with unit horizontal range: horizontal part (sin a, cos a), and
        # Y = (v - y0) * depth / f_y with depth = c * 1.
        y = (uv[:, 1] - self.horizon_row) * c / self.f_vertical
        rays = np.stack([np.sin(alpha), y, np.cos(alpha)], axis=1)
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project optical-frame points to pixel coordinates.

        Args:
            points: ``(n, 3)`` points ``(X, Y, Z)`` in the optical frame, metres.

        Returns:
            ``(uv, valid)``: ``(n, 2)`` pixel coordinates and an ``(n,)`` mask of the
            points that fall inside the image (and in front of a pinhole camera).
        """
        raise NotImplementedError

    def pixel_to_bearing(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the planar bearing and the elevation of the rays through pixels.

        Args:
            uv: ``(n, 2)`` pixel coordinates ``(u, v)``.

        Returns:
            ``(bearing, elevation)``, ``(n,)`` radians each: ``bearing`` counter-clockwise
            from the robot's forward axis (``base_link`` ``x``, REP 103; the negated
            azimuth of :meth:`column_geometry`), in ``(-pi, pi]``; ``elevation`` above
            the horizon (up is positive).
        """
        rays = self.unproject(uv)
        bearing = np.arctan2(-rays[:, 0], rays[:, 2])
        elevation = np.arctan2(-rays[:, 1], np.hypot(rays[:, 0], rays[:, 2]))
        return bearing, elevation

    def bearing_to_pixel(self, bearing: np.ndarray,
                         elevation: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Return the pixels of directions given by bearing and elevation.

        Inverse of :meth:`pixel_to_bearing`.

        Args:
            bearing: ``(n,)`` radians counter-clockwise from the robot's forward axis.
            elevation: ``(n,)`` or scalar radians above the horizon.

        Returns:
            ``(uv, valid)`` as :meth:`project` returns them.
        """
        bearing = np.asarray(bearing, dtype=float).reshape(-1)
        elevation = np.broadcast_to(np.asarray(elevation, dtype=float), bearing.shape)
        horizontal = np.cos(elevation)
        rays = np.stack([-np.sin(bearing) * horizontal, -np.sin(elevation),
                         np.cos(bearing) * horizontal], axis=1)
        return self.project(rays)

    def camera_info(self) -> CameraInfoFields:
        """Return the intrinsics as ``sensor_msgs/CameraInfo`` fields."""
        raise NotImplementedError

    def _inside(self, uv: np.ndarray) -> np.ndarray:
        return ((uv[:, 0] >= -0.5) & (uv[:, 0] < self.width - 0.5)
                & (uv[:, 1] >= -0.5) & (uv[:, 1] < self.height - 0.5))


@dataclass(frozen=True)
class PanoramicCamera(CameraModel):
    """A cylindrical 360-degree panoramic camera (Section 7.5.2; see module docstring).

    Attributes:
        width: image width, pixels (covers 360 degrees of azimuth).
        height: image height, pixels.
        f_y: cylinder radius in pixels (vertical scale); ``None`` means ``f_az``.
        y0: horizon row; ``None`` means ``height / 2``.
    """

    width: int = 1024
    height: int = 256
    f_y: float | None = None
    y0: float | None = None
    kind: str = 'panoramic'

    def __post_init__(self) -> None:
        _check_size(self.width, self.height)

    @property
    def f_az(self) -> float:
        """Return the pixels per radian of azimuth, ``width / (2 pi)``."""
        return self.width / (2.0 * math.pi)

    @property
    def cx(self) -> float:
        """Return the column of azimuth zero (forward), ``width / 2``."""
        return self.width / 2.0

    @property
    def horizon_row(self) -> float:
        """Return the horizon row ``y0``."""
        return self.height / 2.0 if self.y0 is None else float(self.y0)

    @property
    def f_vertical(self) -> float:
        """Return the cylinder radius ``f_y`` in pixels."""
        return self.f_az if self.f_y is None else float(self.f_y)

    def column_geometry(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return azimuth ``(u - cx) / f_az`` and depth factor 1 per column."""
        u = np.asarray(u, dtype=float)
        return (u - self.cx) / self.f_az, np.ones_like(u)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project optical-frame points onto the cylinder (see :class:`CameraModel`)."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        rho = np.hypot(points[:, 0], points[:, 2])
        alpha = np.arctan2(points[:, 0], points[:, 2])
        # Wrapped onto the image's columns, [-0.5, width - 0.5) as pixel centres go: a
        # point just left of the seam is in column 0, not at u = width (outside).
        u = np.mod(self.cx + self.f_az * alpha + 0.5, self.width) - 0.5
        with np.errstate(divide='ignore', invalid='ignore'):
            v = self.horizon_row + self.f_vertical * points[:, 1] / rho
        uv = np.stack([u, v], axis=1)
        return uv, (rho > 0) & self._inside(uv)

    def camera_info(self) -> CameraInfoFields:
        """Return the ``'cylindrical'`` CameraInfo fields (module docstring)."""
        return camera_info_fields(self.width, self.height, 'cylindrical', (), self.f_az,
                                  self.f_vertical, self.cx, self.horizon_row)


@dataclass(frozen=True)
class PinholeCamera(CameraModel):
    """A pinhole camera without distortion (Section 7.5.1).

    Attributes:
        width: image width, pixels.
        height: image height, pixels.
        fx: horizontal focal length, pixels.
        fy: vertical focal length, pixels.
        cx: principal point column.
        cy: principal point row.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    kind: str = 'pinhole'
    distortion_model: str = 'plumb_bob'
    d: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        _check_size(self.width, self.height)
        if not (self.fx > 0 and self.fy > 0):
            raise VbnCommonError(
                f'pinhole focal lengths must be positive, got fx={self.fx}, fy={self.fy}')
        d = _coefficients(self.distortion_model, self.d, lens.BROWN_MODELS)
        object.__setattr__(self, 'd', d)
        object.__setattr__(self, '_limit', lens.brown_limit(np.asarray(d)) if any(d) else
                           math.inf)
        object.__setattr__(self, '_coefficients', np.array(lens.brown_coefficients(d)))

    @property
    def distorted(self) -> bool:
        """Whether any distortion coefficient is non-zero."""
        return any(self.d)

    @property
    def k_matrix(self) -> np.ndarray:
        """Return the ``(3, 3)`` intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def undistorted(self) -> PinholeCamera:
        """Return the same camera without distortion (the renderer's ideal view)."""
        return PinholeCamera(self.width, self.height, self.fx, self.fy, self.cx, self.cy)

    @staticmethod
    def from_fov(width: int, height: int, hfov_deg: float = 90.0) -> PinholeCamera:
        """Build a square-pixel pinhole camera centred in the image.

        Args:
            width: image width, pixels.
            height: image height, pixels.
            hfov_deg: horizontal field of view, degrees (0, 180).
        """
        if not 0.0 < hfov_deg < 180.0:
            raise VbnCommonError(f'pinhole field of view must be in (0, 180) degrees, '
                                 f'got {hfov_deg}')
        f = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
        return PinholeCamera(width, height, f, f, (width - 1) / 2.0, (height - 1) / 2.0)

    @property
    def horizon_row(self) -> float:
        """Return ``cy`` (the camera looks horizontally)."""
        return self.cy

    @property
    def f_vertical(self) -> float:
        """Return ``fy``."""
        return self.fy

    def column_geometry(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return azimuth ``atan((u - cx) / fx)`` and depth factor ``cos(alpha)``.

        Raises:
            VbnCommonError: a distorted camera (a column is no vertical line; render
                through :meth:`undistorted` and a remap).
        """
        if self.distorted:
            raise VbnCommonError('a distorted pinhole camera has no column geometry')
        alpha = np.arctan((np.asarray(u, dtype=float) - self.cx) / self.fx)
        return alpha, np.cos(alpha)

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Return unit optical-frame rays of pixels, undistorted (:mod:`.lens`)."""
        if not self.distorted:
            return super().unproject(uv)
        xy = lens.brown_invert(np.ascontiguousarray(np.asarray(uv, float).reshape(-1, 2)),
                               self.fx, self.fy, self.cx, self.cy,
                               self._coefficients)  # type: ignore[attr-defined]
        rays = np.column_stack([xy, np.ones(len(xy))])
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project optical-frame points with ``u = cx + fx xd``, ``v = cy + fy yd``.

        ``(xd, yd)`` is ``(X / Z, Y / Z)`` distorted; points beyond the radius where the
        distortion stops growing (:func:`~.lens.brown_limit`) are invalid.
        """
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if self.distorted:   # compiled: a dozen numpy calls for a few dozen points
            uv, valid = lens.brown_project(np.ascontiguousarray(points), self.fx, self.fy,
                                           self.cx, self.cy,
                                           self._coefficients,  # type: ignore[attr-defined]
                                           self._limit)  # type: ignore[attr-defined]
            return uv, valid & self._inside(uv)
        z = points[:, 2]
        with np.errstate(divide='ignore', invalid='ignore'):
            x, y = points[:, 0] / z, points[:, 1] / z
            valid = z > 0
            uv = np.stack([self.cx + self.fx * x, self.cy + self.fy * y], axis=1)
        return uv, valid & self._inside(uv)

    def camera_info(self) -> CameraInfoFields:
        """Return the CameraInfo fields (zero ``plumb_bob`` distortion if none)."""
        return camera_info_fields(
            self.width, self.height, self.distortion_model,
            self.d or (0.0,) * lens.coefficient_count(self.distortion_model),
            self.fx, self.fy, self.cx, self.cy)


def camera_info_fields(width: int, height: int, model: str, d: tuple[float, ...], fx: float,
                       fy: float, cx: float, cy: float) -> CameraInfoFields:
    """Return CameraInfo fields with ``K = [fx, 0, cx; 0, fy, cy; 0, 0, 1]``.

    ``R`` is the identity and ``P = [K | 0]``.
    """
    return CameraInfoFields(
        width=width, height=height, distortion_model=model, d=tuple(d),
        k=(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0),
        r=(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        p=(fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0))


def pixels_per_radian(camera: CameraModel) -> float:
    """Return the pixels per radian at the image centre: a panorama's ``f_az``, else ``fx``.

    The unit that turns pixel thresholds into the solvers' angles.
    """
    return float(camera.f_az if camera.kind == 'panoramic' else camera.fx)  # type: ignore


def horizontal_fov(camera: CameraModel) -> float:
    """Return a camera model's horizontal field of view through its principal point, radians.

    The bearings of the outer edges of the first and last columns on the principal
    point's row; a panorama's is ``2 pi``.
    """
    if camera.kind == 'panoramic':
        return 2.0 * math.pi
    row = float(camera.cy)
    bearing, _ = camera.pixel_to_bearing(np.array([[-0.5, row], [camera.width - 0.5, row]]))
    return float(np.mod(bearing[0] - bearing[1], 2.0 * np.pi))


def make_camera(kind: str, width: int | None = None, height: int | None = None,
                hfov_deg: float | None = None, distortion: tuple[str, tuple[float, ...]]
                | None = None) -> CameraModel:
    """Build a camera by name with the project's default sizes.

    Args:
        kind: ``'panoramic'`` (default 1024 x 256), ``'pinhole'`` or ``'fisheye'``
            (default 640 x 480).
        width: image width, pixels, or ``None`` for the default.
        height: image height, pixels, or ``None`` for the default.
        hfov_deg: horizontal field of view across the image width, degrees (default
            90 pinhole, 180 fisheye).
        distortion: ``(model, coefficients)``: ``plumb_bob`` or
            ``rational_polynomial`` for a pinhole, ``equidistant`` for a fisheye
            (whose focal length then makes the image width span ``hfov_deg``).

    Raises:
        VbnCommonError: unknown kind, a distortion the kind cannot have, or invalid
            size or coefficients.
    """
    if kind == 'panoramic':
        if distortion is not None:
            raise VbnCommonError('a panoramic camera has no lens distortion')
        return PanoramicCamera(width or 1024, height or 256)
    if kind == 'pinhole':
        camera = PinholeCamera.from_fov(width or 640, height or 480,
                                        90.0 if hfov_deg is None else hfov_deg)
        if distortion is None:
            return camera
        model, d = distortion
        if model not in lens.BROWN_MODELS:
            raise VbnCommonError(f'a pinhole camera takes plumb_bob or rational_polynomial '
                                 f'distortion, got {model!r}')
        return PinholeCamera(camera.width, camera.height, camera.fx, camera.fy, camera.cx,
                             camera.cy, distortion_model=model, d=tuple(d))
    if kind == 'fisheye':
        from vbn_common.geometry.fisheye import FisheyeCamera
        model, d = distortion if distortion is not None else ('equidistant', ())
        if model != 'equidistant':
            raise VbnCommonError(f'a fisheye camera takes equidistant distortion, '
                                 f'got {model!r}')
        return FisheyeCamera.from_fov(width or 640, height or 480,
                                      180.0 if hfov_deg is None else hfov_deg, tuple(d))
    raise VbnCommonError(f'unknown camera model {kind!r} (expected panoramic, pinhole or '
                         f'fisheye)')


def camera_from_info(info: CameraInfoLike) -> CameraModel:
    """Build the camera model a ``sensor_msgs/CameraInfo`` describes.

    Reads only the attributes ``width``, ``height``, ``distortion_model``, ``d`` and
    ``k`` (duck-typed: rclpy and rosbags messages and :class:`CameraInfoFields`).
    ``'cylindrical'`` gives a :class:`PanoramicCamera` with ``K = [f_az, 0, cx; 0, f_y,
    y0; 0, 0, 1]``, where ``f_az = width / (2 pi)`` and ``cx = width / 2`` (a full
    360-degree panorama, forward in the middle column); ``'plumb_bob'`` and
    ``'rational_polynomial'`` give a :class:`PinholeCamera`, ``'equidistant'`` a
    :class:`~vbn_common.geometry.fisheye.FisheyeCamera`, each with ``K = [fx, 0, cx; 0,
    fy, cy; 0, 0, 1]`` and its ``d`` (empty or the model's count). Intrinsics equal to
    a model's defaults come back as the defaults, so
    ``camera_from_info(camera.camera_info()) == camera``.

    Args:
        info: the camera info.

    Returns:
        The camera model.

    Raises:
        VbnCommonError: a missing attribute, an unknown distortion model, a ``d``
            of the wrong length or not finite, distortion on a panorama, a
            malformed ``K`` (zeros, NaN, skew), a panorama that does not span 360
            degrees about its middle column, or an invalid image size.
    """
    try:
        width_raw, height_raw = info.width, info.height
        model, d_raw, k_raw = info.distortion_model, info.d, info.k
    except AttributeError as exc:
        raise VbnCommonError(f'camera info lacks a CameraInfo field: {exc}') from exc
    width, height = _image_size(width_raw, height_raw)
    try:
        k = np.asarray(k_raw, dtype=float).reshape(-1)
        d = np.asarray(d_raw, dtype=float).reshape(-1)
    except (TypeError, ValueError) as error:
        raise VbnCommonError(
            f'camera info k and d must be numbers, got k={k_raw!r}, d={d_raw!r}') from error
    if k.size != 9 or not np.all(np.isfinite(k)):
        raise VbnCommonError(f'camera info k must hold 9 finite numbers, '
                             f'got {k.tolist()}')
    if k[1] != 0.0 or k[3] != 0.0 or tuple(k[6:]) != _IDENTITY_K_ROW3:
        raise VbnCommonError(f'camera info k must be [f, 0, c; 0, f, c; 0, 0, 1], '
                             f'got {k.tolist()}')
    if model == 'cylindrical':
        if np.any(d != 0.0):
            raise VbnCommonError(f'cylindrical camera info has no distortion, '
                                 f'got d={d.tolist()}')
        camera = PanoramicCamera(width, height)
        if not (math.isclose(k[0], camera.f_az, rel_tol=1e-6)
                and math.isclose(k[2], camera.cx, rel_tol=0.0, abs_tol=1e-6 * width)):
            raise VbnCommonError(
                f'cylindrical camera info must span 360 degrees about the middle column: '
                f'expected k[0] = width / (2 pi) = {camera.f_az} and k[2] = {camera.cx}, '
                f'got {k[0]} and {k[2]}')
        f_y = None if math.isclose(k[4], camera.f_vertical, rel_tol=1e-12) else float(k[4])
        y0 = None if math.isclose(k[5], camera.horizon_row, rel_tol=1e-12) else float(k[5])
        if f_y is not None and not f_y > 0:
            raise VbnCommonError(f'cylindrical camera info needs f_y = k[4] > 0, '
                                 f'got {f_y}')
        return PanoramicCamera(width, height, f_y=f_y, y0=y0)
    intrinsics = (width, height, float(k[0]), float(k[4]), float(k[2]), float(k[5]))
    if model in lens.BROWN_MODELS:
        return PinholeCamera(*intrinsics, distortion_model=model, d=tuple(d.tolist()))
    if model == 'equidistant':
        from vbn_common.geometry.fisheye import FisheyeCamera
        return FisheyeCamera(*intrinsics, d=tuple(d.tolist()))
    raise VbnCommonError(f'unknown camera info distortion_model {model!r} (expected '
                         f'cylindrical, plumb_bob, rational_polynomial or equidistant)')


def _coefficients(model: str, d: Any, models: dict[str, int]) -> tuple[float, ...]:
    """Return ``d`` as floats, checked against the model (empty: no distortion)."""
    if model not in models:
        raise VbnCommonError(f'unknown distortion model {model!r} (expected '
                             f'{" or ".join(models)})')
    values = tuple(float(v) for v in np.asarray(d, dtype=float).reshape(-1))
    if values and len(values) != models[model]:
        raise VbnCommonError(f'{model} distortion takes {models[model]} coefficients, '
                             f'got {len(values)}')
    if not all(math.isfinite(v) for v in values):
        raise VbnCommonError(f'distortion coefficients must be finite, got {list(values)}')
    return values if any(values) else ()


def _image_size(width: Any, height: Any) -> tuple[int, int]:
    """Return ``(width, height)`` as ints (message fields may be numpy integers)."""
    try:
        size = int(width), int(height)
    except (TypeError, ValueError) as error:
        raise VbnCommonError(f'image size must be integers, '
                             f'got {width!r} x {height!r}') from error
    if size != (width, height):
        raise VbnCommonError(f'image size must be integers, got {width!r} x {height!r}')
    return size


def _check_size(width: int, height: int) -> None:
    if not (isinstance(width, int) and isinstance(height, int)) or width < 8 or height < 8:
        raise VbnCommonError(f'image size must be at least 8 x 8 pixels, '
                             f'got {width} x {height}')
    if width > 16384 or height > 16384:
        raise VbnCommonError(f'image size {width} x {height} is too large (max 16384)')
