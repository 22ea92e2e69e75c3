"""The full relative motion from the essential matrix (thesis 7.4).

Hartley's normalised eight-point algorithm inside the shared MSAC loop of
:mod:`.ransac`, and the textbook decomposition with the cheirality test, for any
camera. Conventions in :mod:`vbn_common.geometry.two_view`.
"""
from __future__ import annotations

import math

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.epipolar import (
    check_rays,
    check_translation,
    finish_motion,
    optical_to_planar,
    rms,
    sampson,
    triangulate_depths,
)
from vbn_common.geometry.motion import RelativeMotion
from vbn_common.geometry.ransac import msac_loop, optimise_locally

__all__ = ['general_essential']


def _hartley(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return Hartley-normalised homogeneous points and the similarity applied.

    Rays all in front (``z > 0``, a pinhole camera) become image points ``(x/z, y/z,
    1)``, translated to their centroid and scaled to a mean distance ``sqrt(2)``;
    other rays (a panorama's) are well conditioned already and stay as they are.
    """
    if np.all(f[:, 2] > 1e-6):
        p = f[:, :2] / f[:, 2:3]
        centre = p.mean(axis=0)
        scale = math.sqrt(2.0) / max(float(np.mean(np.linalg.norm(p - centre, axis=1))),
                                     1e-12)
        N = np.array([[scale, 0.0, -scale * centre[0]], [0.0, scale, -scale * centre[1]],
                      [0.0, 0.0, 1.0]])
        return np.concatenate([p, np.ones((len(p), 1))], axis=1) @ N.T, N
    return f, np.eye(3)


def _eight_point(f1: np.ndarray, f2: np.ndarray) -> np.ndarray:
    """Normalised eight-point: ``E`` with ``f2^T E f1 = 0``, singular values (1, 1, 0)."""
    p1, N1 = _hartley(f1)
    p2, N2 = _hartley(f2)
    A = np.einsum('ni,nj->nij', p2, p1).reshape(len(p1), 9)
    _, _, vt = np.linalg.svd(A)
    E = N2.T @ vt[-1].reshape(3, 3) @ N1
    return _project_essential(E)


def _project_essential(E: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(E)
    return U @ np.diag([1.0, 1.0, 0.0]) @ Vt


def _decompose_essential(E: np.ndarray, f1: np.ndarray,
                         f2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the ``(R, T)`` of the four decompositions with the most points in front."""
    U, _, Vt = np.linalg.svd(E)
    if np.linalg.det(U) < 0:
        U = -U
    if np.linalg.det(Vt) < 0:
        Vt = -Vt
    W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    best, best_count = None, -1
    for R in (U @ W @ Vt, U @ W.T @ Vt):
        for T in (U[:, 2], -U[:, 2]):
            l1, l2 = triangulate_depths(R, T, f1, f2)
            count = int(np.sum((l1 > 0) & (l2 > 0)))
            if count > best_count:
                best, best_count = (R, T), count
    return best


def general_essential(rays_model: np.ndarray, rays_current: np.ndarray, *,
                      threshold: float = 1.5 / 320.0, max_iterations: int = 1000,
                      confidence: float = 0.999, noise_floor: float = 1e-4,
                      min_parallax: float = 8e-4, min_parallax_ratio: float = 2.5,
                      rng: np.random.Generator | int | None = None) -> RelativeMotion:
    """Estimate the full relative motion from the essential matrix (thesis 7.4).

    Hartley's normalised eight-point algorithm (pinhole rays become image points,
    centred and scaled; a panorama's unit rays are used as they are) inside RANSAC
    on minimal samples of eight (batched SVDs), scored by Sampson angular errors;
    the inliers give the final least-squares ``E``, projected to singular values
    ``(1, 1, 0)`` and decomposed into the rotation and translation with the most
    points in front of both cameras (cheirality). The motion is not assumed planar:
    ``direction`` is ``(3,)`` (``z`` up) and ``rotation`` the full rotation;
    ``theta`` is the yaw of the current camera's forward axis in the model camera's
    planar frame.

    Args:
        rays_model: ``(n, 3)`` unit rays of the model view (optical frame), ``n >= 8``.
        rays_current: ``(n, 3)`` unit rays of the current view.
        threshold: inlier threshold on the Sampson error, radians.
        max_iterations: RANSAC hypotheses at most.
        confidence: RANSAC confidence.
        noise_floor: smallest noise for the covariance, radians.
        min_parallax: smallest median parallax after rotation, radians.
        min_parallax_ratio: the parallax must also exceed this many times the
            inliers' RMS error (see :class:`TwoViewConfig`).
        rng: random generator or seed.

    Returns:
        The motion.

    Raises:
        VbnCommonError: bad input, fewer than 8 correspondences or inliers, or
            views at the same place.
    """
    method = 'general_essential'
    f1, f2 = check_rays(rays_model, rays_current, 8, method)
    n = len(f1)
    p1, N1 = _hartley(f1)
    p2, N2 = _hartley(f2)
    A = np.einsum('ni,nj->nij', p2, p1).reshape(n, 9)

    def hypotheses(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        _, _, vt = np.linalg.svd(A[samples])                           # (count, 9, 9)
        Es = N2.T @ vt[:, -1, :].reshape(-1, 3, 3) @ N1
        U, _, Vt = np.linalg.svd(Es)
        Es = U @ (np.array([1.0, 1.0, 0.0])[:, None] * Vt)             # singular (1, 1, 0)
        return Es, sampson(Es, f1, f2)

    best = msac_loop(n, 8, hypotheses, threshold, max_iterations=max_iterations,
                     confidence=confidence, rng=np.random.default_rng(rng),
                     residuals=lambda E: sampson(E, f1, f2),
                     polish=lambda E, score: optimise_locally(E, score, f1, f2, threshold,
                                                              _eight_point, 8))
    E, inliers = best.model, best.inliers
    if inliers.sum() < 8:
        raise VbnCommonError(f'{method}: no consensus: {int(inliers.sum())} inliers '
                             f'of {n} correspondences (needs 8)')
    R, T = _decompose_essential(E, f1[inliers], f2[inliers])
    residual = rms(sampson(E, f1[inliers], f2[inliers]))
    check_translation(f1[inliers], f2[inliers], min_parallax, method, residual,
                      min_parallax_ratio)
    theta, centre, planar_rotation = optical_to_planar(R, T)
    direction = centre / np.linalg.norm(centre)
    phi = float(math.atan2(direction[1], direction[0]))
    return finish_motion(theta, phi, f1, f2, inliers, method, noise_floor,
                         rotation=planar_rotation, direction=direction)


