"""Compiled Gauss-Newton of the tilted two-view pose.

:func:`~landmark_localizer.tilt_refinement.refine_tilted` solves ``(x, y, yaw, pitch,
roll, dz)`` on the coplanarity errors of every model view's correspondences, with
priors on the tilt and the height and a forward-difference Jacobian. Written with numpy
each of its up to ten steps evaluated seven stacked states in a dozen array calls, a
millisecond a refinement, and it runs on the frames that already cost the most (a
region change, where the planar pose is not level enough). These kernels loop over the
correspondences instead (numba, compiled once per machine and cached); the arithmetic is
:class:`~landmark_localizer.tilt_refinement._Problem`'s, written out per ray.
"""
from __future__ import annotations

import math

from numba import njit
import numpy as np

from landmark_localizer.angular_kernels import huber_accumulate, solve_in_place, wrap

__all__ = ['refine_tilted_in_place', 'tilted_errors']

#: Forward-difference steps of ``(x, y, yaw, pitch, roll, dz)``: metres and radians.
STEP = (1e-4, 1e-4, 1e-5, 1e-5, 1e-5, 1e-4)
#: A step below these (position and height in metres; angles in radians) is the last.
STOP_M = 1e-4
STOP_RAD = 1e-5


@njit(cache=True)
def _turn(state: np.ndarray, m: np.ndarray, turn: np.ndarray) -> None:
    """``turn (3, 3)``: ``R_z(yaw) M R_x(pitch) R_z(roll) M^T``, rays to world directions."""
    cp, sp = math.cos(state[3]), math.sin(state[3])
    cr, sr = math.cos(state[4]), math.sin(state[4])
    tilt = np.array([[cr, -sr, 0.0], [cp * sr, cp * cr, -sp], [sp * sr, sp * cr, cp]])
    left = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            for k in range(3):
                left[i, j] += m[i, k] * tilt[k, j]
    level = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            for k in range(3):
                level[i, j] += left[i, k] * m[j, k]
    c2, s2 = math.cos(state[2]), math.sin(state[2])
    for j in range(3):
        turn[0, j] = c2 * level[0, j] - s2 * level[1, j]
        turn[1, j] = s2 * level[0, j] + c2 * level[1, j]
        turn[2, j] = level[2, j]


@njit(cache=True)
def tilted_errors(state: np.ndarray, m: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                  a1: np.ndarray, g2: np.ndarray, out: np.ndarray) -> None:
    """Fill ``out (n,)`` with the Sampson angular errors at ``state (6,)``.

    ``m``: the planar-from-optical rotation; ``vx``, ``vy`` ``(n,)``: each
    correspondence's model view position; ``a1 (n, 3)``: its model ray as a world
    direction; ``g2 (n, 3)``: its current ray in the planar frame.
    """
    turn = np.empty((3, 3))
    _turn(state, m, turn)
    for i in range(g2.shape[0]):
        a2x = turn[0, 0] * g2[i, 0] + turn[0, 1] * g2[i, 1] + turn[0, 2] * g2[i, 2]
        a2y = turn[1, 0] * g2[i, 0] + turn[1, 1] * g2[i, 1] + turn[1, 2] * g2[i, 2]
        a2z = turn[2, 0] * g2[i, 0] + turn[2, 1] * g2[i, 1] + turn[2, 2] * g2[i, 2]
        bx, by, bz = state[0] - vx[i], state[1] - vy[i], state[5]
        norm = max(math.sqrt(bx * bx + by * by + bz * bz), 1e-12)
        bx, by, bz = bx / norm, by / norm, bz / norm
        a1x, a1y, a1z = a1[i, 0], a1[i, 1], a1[i, 2]
        e = bx * (a1y * a2z - a1z * a2y) + by * (a1z * a2x - a1x * a2z) + \
            bz * (a1x * a2y - a1y * a2x)
        d1 = bx * a1x + by * a1y + bz * a1z
        d2 = bx * a2x + by * a2y + bz * a2z
        out[i] = e / math.sqrt(max(2.0 - d1 * d1 - d2 * d2, 1e-12))


@njit(cache=True)
def _linearise(state: np.ndarray, m: np.ndarray, vx: np.ndarray, vy: np.ndarray,
               a1: np.ndarray, g2: np.ndarray, r: np.ndarray, jac: np.ndarray) -> None:
    """Errors ``r (n,)`` at ``state`` and their forward differences ``jac (n, 6)``."""
    tilted_errors(state, m, vx, vy, a1, g2, r)
    probe, moved = state.copy(), np.empty(r.size)
    for k in range(6):
        probe[k] = state[k] + STEP[k]
        tilted_errors(probe, m, vx, vy, a1, g2, moved)
        for i in range(r.size):
            jac[i, k] = (moved[i] - r[i]) / STEP[k]
        probe[k] = state[k]


@njit(cache=True)
def refine_tilted_in_place(state: np.ndarray, m: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                           a1: np.ndarray, g2: np.ndarray, threshold: float,
                           prior: np.ndarray, iterations: int, r: np.ndarray,
                           jac: np.ndarray) -> bool:
    """Huber-weighted Gauss-Newton on ``state (6,)`` in place; False on a singular step.

    ``prior (6,)``: each unknown's prior weight around 0 (the rows
    ``prior * state``); a ridge of 1e-12 on the normal equations. ``r (n,)`` and
    ``jac (n, 6)`` are filled at the state found.
    """
    a, b = np.empty((6, 6)), np.empty(6)
    for _ in range(iterations):
        _linearise(state, m, vx, vy, a1, g2, r, jac)
        a[:, :] = 0.0
        for j in range(6):
            b[j] = -prior[j] * prior[j] * state[j]
        huber_accumulate(r, jac, threshold, a, b)
        for j in range(6):
            a[j, j] += prior[j] * prior[j] + 1e-12
        if not solve_in_place(a, b, 0.0):
            return False
        for j in range(6):
            state[j] += b[j]
        state[2] = wrap(state[2])
        if max(abs(b[0]), abs(b[1]), abs(b[5])) < STOP_M and \
                max(abs(b[2]), abs(b[3]), abs(b[4])) < STOP_RAD:
            break
    _linearise(state, m, vx, vy, a1, g2, r, jac)
    return True
