"""Compiled Gauss-Newton steps on the angular errors of rays to 3-D points.

Not in the thesis. :func:`~landmark_localizer.absolute_pose.refine_absolute` polishes a
tracked frame's pose on a hundred rays two or three times a frame; written with numpy
its steps were a dozen array calls each on arrays of a few hundred numbers, where the
calls' fixed cost was most of the time (0.79 ms a refinement on the pinhole room).
These kernels, compiled by numba, loop over the rays once a step and accumulate the
normal equations directly (0.03 ms). The model is the one of
:func:`~landmark_localizer.absolute_pose._residuals`: the residual of a ray is
``R(pitch, roll) ray - v / |v|`` with ``v = Rz(yaw)^T (p - (x, y, dz))``, over the state
``(x, y, yaw, pitch, roll, dz)``.

Compiled once per machine: ``cache=True`` keeps the machine code beside the sources
(or in numba's cache directory where they are read-only).
"""
from __future__ import annotations

import math

from numba import njit
import numpy as np

__all__ = ['SINGULAR', 'angular_errors', 'coarse_inliers', 'gauss_newton', 'linearise',
           'normal_equations', 'solve_in_place', 'wrap']

#: OpenCV's LU (``DECOMP_LU``) calls a pivot this small singular.
SINGULAR = 100.0 * np.finfo(float).eps


@njit(cache=True)
def wrap(angle: float) -> float:
    """``angle`` in ``[-pi, pi)`` (:func:`vbn_common.geometry.frames.wrap_angle`)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def _row(state: np.ndarray, ray: np.ndarray, point: np.ndarray, res: np.ndarray,
         jac: np.ndarray) -> None:
    """One ray's residual ``res (3,)`` and its derivatives ``jac (3, 6)`` at ``state``.

    ``d(-u)/d(state) = -(I - u u^T) / |v| dv/d(state)``: for ``x``, ``y`` and ``dz``
    ``dv`` is a column of ``-Rz(yaw)^T``; for the yaw ``dv = (v_y, -v_x, 0)`` is
    orthogonal to ``u``. The tilt's columns turn the ray by ``dR/dpitch`` and
    ``dR/droll`` with ``R = Ry(pitch) Rx(roll)``.
    """
    yaw, pitch, roll = state[2], state[3], state[4]
    cp, sp, cr, sr = math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    c, s = math.cos(yaw), math.sin(yaw)
    a0, a1, a2 = ray[0], ray[1], ray[2]
    dx, dy, dz = point[0] - state[0], point[1] - state[1], point[2] - state[5]
    v0, v1, v2 = c * dx + s * dy, -s * dx + c * dy, dz
    inv = 1.0 / math.sqrt(max(v0 * v0 + v1 * v1 + v2 * v2, 1e-24))
    u0, u1, u2 = v0 * inv, v1 * inv, v2 * inv
    res[0] = cp * a0 + sp * sr * a1 + sp * cr * a2 - u0
    res[1] = cr * a1 - sr * a2 - u1
    res[2] = -sp * a0 + cp * sr * a1 + cp * cr * a2 - u2
    along_x = u0 * c - u1 * s    # u . (c, -s, 0)
    along_y = u0 * s + u1 * c    # u . (s, c, 0)
    jac[0, 0], jac[1, 0], jac[2, 0] = (c - u0 * along_x) * inv, \
        (-s - u1 * along_x) * inv, -u2 * along_x * inv
    jac[0, 1], jac[1, 1], jac[2, 1] = (s - u0 * along_y) * inv, \
        (c - u1 * along_y) * inv, -u2 * along_y * inv
    jac[0, 2], jac[1, 2], jac[2, 2] = -u1, u0, 0.0
    jac[0, 3], jac[1, 3], jac[2, 3] = -sp * a0 + cp * sr * a1 + cp * cr * a2, 0.0, \
        -cp * a0 - sp * sr * a1 - sp * cr * a2
    jac[0, 4], jac[1, 4], jac[2, 4] = sp * cr * a1 - sp * sr * a2, -sr * a1 - cr * a2, \
        cp * cr * a1 - cp * sr * a2
    jac[0, 5], jac[1, 5], jac[2, 5] = -u0 * u2 * inv, -u1 * u2 * inv, (1.0 - u2 * u2) * inv


@njit(cache=True)
def angular_errors(state: np.ndarray, rays: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n,) angles between the rays turned by the state's tilt and the directions to points.

    The errors :func:`~landmark_localizer.absolute_pose._angular_errors` gives at the
    state's planar pose for ``rays @ tilt_rotation(pitch, roll).T`` and the points
    lowered by ``dz``.
    """
    res, jac = np.empty(3), np.empty((3, 6))
    out = np.empty(rays.shape[0])
    for i in range(rays.shape[0]):
        _row(state, rays[i], points[i], res, jac)
        # |t - u|^2 = 2 - 2 t.u for unit t and u (the turned ray and the direction).
        squared = res[0] * res[0] + res[1] * res[1] + res[2] * res[2]
        out[i] = 2.0 * math.asin(min(1.0, 0.5 * math.sqrt(squared)))
    return out


