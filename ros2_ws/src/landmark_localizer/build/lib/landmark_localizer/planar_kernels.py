"""Compiled Gauss-Newton of the two-view pose on the model views' epipolar errors (7.4, 7.5).

:func:`~landmark_localizer.pose.refine_pose` polishes the pose ``(x, y, yaw)`` on the
Sampson errors of every model view's correspondences at once, with Huber weights and a
forward-difference Jacobian. Written with numpy each step was a dozen array calls on a
hundred correspondences, most of its time their fixed cost; this kernel loops over them
(numba, compiled once per machine and cached). The errors are those of
:func:`vbn_common.geometry.epipolar.planar_sampson`: a view at ``(xv, yv, yawv)`` sees
the camera turned by ``theta = yaw - yawv`` at the bearing ``phi`` of ``(x - xv, y - yv)``
in its own frame.
"""
from __future__ import annotations

import math

from numba import njit
import numpy as np

from landmark_localizer.angular_kernels import huber_accumulate, solve_in_place, wrap

__all__ = ['planar_residuals', 'refine_planar']

#: Forward-difference steps of ``(x, y, yaw)``: metres, metres, radians.
STEP = (1e-4, 1e-4, 1e-5)
#: Gauss-Newton stops when a step moves the position less than this (a tenth of a
#: millimetre, far below what the pixels resolve) and the heading less than STOP_RAD.
STOP_M = 1e-4
STOP_RAD = 1e-5


@njit(cache=True)
def planar_residuals(pose: np.ndarray, view_poses: np.ndarray, view: np.ndarray,
                     g1: np.ndarray, g2: np.ndarray, out: np.ndarray) -> None:
    """Fill ``out (n,)`` with the signed Sampson errors of every correspondence at ``pose``.

    ``view_poses (m, 3)``: the model views; ``view (n,)``: each correspondence's view;
    ``g1``, ``g2`` ``(n, 3)``: its model and current rays in the planar frame (z up).
    """
    m = view_poses.shape[0]
    cos_t, sin_t = np.empty(m), np.empty(m)
    tx, ty = np.empty(m), np.empty(m)
    for k in range(m):
        c, s = math.cos(view_poses[k, 2]), math.sin(view_poses[k, 2])
        dx, dy = pose[0] - view_poses[k, 0], pose[1] - view_poses[k, 1]
        theta = wrap(pose[2] - view_poses[k, 2])
        phi = math.atan2(-s * dx + c * dy, c * dx + s * dy)
        cos_t[k], sin_t[k] = math.cos(theta), math.sin(theta)
        tx[k], ty[k] = -math.cos(phi - theta), -math.sin(phi - theta)
    for i in range(g1.shape[0]):
        k = view[i]
        c, s, x, y = cos_t[k], sin_t[k], tx[k], ty[k]
        hx = c * g1[i, 0] + s * g1[i, 1]
        hy = c * g1[i, 1] - s * g1[i, 0]
        algebraic = g1[i, 2] * (g2[i, 0] * y - g2[i, 1] * x) + g2[i, 2] * (x * hy - y * hx)
        t_h = x * hx + y * hy
        t_g2 = x * g2[i, 0] + y * g2[i, 1]
        denom2 = 2.0 - t_h * t_h - t_g2 * t_g2 - 2.0 * algebraic * algebraic
        out[i] = algebraic / math.sqrt(max(denom2, 1e-300))


@njit(cache=True)
def _linearise(pose: np.ndarray, view_poses: np.ndarray, view: np.ndarray, g1: np.ndarray,
               g2: np.ndarray, r: np.ndarray, jac: np.ndarray) -> None:
    """Residuals ``r (n,)`` at ``pose`` and their forward differences ``jac (n, 3)``."""
    planar_residuals(pose, view_poses, view, g1, g2, r)
    probe, moved = pose.copy(), np.empty(r.size)
    for k in range(3):
        probe[k] = pose[k] + STEP[k]
        planar_residuals(probe, view_poses, view, g1, g2, moved)
        for i in range(r.size):
            jac[i, k] = (moved[i] - r[i]) / STEP[k]
        probe[k] = pose[k]


@njit(cache=True)
def refine_planar(pose: np.ndarray, view_poses: np.ndarray, view: np.ndarray,
                  g1: np.ndarray, g2: np.ndarray, threshold: float, iterations: int,
                  r: np.ndarray, jac: np.ndarray) -> bool:
    """Huber-weighted Gauss-Newton on ``pose (3,)`` in place; False on a singular step.

    At most ``iterations`` steps (a ridge of 1e-12 on the normal equations), each
    ``threshold`` (radians) the Huber threshold; ``r (n,)`` and ``jac (n, 3)`` are
    filled at the pose found.
    """
    a, b = np.empty((3, 3)), np.empty(3)
    for _ in range(iterations):
        _linearise(pose, view_poses, view, g1, g2, r, jac)
        a[:, :] = 0.0
        b[:] = 0.0
        huber_accumulate(r, jac, threshold, a, b)
        for j in range(3):
            a[j, j] += 1e-12
        if not solve_in_place(a, b, 0.0):
            return False
        for j in range(3):
            pose[j] += b[j]
        pose[2] = wrap(pose[2])
        if max(abs(b[0]), abs(b[1])) < STOP_M and abs(b[2]) < STOP_RAD:
            break
    _linearise(pose, view_poses, view, g1, g2, r, jac)
    return True
