"""Planar motion from the planar essential matrix (thesis 7.5.1, pinhole cameras).

Under planar motion the essential matrix has four non-zero entries, linear in at least
four correspondences; rotation and translation are read from it without the usual
four-fold ambiguity. Robust by the shared MSAC loop of :mod:`.ransac`. Conventions in
:mod:`vbn_common.geometry.two_view`.
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
    planar_epipolar_residuals,
    refine_planar,
    rms,
    sampson,
    triangulate_depths,
)
from vbn_common.geometry.motion import RelativeMotion
from vbn_common.geometry.ransac import msac_loop, optimise_locally

__all__ = ['pinhole_planar_essential']


def _planar_rows(f1: np.ndarray, f2: np.ndarray) -> np.ndarray:
    """Rows ``c = (p'x py, p'y px, p'y pz, p'z py)`` of the 4-unknown system (7.5.1)."""
    return np.stack([f2[..., 0] * f1[..., 1], f2[..., 1] * f1[..., 0],
                     f2[..., 1] * f1[..., 2], f2[..., 2] * f1[..., 1]], axis=-1)


def _planar_e_matrix(e: np.ndarray) -> np.ndarray:
    """``(..., 4)`` ``(e12, e21, e23, e32)`` -> ``(..., 3, 3)`` essential matrices."""
    E = np.zeros(e.shape[:-1] + (3, 3))
    E[..., 0, 1], E[..., 1, 0], E[..., 1, 2], E[..., 2, 1] = (e[..., 0], e[..., 1],
                                                              e[..., 2], e[..., 3])
    return E


def _planar_fit(f1: np.ndarray, f2: np.ndarray) -> np.ndarray:
    """Least-squares planar essential matrix: the smallest right singular vector."""
    _, _, vt = np.linalg.svd(_planar_rows(f1, f2))
    return _planar_e_matrix(vt[-1])


def _planar_e_motion(e: np.ndarray, f1: np.ndarray,
                     f2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation of the thesis's 7.5.1, the sign of T by cheirality."""
    e12, e21, e23, e32 = e
    norm = e32 * e32 + e12 * e12
    sin_t = (e32 * e21 - e12 * e23) / norm
    cos_t = -(e32 * e23 + e12 * e21) / norm
    ang = math.atan2(sin_t, cos_t)
    c, s = math.cos(ang), math.sin(ang)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])     # eq. 7.10
    T = np.array([e32, 0.0, -e12]) / math.sqrt(norm)
    best_T, best_count = T, -1
    for cand in (T, -T):
        l1, l2 = triangulate_depths(R, cand, f1, f2)
        count = int(np.sum((l1 > 0) & (l2 > 0)))
        if count > best_count:
            best_T, best_count = cand, count
    return R, best_T


def pinhole_planar_essential(rays_model: np.ndarray, rays_current: np.ndarray, *,
                             threshold: float = 1.5 / 320.0, max_iterations: int = 1000,
                             confidence: float = 0.999, refine: bool = True,
                             noise_floor: float = 1e-4, min_parallax: float = 8e-4,
                             min_parallax_ratio: float = 2.5,
                             rng: np.random.Generator | int | None = None) -> RelativeMotion:
    """Estimate planar motion from the planar essential matrix (thesis 7.5.1).

    Under planar motion ``E = [T]x R_y(theta)`` has four non-zero entries
    (eq. 7.11); each correspondence gives one linear equation ``c^t e = 0`` in
    ``e = (e12, e21, e23, e32)``. RANSAC draws minimal samples of four
    correspondences (null vector of a 4 x 4 system, all samples of a batch solved
    in one batched SVD), scores them by Sampson errors, and the inliers of the best
    give the least-squares ``e`` (smallest right singular vector). ``T = (e32, 0,
    -e12)`` and ``sin``/``cos theta`` follow as in the thesis, unambiguously (the
    twisted pair of the general decomposition is not a planar motion); the sign of
    ``T``, which ``e`` leaves open, is the one that puts the points in front of both
    cameras (cheirality). With ``refine`` a few Gauss-Newton steps on the Sampson
    errors polish ``(theta, phi)``.

    Departure: the equations use unit rays rather than ``(x, y, 1)`` image points
    (each equation scaled by a positive number), so panoramas work as well.

    Args:
        rays_model: ``(n, 3)`` unit rays of the model view (optical frame), ``n >= 4``.
        rays_current: ``(n, 3)`` unit rays of the current view.
        threshold: inlier threshold on the Sampson error, radians.
        max_iterations: RANSAC hypotheses at most.
        confidence: RANSAC confidence.
        refine: polish by Gauss-Newton.
        noise_floor: smallest noise for the covariance, radians.
        min_parallax: smallest median parallax after rotation, radians.
        min_parallax_ratio: the parallax must also exceed this many times the
            inliers' RMS error (see :class:`TwoViewConfig`).
        rng: random generator or seed.

    Returns:
        The motion.

    Raises:
        VbnCommonError: bad input, fewer than 4 correspondences, fewer than 4
            inliers, or views at the same place.
    """
    method = 'pinhole_planar'
    f1, f2 = check_rays(rays_model, rays_current, 4, method)
    n = len(f1)
    rows = _planar_rows(f1, f2)                                        # (n, 4)

    def hypotheses(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        _, _, vt = np.linalg.svd(rows[samples])                        # null vectors
        models = _planar_e_matrix(vt[:, -1, :])                        # (count, 3, 3)
        return models, sampson(models, f1, f2)                         # (count, n)

    best = msac_loop(n, 4, hypotheses, threshold, max_iterations=max_iterations,
                     confidence=confidence, rng=np.random.default_rng(rng),
                     residuals=lambda E: sampson(E, f1, f2),
                     polish=lambda E, score: optimise_locally(E, score, f1, f2, threshold,
                                                              _planar_fit, 4))
    best_E, inliers = best.model, best.inliers
    e = np.array([best_E[0, 1], best_E[1, 0], best_E[1, 2], best_E[2, 1]])
    if inliers.sum() < 4:
        raise VbnCommonError(f'{method}: no consensus: {int(inliers.sum())} inliers '
                             f'of {n} correspondences (needs 4)')
    R, T = _planar_e_motion(e, f1[inliers], f2[inliers])
    theta, centre, _ = optical_to_planar(R, T)
    phi = float(math.atan2(centre[1], centre[0]))
    if refine:
        theta, phi = refine_planar(theta, phi, f1[inliers], f2[inliers])
    residual = rms(planar_epipolar_residuals(f1[inliers], f2[inliers], theta, phi))
    check_translation(f1[inliers], f2[inliers], min_parallax, method, residual,
                      min_parallax_ratio)
    return finish_motion(theta, phi, f1, f2, inliers, method, noise_floor)


