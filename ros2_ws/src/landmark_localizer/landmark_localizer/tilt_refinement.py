"""The pose refinement with the frame's own pitch, roll and height.

:func:`~landmark_localizer.pose.refine_pose` solves the planar pose ``(x, y, yaw)`` on
the epipolar errors of all model views (thesis 7.4 and 7.5: planar motion, a level
camera at the exploration's height). A real robot departs from that per frame:
vibration and an uneven floor pitch and roll the camera by fractions of a degree that
the mount does not explain, and a second robot sharing the database carries its
camera at another height. Both break the planar constraint, and the planar pose
absorbs the error.

Here the current camera's state is ``(x, y, yaw, pitch, roll, dz)``: its rays are
levelled by the frame's tilt (:func:`~vbn_common.geometry.mount.tilt_matrix`) and it
stands ``dz`` above the model views' height. The model views stay as the exploration
recorded them (level, after the mount's tilt, at one height), so their planar poses
fix each baseline's horizontal part and its length; ``dz`` is its vertical part. For
correspondence ``i`` of view ``v`` with world directions ``a1`` (model) and ``a2``
(current) and the baseline's direction ``b`` (from the model view to the current
camera), the coplanarity error is ``e = b . (a1 x a2)`` and its Sampson angular error
on the sphere ``e / sqrt(2 - (b . a1)^2 - (b . a2)^2)``, the same measure as the planar
solvers' (:func:`vbn_common.geometry.epipolar.planar_sampson`).

Priors keep the three extra unknowns where the data cannot place them (a robot on the
line through two views, few points): ``pitch, roll ~ N(0, tilt_prior_deg)`` and ``dz ~
N(0, height_prior_m)``, as residual rows scaled to the measurement noise.
Gauss-Newton with Huber weights, the Jacobian by forward differences, compiled
(:mod:`~landmark_localizer.tilt_kernels`); the covariance of ``(x, y, yaw)`` is the
marginal of the full one.
"""
from __future__ import annotations

import math

import numpy as np

from landmark_localizer.tilt_kernels import refine_tilted_in_place
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION

__all__ = ['marginal_covariance', 'refine_tilted', 'tilted_residuals']

_M = BASE_TO_CAMERA_ROTATION  # planar (z up) <- optical


