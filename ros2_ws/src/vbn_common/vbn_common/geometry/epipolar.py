"""Epipolar geometry shared by the two-view solvers (thesis 7.4 and 7.5).

The conventions of :mod:`vbn_common.geometry.two_view`: unit rays in the optical frame,
motions ``X_cur = R X_model + T`` with ``p_cur^T E p_model = 0`` and ``E = [T]x R``,
planar motions ``(theta, phi)`` in the model camera's planar (REP 103) frame. Here:
conversions between planar and optical motions, Sampson angular errors (general and,
in closed form, planar), triangulated depths for the cheirality tests, the parallax
test that refuses views at one place, the Gauss-Newton polish of a planar motion and
the covariance of ``(theta, phi)`` that every solver reports.
"""
from __future__ import annotations

import math

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION, wrap_angle
from vbn_common.geometry.motion import RelativeMotion

__all__ = [
    'check_rays',
    'check_translation',
    'finish_motion',
    'optical_to_planar',
    'parallax',
    'planar_epipolar_residuals',
    'planar_essential_matrix',
    'planar_sampson',
    'planar_to_optical',
    'pointwise_planar_residuals',
    'refine_planar',
    'residual_jacobian',
    'rms',
    'rot_z',
    'sampson',
    'skew',
    'triangulate_depths',
]

_M = BASE_TO_CAMERA_ROTATION  # p_base = _M @ p_optical


def check_rays(rays_model: np.ndarray, rays_current: np.ndarray, minimum: int,
               method: str) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(rays_model, dtype=float)
    b = np.asarray(rays_current, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape != b.shape:
        raise VbnCommonError(f'{method}: rays must be two (n, 3) arrays of the same '
                             f'shape, got {a.shape} and {b.shape}')
    if len(a) < minimum:
        raise VbnCommonError(f'{method}: needs at least {minimum} correspondences, '
                             f'got {len(a)}')
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise VbnCommonError(f'{method}: rays must be finite')
    na, nb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    if np.any(na == 0) or np.any(nb == 0):
        raise VbnCommonError(f'{method}: rays must be non-zero')
    return a / na[:, None], b / nb[:, None]


def rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def skew(t: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])


def planar_to_optical(theta: float, phi: float) -> tuple[np.ndarray, np.ndarray]:
    """Return optical ``(R, T)``, ``X_cur = R X_model + T``, of a planar motion.

    The current camera sits at ``(cos phi, sin phi)`` in the model camera's planar
    frame, turned by ``theta``.
    """
    rz_t = rot_z(theta).T
    centre = np.array([math.cos(phi), math.sin(phi), 0.0])
    return _M.T @ rz_t @ _M, -_M.T @ rz_t @ centre