@njit(cache=True)
def coarse_inliers(poses: np.ndarray, rays: np.ndarray, points: np.ndarray, threshold: float,
                   tilt_prior: float, height_prior: float) -> np.ndarray:
    """(m, n) bool: the rays each planar pose ``(x, y, yaw)`` explains, its tilt unknown.

    :func:`~landmark_localizer.absolute_pose._coarse_inliers`: the azimuth within
    ``threshold`` (as an arc at the ray's horizontal length), the elevation within
    ``threshold`` plus three tilt priors and three height priors at the point's
    distance (at least 0.5 m), the point in front.
    """
    m, n = poses.shape[0], rays.shape[0]
    out = np.empty((m, n), np.bool_)
    two_pi = 2.0 * math.pi
    for j in range(n):
        ray_azimuth = math.atan2(rays[j, 1], rays[j, 0])
        ray_elevation = math.atan2(rays[j, 2], math.hypot(rays[j, 0], rays[j, 1]))
        for i in range(m):
            c, s = math.cos(poses[i, 2]), math.sin(poses[i, 2])
            dx, dy = points[j, 0] - poses[i, 0], points[j, 1] - poses[i, 1]
            v0, v1, v2 = c * dx + s * dy, -s * dx + c * dy, points[j, 2]
            norm = max(math.sqrt(v0 * v0 + v1 * v1 + v2 * v2), 1e-12)
            v0, v1, v2 = v0 / norm, v1 / norm, v2 / norm
            azimuth = math.atan2(v1, v0) - ray_azimuth
            azimuth = abs((azimuth + math.pi) % two_pi - math.pi)
            horizontal = math.hypot(v0, v1)
            elevation = abs(math.atan2(v2, horizontal) - ray_elevation)
            slack = threshold + 3.0 * tilt_prior + 3.0 * height_prior / max(
                math.hypot(dx, dy), 0.5)
            out[i, j] = azimuth * horizontal <= threshold and elevation <= slack and \
                v0 * rays[j, 0] + v1 * rays[j, 1] + v2 * rays[j, 2] > 0
    return out