def _levelling(pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """``(m, 3, 3)`` rotations taking the frame's rays to level ones, in the planar frame.

    ``M R_x(pitch) R_z(roll) M^T``: the tilt of :mod:`vbn_common.geometry.mount`, which
    is defined in the optical frame.
    """
    cp, sp, cr, sr = np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    tilt = np.zeros((len(cp), 3, 3))
    tilt[:, 0, 0], tilt[:, 0, 1] = cr, -sr
    tilt[:, 1, 0], tilt[:, 1, 1], tilt[:, 1, 2] = cp * sr, cp * cr, -sp
    tilt[:, 2, 0], tilt[:, 2, 1], tilt[:, 2, 2] = sp * sr, sp * cr, cp
    return _M @ tilt @ _M.T


def _prior(noise: float, tilt_prior_deg: float, height_prior_m: float) -> np.ndarray:
    """Return the prior rows' weights per unknown, in units of the measurement noise."""
    tilt = 1.0 / math.radians(tilt_prior_deg)
    return np.array([0.0, 0.0, 0.0, tilt, tilt, 1.0 / height_prior_m]) * noise


class _Problem:
    """The state-free part of :func:`tilted_residuals`, computed once per refinement."""

    def __init__(self, view_poses: np.ndarray, view: np.ndarray, rays_model: np.ndarray,
                 rays_current: np.ndarray) -> None:
        vp = np.asarray(view_poses, float)[view]                   # (n, 3)
        g1 = np.asarray(rays_model, float) @ _M.T                  # planar frame
        c1, s1 = np.cos(vp[:, 2]), np.sin(vp[:, 2])
        self.a1 = (c1 * g1[:, 0] - s1 * g1[:, 1], s1 * g1[:, 0] + c1 * g1[:, 1],
                   g1[:, 2])                                        # world directions
        self.g2 = np.asarray(rays_current, float) @ _M.T           # (n, 3)
        self.vx, self.vy = vp[:, 0], vp[:, 1]

    def residuals(self, states: np.ndarray) -> np.ndarray:
        """Return the ``(m, n)`` Sampson angular errors of ``m`` states."""
        states = np.atleast_2d(states)
        level = _levelling(states[:, 3], states[:, 4])             # (m, 3, 3)
        c2, s2 = np.cos(states[:, 2]), np.sin(states[:, 2])
        turn = level.copy()                                         # R_z(yaw) @ level
        turn[:, 0] = c2[:, None] * level[:, 0] - s2[:, None] * level[:, 1]
        turn[:, 1] = s2[:, None] * level[:, 0] + c2[:, None] * level[:, 1]
        a2 = np.matmul(turn, self.g2.T)                             # (m, 3, n)
        a2x, a2y, a2z = a2[:, 0], a2[:, 1], a2[:, 2]
        a1x, a1y, a1z = self.a1
        bx = states[:, 0, None] - self.vx
        by = states[:, 1, None] - self.vy
        bz = np.broadcast_to(states[:, 5, None], bx.shape)
        norm = np.maximum(np.sqrt(bx * bx + by * by + bz * bz), 1e-12)
        bx, by, bz = bx / norm, by / norm, bz / norm
        e = bx * (a1y * a2z - a1z * a2y) + by * (a1z * a2x - a1x * a2z) + \
            bz * (a1x * a2y - a1y * a2x)
        d1 = bx * a1x + by * a1y + bz * a1z
        d2 = bx * a2x + by * a2y + bz * a2z
        return e / np.sqrt(np.maximum(2.0 - d1 * d1 - d2 * d2, 1e-12))


def tilted_residuals(states: np.ndarray, view_poses: np.ndarray, view: np.ndarray,
                     rays_model: np.ndarray, rays_current: np.ndarray) -> np.ndarray:
    """Return the ``(m, n)`` Sampson angular errors of ``m`` states (module docstring).

    Args:
        states: ``(m, 6)`` ``(x, y, yaw, pitch, roll, dz)`` of the current camera.
        view_poses: ``(V, 3)`` planar camera poses of the model views.
        view: ``(n,)`` the view of each correspondence.
        rays_model: ``(n, 3)`` optical rays in the model views (already levelled by the
            mount).
        rays_current: ``(n, 3)`` optical rays of the current frame (idem).
    """
    return _Problem(view_poses, view, rays_model, rays_current).residuals(states)


def refine_tilted(initial: np.ndarray, view_poses: np.ndarray, view: np.ndarray,
                  rays_model: np.ndarray, rays_current: np.ndarray, threshold: float,
                  noise: float, tilt_prior_deg: float, height_prior_m: float,
                  iterations: int = 10
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Refine ``(x, y, yaw, pitch, roll, dz)`` from the planar pose ``initial``.

    Args:
        initial: ``(3,)`` planar camera pose to start from (pitch, roll, dz start at 0).
        view_poses: ``(V, 3)`` the model views' planar camera poses.
        view: ``(n,)`` the view of each correspondence.
        rays_model: ``(n, 3)`` its rays in the model view.
        rays_current: ``(n, 3)`` its rays in the current frame.
        threshold: Huber threshold, radians.
        noise: the measurement noise that scales the prior rows, radians.
        tilt_prior_deg: standard deviation of the frame's pitch and roll, degrees.
        height_prior_m: standard deviation of its height offset, metres.
        iterations: Gauss-Newton steps at most.

    Returns:
        ``(state (6,), residuals (n,), jacobian (n, 6))`` at the solution, or None if a
        step cannot be solved.
    """
    state = np.r_[np.asarray(initial, float)[:3], 0.0, 0.0, 0.0]
    problem = _Problem(view_poses, view, rays_model, rays_current)
    a1 = np.ascontiguousarray(np.stack(problem.a1, axis=1))
    r, jac = np.empty(len(a1)), np.empty((len(a1), 6))
    vx, vy = np.ascontiguousarray(problem.vx), np.ascontiguousarray(problem.vy)
    prior = _prior(noise, tilt_prior_deg, height_prior_m)
    if not refine_tilted_in_place(state, _M, vx, vy, a1, problem.g2, float(threshold), prior,
                                  int(iterations), r, jac):
        return None
    return state, r, jac


def marginal_covariance(jac: np.ndarray, sigma2: float, noise: float,
                        tilt_prior_deg: float, height_prior_m: float) -> np.ndarray | None:
    """Return the ``(3, 3)`` covariance of ``(x, y, yaw)``, the tilt and height marginalised."""
    prior = _prior(noise, tilt_prior_deg, height_prior_m)
    try:
        full = np.linalg.inv(jac.T @ jac + np.diag(prior ** 2 * sigma2 / noise ** 2))
    except np.linalg.LinAlgError:
        return None
    return sigma2 * full[:3, :3]