def optical_to_planar(R: np.ndarray, T: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Return ``(theta, centre, planar_rotation)`` of an optical motion ``X_cur = R X + T``.

    ``centre`` is the current camera's centre in the model camera's planar frame
    (``(3,)``, ``z`` up), ``planar_rotation`` maps model planar directions to current
    ones.
    """
    orientation = _M @ R.T @ _M.T  # current axes in the model's planar frame
    theta = float(math.atan2(orientation[1, 0], orientation[0, 0]))
    return theta, _M @ (-R.T @ T), orientation.T


def planar_essential_matrix(theta: float, phi: float) -> np.ndarray:
    R, T = planar_to_optical(theta, phi)
    return skew(T) @ R


def sampson(E: np.ndarray, f_model: np.ndarray, f_current: np.ndarray) -> np.ndarray:
    """Return signed Sampson errors of ``f_cur^T E f_model = 0`` on the unit sphere.

    ``E`` is ``(3, 3)`` or ``(m, 3, 3)``; the result ``(n,)`` or ``(m, n)`` radians.
    The gradient is projected on each (unit) ray's tangent plane, so the error is an
    angle: ``|g|^2 = |E f1|^2 - a^2 + |E^T f2|^2 - a^2`` for the algebraic error ``a``.
    """
    e_f1 = E @ f_model.T                                    # (..., 3, n)
    et_f2 = np.swapaxes(E, -1, -2) @ f_current.T
    algebraic = np.sum(f_current.T * e_f1, axis=-2)
    a2 = algebraic * algebraic
    denom2 = np.sum(e_f1 * e_f1, axis=-2) + np.sum(et_f2 * et_f2, axis=-2) - 2.0 * a2
    return algebraic / np.sqrt(np.maximum(denom2, 1e-300))


def planar_epipolar_residuals(rays_model: np.ndarray, rays_current: np.ndarray,
                              theta: float, phi: float) -> np.ndarray:
    """Return the Sampson angular errors of correspondences under a planar motion.

    Args:
        rays_model: ``(n, 3)`` unit rays of the model view (optical frame).
        rays_current: ``(n, 3)`` unit rays of the current view.
        theta: the current camera's yaw relative to the model camera's, radians.
        phi: bearing of the current camera from the model camera, radians (module
            conventions).

    Returns:
        ``(n,)`` signed errors, radians (zero for an exact correspondence).
    """
    return sampson(planar_essential_matrix(theta, phi), np.asarray(rays_model, dtype=float),
                   np.asarray(rays_current, dtype=float))


def pointwise_planar_residuals(rays_model: np.ndarray, rays_current: np.ndarray,
                               theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Return Sampson angular errors, correspondence ``i`` under its own planar motion.

    Like :func:`planar_epipolar_residuals`, but ``theta`` and ``phi`` are ``(n,)``:
    each correspondence may belong to another model view (one motion per view,
    repeated for its correspondences), so that the errors of several views come from
    one vectorised pass (the localizer refines a pose on all its views at once). They
    may also be ``(m, n)``: ``m`` such sets of motions at once, ``(m, n)`` errors.

    Args:
        rays_model: ``(n, 3)`` unit rays of each correspondence's model view.
        rays_current: ``(n, 3)`` unit rays of the current view.
        theta: ``(n,)`` (or ``(m, n)``) relative yaw of each correspondence's motion,
            radians.
        phi: ``(n,)`` (or ``(m, n)``) bearing of each correspondence's motion, radians.

    Returns:
        ``(n,)`` (or ``(m, n)``) signed errors, radians.
    """
    return planar_sampson(np.asarray(rays_model, dtype=float) @ _M.T,
                          np.asarray(rays_current, dtype=float) @ _M.T,
                          np.asarray(theta, dtype=float), np.asarray(phi, dtype=float))


def planar_sampson(g1: np.ndarray, g2: np.ndarray, theta: np.ndarray,
                   phi: np.ndarray) -> np.ndarray:
    """Sampson errors of planar motions from rays in the planar frame, broadcasting.

    ``g1``, ``g2``: ``(n, 3)`` unit rays (z up); ``theta``, ``phi`` broadcast against
    ``(n,)``: ``(n,)`` for one motion per correspondence, ``(m, 1)`` for ``m`` motions
    scored on every correspondence (``(m, n)`` errors). In the planar frame
    ``E = [T]x Rz(theta)^T`` with ``T = -(cos psi, sin psi, 0)``, ``psi = phi - theta``,
    and for unit rays ``|E g1|^2 = 1 - (T.h)^2`` (``h = Rz(theta)^T g1``) and
    ``|E^T g2|^2 = 1 - (T.g2)^2``: no matrix per motion is formed (equal to
    :func:`planar_epipolar_residuals`, ``ros2_ws/src/vbn_common/test/test_two_view.py``).
    """
    c, s = np.cos(theta), np.sin(theta)
    hx = c * g1[:, 0] + s * g1[:, 1]
    hy = c * g1[:, 1] - s * g1[:, 0]
    psi = phi - theta
    tx, ty = -np.cos(psi), -np.sin(psi)
    hz = g1[:, 2]
    algebraic = hz * (g2[:, 0] * ty - g2[:, 1] * tx) + g2[:, 2] * (tx * hy - ty * hx)
    t_h = tx * hx + ty * hy
    t_g2 = tx * g2[:, 0] + ty * g2[:, 1]
    denom2 = 2.0 - t_h * t_h - t_g2 * t_g2 - 2.0 * algebraic * algebraic
    return algebraic / np.sqrt(np.maximum(denom2, 1e-300))


def triangulate_depths(R: np.ndarray, T: np.ndarray, f_model: np.ndarray,
                       f_current: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return depths ``(l1, l2)`` along the rays with ``l2 f_cur ~ l1 R f_model + T``."""
    a = f_model @ R.T                       # R f_model
    b = f_current
    # min |l1 a + T - l2 b|^2: normal equations of two unknowns per point.
    ab = np.sum(a * b, axis=1)
    at, bt = a @ T, b @ T
    det = ab * ab - 1.0                     # |a| = |b| = 1
    with np.errstate(divide='ignore', invalid='ignore'):
        l1 = (at - ab * bt) / det
        l2 = (ab * at - bt) / det
    return l1, l2


def parallax(f_model: np.ndarray, f_current: np.ndarray) -> float:
    """Return the median angle left between the rays by the best pure rotation.

    The rotation (Kabsch: least squares over all rotations) explains the data when
    the cameras share their centre; what it leaves is the parallax of translation.
    """
    if not len(f_model):
        return 0.0
    U, _, Vt = np.linalg.svd(f_current.T @ f_model)
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt     # f_current ~ R f_model
    rotated = f_model @ R.T
    cos = np.clip(np.sum(rotated * f_current, axis=1), -1.0, 1.0)
    return float(np.median(np.arccos(cos))) if len(cos) else 0.0

def refine_planar(theta: float, phi: float, f_model: np.ndarray, f_current: np.ndarray,
                  iterations: int = 6) -> tuple[float, float]:
    """Gauss-Newton on the Sampson errors over ``(theta, phi)`` (numerical Jacobian)."""
    x = np.array([theta, phi])
    cost, step = math.inf, np.zeros(2)
    for _ in range(iterations):
        r, J = residual_jacobian(x, f_model, f_current)
        new_cost = float(r @ r)
        if new_cost > cost:            # the last step did not help: undo it
            x = x - step
            break
        cost = new_cost
        JtJ = J.T @ J
        if not np.all(np.isfinite(JtJ)) or np.linalg.cond(JtJ) > 1e14:
            break
        step = np.linalg.solve(JtJ, -J.T @ r)
        x = x + step
        if np.max(np.abs(step)) < 1e-11:
            break
    return float(x[0]), float(x[1])


def residual_jacobian(x: np.ndarray, f_model: np.ndarray, f_current: np.ndarray,
                      h: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Residuals at ``x`` and their central-difference Jacobian, in one batched pass."""
    offsets = np.array([[0.0, 0.0], [h, 0.0], [-h, 0.0], [0.0, h], [0.0, -h]])
    points = x + offsets
    err = planar_sampson(f_model @ _M.T, f_current @ _M.T, points[:, :1],
                         points[:, 1:])                                   # (5, n)
    J = np.stack([err[1] - err[2], err[3] - err[4]], axis=1) / (2.0 * h)
    return err[0], J


def finish_motion(theta: float, phi: float, f_model: np.ndarray, f_current: np.ndarray,
                  inliers: np.ndarray, method: str, noise_floor: float,
                  rotation: np.ndarray | None = None,
                  direction: np.ndarray | None = None) -> RelativeMotion:
    """Residual and covariance of ``(theta, phi)`` over the inliers; the result."""
    x = np.array([theta, phi])
    r, J = residual_jacobian(x, f_model[inliers], f_current[inliers])
    dof = max(len(r) - 2, 1)
    rms = float(math.sqrt(r @ r / len(r))) if len(r) else math.inf
    sigma2 = max(float(r @ r) / dof, noise_floor ** 2)
    JtJ = J.T @ J
    try:
        covariance = sigma2 * np.linalg.inv(JtJ)
    except np.linalg.LinAlgError:
        covariance = np.full((2, 2), np.inf)
    if direction is None:
        direction = np.array([math.cos(phi), math.sin(phi)])
    if rotation is None:
        rotation = rot_z(-theta)
    return RelativeMotion(theta=float(wrap_angle(theta)), direction=direction,
                          inliers=inliers, residual=rms, method=method,
                          covariance=covariance, rotation=rotation)


def check_translation(f_model: np.ndarray, f_current: np.ndarray, min_parallax: float,
                      method: str, residual: float = 0.0, ratio: float = 2.5) -> None:
    """Refuse views whose parallax is not above the noise.

    The median angle that the best pure rotation leaves between the rays must
    exceed ``min_parallax`` and ``ratio`` times the inliers' RMS epipolar error: with
    less, a rotation alone explains the data and the direction of translation is
    noise.
    """
    median = parallax(f_model, f_current)
    needed = max(min_parallax, ratio * residual)
    if median < needed:
        raise VbnCommonError(
            f'{method}: the views are at (nearly) the same place: median parallax '
            f'{median:.2e} rad < {needed:.2e} rad, the direction of translation is '
            f'undetermined')


def rms(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(errors * errors))) if len(errors) else 0.0

