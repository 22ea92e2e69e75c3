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
ray; images are never undistorted): :func:`brown_undistort` is a compiled Newton
iteration on the forward mapping, each step halved until it helps (it replaced OpenCV's
``undistortPoints``, whose fixed-point iteration stalled under strong distortion and whose
call cost more than the points); :func:`equidistant_theta` is a vectorised
Newton iteration on ``theta_d(theta)`` (OpenCV's ``fisheye.undistortPoints`` returns
``X / Z``, which does not exist at 90 degrees).
"""
from __future__ import annotations

import math

from numba import njit
import numpy as np

__all__ = ['BROWN_MODELS', 'MODELS', 'brown_coefficients', 'brown_distort', 'brown_invert',
           'brown_limit', 'brown_project', 'brown_undistort', 'coefficient_count',
           'equidistant_limit', 'equidistant_theta', 'equidistant_theta_d']

#: Distortion models on normalised coordinates, with their coefficient counts.
BROWN_MODELS = {'plumb_bob': 5, 'rational_polynomial': 8}
#: Every model this module handles, with its coefficient count.
MODELS = {**BROWN_MODELS, 'equidistant': 4}


def coefficient_count(model: str) -> int:
    """Return the number of ``d`` coefficients of a model (KeyError if unknown)."""
    return MODELS[model]


def _padded(d: np.ndarray, n: int) -> tuple[float, ...]:
    """Return the first ``n`` coefficients, zeros after the given ones (np.pad costs more)."""
    values = [float(v) for v in np.asarray(d, float).reshape(-1)[:n]]
    return tuple(values + [0.0] * (n - len(values)))


def brown_coefficients(d: np.ndarray) -> tuple[float, ...]:
    """Return the eight rational_polynomial coefficients of ``d`` (plumb_bob: zeros after)."""
    return _padded(d, 8)


def brown_distort(x: np.ndarray, y: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the distorted normalised coordinates ``(xd, yd)`` (module docstring)."""
    k1, k2, p1, p2, k3, k4, k5, k6 = brown_coefficients(np.asarray(d, float).reshape(-1))
    r2 = x * x + y * y
    radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


