"""Lens distortion of ``sensor_msgs/CameraInfo``: plumb_bob, rational_polynomial, equidistant.

The three models ROS drivers publish (``sensor_msgs/distortion_models.hpp``), as
OpenCV defines them, on normalised coordinates (``x = X / Z``, ``y = Y / Z`` in the
optical frame) or, for the fisheye, on the angle from the optical axis:

- ``plumb_bob`` (Brown-Conrady, ``d = (k1, k2, p1, p2, k3)``) and
  ``rational_polynomial`` (``d = (k1, k2, p1, p2, k3, k4, k5, k6)``)::

      r2 = x^2 + y^2
      radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
      xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
      yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y

- ``equidistant`` (OpenCV's fisheye model, ``d = (k1, k2, k3, k4)``): a ray at angle
  ``theta`` from the optical axis lands at radius
  ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)`` (in units of
  the focal length) in the direction of its azimuth about the axis. ``theta`` is taken
  from the ray itself (``atan2(hypot(X, Y), Z)``), not from ``X / Z``, so that rays at
  and beyond 90 degrees (a 180 to 200 degree lens) project too.

Both mappings are only invertible while they grow with the radius: :func:`brown_limit`
and :func:`equidistant_limit` give the largest undistorted radius (or angle) up to which
they do, and a point beyond it is outside the camera's model (``project`` marks it
invalid; a pixel that would need it does not exist in a real image).

The inverses, on the hot path of the builder and the localizer (each keypoint becomes a
ray; images are never undistorted): :func:`brown_undistort` runs OpenCV's
``undistortPoints`` with a convergence criterion (50 iterations, 1e-12) and finishes
with Newton steps; :func:`equidistant_theta` is a vectorised
Newton iteration on ``theta_d(theta)`` (OpenCV's ``fisheye.undistortPoints`` returns
``X / Z``, which does not exist at 90 degrees).
"""
from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ['BROWN_MODELS', 'MODELS', 'brown_distort', 'brown_limit', 'brown_undistort',
           'coefficient_count', 'equidistant_limit', 'equidistant_theta',
           'equidistant_theta_d']

#: Distortion models on normalised coordinates, with their coefficient counts.
BROWN_MODELS = {'plumb_bob': 5, 'rational_polynomial': 8}
#: Every model this module handles, with its coefficient count.
MODELS = {**BROWN_MODELS, 'equidistant': 4}

_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)


def coefficient_count(model: str) -> int:
    """Return the number of ``d`` coefficients of a model (KeyError if unknown)."""
    return MODELS[model]


def _padded(d: np.ndarray, n: int) -> tuple[float, ...]:
    """Return the first ``n`` coefficients, zeros after the given ones (np.pad costs more)."""
    values = [float(v) for v in np.asarray(d, float).reshape(-1)[:n]]
    return tuple(values + [0.0] * (n - len(values)))


def _brown_coefficients(d: np.ndarray) -> tuple[float, ...]:
    return _padded(d, 8)