@njit(cache=True)
def linearise(state: np.ndarray, rays: np.ndarray, points: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """``(r (n, 3), J (n, 3, 6))``: every ray's residual and derivatives at ``state``."""
    n = rays.shape[0]
    res, jac = np.empty((n, 3)), np.empty((n, 3, 6))
    for i in range(n):
        _row(state, rays[i], points[i], res[i], jac[i])
    return res, jac


@njit(cache=True)
def normal_equations(state: np.ndarray, rays: np.ndarray, points: np.ndarray,
                     threshold: float, point_weights: np.ndarray, hessian: np.ndarray,
                     gradient: np.ndarray) -> float:
    """Fill ``J^T W J (6, 6)`` and ``J^T W r (6,)`` at ``state``; return ``sum w_i |r_i|^2``.

    ``W``: each ray's Huber weight (1 within ``threshold`` of its angular error, else
    ``threshold / |r|``) times its ``point_weights``; the returned sum weighs the
    squares by ``point_weights`` alone (the rays' noise, :func:`refine_absolute`).
    """
    hessian[:, :] = 0.0
    gradient[:] = 0.0
    res, jac = np.empty(3), np.empty((3, 6))
    squares = 0.0
    for i in range(rays.shape[0]):
        _row(state, rays[i], points[i], res, jac)
        norm = math.sqrt(res[0] * res[0] + res[1] * res[1] + res[2] * res[2])
        squares += point_weights[i] * norm * norm
        w = min(1.0, threshold / max(norm, 1e-12)) * point_weights[i]
        for j in range(6):
            gradient[j] += w * (jac[0, j] * res[0] + jac[1, j] * res[1] + jac[2, j] * res[2])
            for m in range(j, 6):
                hessian[j, m] += w * (jac[0, j] * jac[0, m] + jac[1, j] * jac[1, m]
                                      + jac[2, j] * jac[2, m])
    for j in range(6):
        for m in range(j):
            hessian[j, m] = hessian[m, j]
    return squares


@njit(cache=True)
def huber_accumulate(r: np.ndarray, jac: np.ndarray, threshold: float, a: np.ndarray,
                     b: np.ndarray) -> None:
    """Add the Huber-weighted ``J^T W J`` to ``a`` and ``-J^T W r`` to ``b``, ray by ray.

    ``r (n,)`` residuals, ``jac (n, m)`` their Jacobian, ``threshold`` the Huber
    threshold (a residual beyond it weighs ``threshold / |r|``).
    """
    m = jac.shape[1]
    for i in range(r.size):
        w = min(1.0, threshold / max(abs(r[i]), 1e-12))
        for j in range(m):
            b[j] -= w * jac[i, j] * r[i]
            for k in range(m):
                a[j, k] += w * jac[i, j] * jac[i, k]


@njit(cache=True)
def solve_in_place(a: np.ndarray, b: np.ndarray, tiny: float) -> bool:
    """Solve ``a x = b`` in place (``b`` becomes ``x``): LU with partial pivoting.

    False when a pivot's magnitude is below ``tiny`` (:data:`SINGULAR`: as OpenCV's
    ``DECOMP_LU`` reports; 0: an exactly singular matrix, as LAPACK's).
    """
    n = b.shape[0]
    for i in range(n):
        k = i
        for j in range(i + 1, n):
            if abs(a[j, i]) > abs(a[k, i]):
                k = j
        if abs(a[k, i]) < tiny or a[k, i] == 0.0:
            return False
        if k != i:
            for j in range(i, n):
                a[i, j], a[k, j] = a[k, j], a[i, j]
            b[i], b[k] = b[k], b[i]
        for j in range(i + 1, n):
            factor = a[j, i] / a[i, i]
            for m in range(i + 1, n):
                a[j, m] -= factor * a[i, m]
            b[j] -= factor * b[i]
    for i in range(n - 1, -1, -1):
        total = b[i]
        for m in range(i + 1, n):
            total -= a[i, m] * b[m]
        b[i] = total / a[i, i]
    return True


@njit(cache=True)
def gauss_newton(state: np.ndarray, rays: np.ndarray, points: np.ndarray, threshold: float,
                 point_weights: np.ndarray, free: np.ndarray, prior_info: np.ndarray,
                 centre: np.ndarray, iterations: int, stop_m: float, stop_rad: float) -> int:
    """Huber-weighted Gauss-Newton on ``state (6,)`` in place; the steps taken, -1: failed.

    ``free``: (6,) indices of the unknowns that move (``x``, ``y`` and the yaw first);
    ``prior_info``: their priors' information (0: none) around ``centre`` (6,), the
    yaw's offset wrapped. A step solves the free unknowns' normal equations (a ridge of
    1e-12 on the diagonal); it stops once a step moves the position less than
    ``stop_m`` and the heading less than ``stop_rad``. -1: a singular system or a state
    that is not finite.
    """
    hessian, gradient = np.empty((6, 6)), np.empty(6)
    k = free.size
    a, b = np.empty((k, k)), np.empty(k)
    steps = 0
    for _ in range(iterations):
        normal_equations(state, rays, points, threshold, point_weights, hessian, gradient)
        for i in range(k):
            offset = state[free[i]] - centre[free[i]]
            if i == 2:
                offset = wrap(offset)
            b[i] = -(gradient[free[i]] + prior_info[i] * offset)
            for j in range(k):
                a[i, j] = hessian[free[i], free[j]]
            a[i, i] += prior_info[i] + 1e-12
        if not solve_in_place(a, b, SINGULAR):
            return -1
        for i in range(k):
            state[free[i]] += b[i]
        state[2] = wrap(state[2])
        steps += 1
        if not math.isfinite(state.sum()):
            return -1
        if max(abs(b[0]), abs(b[1])) < stop_m and abs(b[2]) < stop_rad:
            break
    return steps