@njit(cache=True, error_model='numpy')
def brown_project(points: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                  c: np.ndarray, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``(n, 2)`` of optical-frame points through Brown's distortion, and validity.

    ``c``: the eight coefficients (:func:`brown_coefficients`), as :func:`brown_invert`
    takes them. ``valid``: in front (``Z > 0``) and within the undistorted radius
    ``limit`` (:func:`brown_limit`); the image's bounds are the camera's to check. The
    same arithmetic as :func:`brown_distort` on ``(X / Z, Y / Z)``, point by point,
    compiled.
    """
    n = points.shape[0]
    uv, valid = np.empty((n, 2)), np.empty(n, np.bool_)
    for i in range(n):
        x, y = points[i, 0] / points[i, 2], points[i, 1] / points[i, 2]
        valid[i] = points[i, 2] > 0 and math.hypot(x, y) <= limit
        xd, yd = _brown_point(x, y, c)
        uv[i, 0], uv[i, 1] = cx + fx * xd, cy + fy * yd
    return uv, valid


def brown_limit(d: np.ndarray, r_max: float = 10.0) -> float:
    """Return the undistorted radius up to which the radial mapping ``r radial(r)`` grows.

    Sampled finely on ``[0, r_max]`` (``r_max`` = 10 is 84 degrees off axis); ``r_max``
    when it grows throughout. The tangential terms are small and are not considered.
    """
    k1, k2, _, _, k3, k4, k5, k6 = brown_coefficients(np.asarray(d, float).reshape(-1))
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
    uv = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 2))
    k = np.asarray(k, np.float64)
    return brown_invert(uv, float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]),
                        np.array(brown_coefficients(np.asarray(d, np.float64).reshape(-1))))


@njit(cache=True, error_model='numpy')
def _brown_point(x: float, y: float, c: np.ndarray) -> tuple[float, float]:
    """:func:`brown_distort` of one point, coefficients ``c`` (8,)."""
    r2 = x * x + y * y
    radial = (1.0 + r2 * (c[0] + r2 * (c[1] + r2 * c[4]))) / \
        (1.0 + r2 * (c[5] + r2 * (c[6] + r2 * c[7])))
    return (x * radial + 2.0 * c[2] * x * y + c[3] * (r2 + 2.0 * x * x),
            y * radial + c[2] * (r2 + 2.0 * y * y) + 2.0 * c[3] * x * y)


@njit(cache=True, error_model='numpy')
def brown_invert(uv: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                 c: np.ndarray) -> np.ndarray:
    """Undistorted normalised ``(x, y)`` ``(n, 2)`` of pixels ``uv (n, 2)``, compiled.

    Newton's method on the forward mapping (:func:`brown_distort`, coefficients ``c``
    (8,)) from the distorted coordinates, a central-difference Jacobian, each step
    halved until it lowers the residual (strong distortion overshoots a full step); it
    stops once the point distorts within 1e-16 of its target, after 30 steps, or when
    no step helps. The same root as OpenCV's ``undistortPoints`` followed by Newton
    steps, without its per-call cost.
    """
    n = uv.shape[0]
    xy = np.empty((n, 2))
    h = 1e-7
    for i in range(n):
        tx, ty = (uv[i, 0] - cx) / fx, (uv[i, 1] - cy) / fy
        x, y = tx, ty
        fx0, fy0 = _brown_point(x, y, c)
        rx, ry = fx0 - tx, fy0 - ty
        residual = abs(rx) + abs(ry)
        for _ in range(30):
            if not residual >= 1e-16:   # converged (or not finite: nothing to do)
                break
            ax, ay = _brown_point(x + h, y, c)
            bx, by = _brown_point(x - h, y, c)
            px, py = _brown_point(x, y + h, c)
            qx, qy = _brown_point(x, y - h, c)
            j11, j21 = (ax - bx) / (2 * h), (ay - by) / (2 * h)
            j12, j22 = (px - qx) / (2 * h), (py - qy) / (2 * h)
            det = j11 * j22 - j12 * j21
            if not abs(det) > 1e-12:
                break
            sx, sy = (j22 * rx - j12 * ry) / det, (j11 * ry - j21 * rx) / det
            t, moved = 1.0, False
            while t > 1e-4:
                nx, ny = x - t * sx, y - t * sy
                gx, gy = _brown_point(nx, ny, c)
                nrx, nry = gx - tx, gy - ty
                if abs(nrx) + abs(nry) < residual:
                    x, y, rx, ry, residual = nx, ny, nrx, nry, abs(nrx) + abs(nry)
                    moved = True
                    break
                t *= 0.5
            if not moved:
                break
        if not math.isfinite(residual):   # a pixel that is not finite has no ray
            x = y = math.nan
        xy[i, 0], xy[i, 1] = x, y
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
    mapping grows, so it converges to the one root there: each radius until its step is
    below 1e-13 rad (at most 30 steps), compiled (a vectorised loop cost a fisheye
    frame's rays 0.3 ms, for a few dozen of them).
    """
    theta_d = np.asarray(theta_d, dtype=float)
    k1, k2, k3, k4 = _padded(d, 4)
    out = _equidistant_newton(np.ascontiguousarray(theta_d.reshape(-1)), k1, k2, k3, k4,
                              float(limit))
    return out.reshape(theta_d.shape)


@njit(cache=True, error_model='numpy')
def _equidistant_newton(theta_d: np.ndarray, k1: float, k2: float, k3: float, k4: float,
                        limit: float) -> np.ndarray:
    t2 = limit * limit
    top = limit * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    out = np.empty(theta_d.size)
    for i in range(theta_d.size):
        target = theta_d[i]
        if not target <= top:
            out[i] = np.nan
            continue
        theta = min(max(target, 0.0), limit)
        for _ in range(30):
            t2 = theta * theta
            value = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
            slope = 1.0 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
            step = (value - target) / slope
            theta = min(max(theta - step, 0.0), limit)
            if abs(step) < 1e-13:
                break
        out[i] = theta
    return out