def brown_distort(x: np.ndarray, y: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the distorted normalised coordinates ``(xd, yd)`` (module docstring)."""
    k1, k2, p1, p2, k3, k4, k5, k6 = _brown_coefficients(np.asarray(d, float).reshape(-1))
    r2 = x * x + y * y
    radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def brown_limit(d: np.ndarray, r_max: float = 10.0) -> float:
    """Return the undistorted radius up to which the radial mapping ``r radial(r)`` grows.

    Sampled finely on ``[0, r_max]`` (``r_max`` = 10 is 84 degrees off axis); ``r_max``
    when it grows throughout. The tangential terms are small and are not considered.
    """
    k1, k2, _, _, k3, k4, k5, k6 = _brown_coefficients(np.asarray(d, float).reshape(-1))
    r = np.linspace(0.0, r_max, 20001)
    r2 = r * r
    denominator = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    mapped = r * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / np.where(
        denominator > 0, denominator, np.nan)
    bad = ~(np.diff(mapped) > 0)
    return float(r[int(np.argmax(bad))]) if bad.any() else float(r_max)


def brown_undistort(uv: np.ndarray, k: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Return ``(n, 2)`` undistorted normalised coordinates ``(x, y)`` of pixels.

    Args:
        uv: ``(n, 2)`` pixel coordinates.
        k: ``(3, 3)`` intrinsic matrix.
        d: plumb_bob or rational_polynomial coefficients.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2)
    if uv.shape[0] == 0:
        return np.zeros((0, 2))
    k = np.asarray(k, np.float64)
    d = np.asarray(d, np.float64).reshape(-1)
    xy = cv2.undistortPoints(uv, k, d, criteria=_UNDISTORT_CRITERIA).reshape(-1, 2)
    # OpenCV's fixed-point iteration can stall under strong distortion: Newton steps on
    # the forward mapping (a central-difference Jacobian) finish it.
    target = np.column_stack([(uv[:, 0, 0] - k[0, 2]) / k[0, 0],
                              (uv[:, 0, 1] - k[1, 2]) / k[1, 1]])
    h = 1e-7
    for _ in range(5):
        fx, fy = brown_distort(xy[:, 0], xy[:, 1], d)
        rx, ry = fx - target[:, 0], fy - target[:, 1]
        if np.all(np.abs(rx) + np.abs(ry) < 1e-14):
            break
        ax, ay = brown_distort(xy[:, 0] + h, xy[:, 1], d)
        bx, by = brown_distort(xy[:, 0] - h, xy[:, 1], d)
        cx, cy = brown_distort(xy[:, 0], xy[:, 1] + h, d)
        ex, ey = brown_distort(xy[:, 0], xy[:, 1] - h, d)
        j11, j21 = (ax - bx) / (2 * h), (ay - by) / (2 * h)
        j12, j22 = (cx - ex) / (2 * h), (cy - ey) / (2 * h)
        det = j11 * j22 - j12 * j21
        det = np.where(np.abs(det) > 1e-12, det, np.nan)
        step = np.column_stack([(j22 * rx - j12 * ry) / det, (j11 * ry - j21 * rx) / det])
        xy = np.where(np.isfinite(step), xy - step, xy)
    return xy


def equidistant_theta_d(theta: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Return the distorted radius ``theta_d`` of rays at ``theta`` from the axis."""
    k1, k2, k3, k4 = _padded(d, 4)
    t2 = theta * theta
    return theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))


def _equidistant_slope(theta: np.ndarray, d: np.ndarray) -> np.ndarray:
    k1, k2, k3, k4 = _padded(d, 4)
    t2 = theta * theta
    return 1.0 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))


def equidistant_limit(d: np.ndarray, theta_max: float = math.radians(120.0)) -> float:
    """Return the angle up to which ``theta_d(theta)`` grows (at most ``theta_max``)."""
    theta = np.linspace(0.0, theta_max, 20001)
    bad = ~(_equidistant_slope(theta, d) > 0)
    return float(theta[int(np.argmax(bad))]) if bad.any() else float(theta_max)


def equidistant_theta(theta_d: np.ndarray, d: np.ndarray, limit: float) -> np.ndarray:
    """Return the angle ``theta`` of radius ``theta_d`` (NaN beyond the model's ``limit``).

    Newton's iteration from ``theta = theta_d``, kept inside ``[0, limit]``, where the
    mapping grows, so it converges to the one root there.
    """
    theta_d = np.asarray(theta_d, dtype=float)
    top = equidistant_theta_d(np.float64(limit), d)
    theta = np.clip(theta_d, 0.0, limit)
    for _ in range(30):
        step = (equidistant_theta_d(theta, d) - theta_d) / _equidistant_slope(theta, d)
        theta = np.clip(theta - step, 0.0, limit)
        if np.all(np.abs(step) < 1e-13):
            break
    return np.where(theta_d <= top, theta, np.nan)
