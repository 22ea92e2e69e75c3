"""Planar motion between two panoramas in closed form (thesis 7.5.2, "Computing T and theta").

Each pair of correspondences gives a quadratic in ``r`` (eq. 7.15) and two candidate
rotations (eq. 7.16); the candidates vote, the best is scored by truncated Sampson
errors and refined by the thesis's rank-one criterion. Conventions in
:mod:`vbn_common.geometry.two_view`.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.epipolar import (
    check_rays,
    check_translation,
    finish_motion,
    planar_epipolar_residuals,
    planar_sampson,
    refine_planar,
    rms,
)
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION
from vbn_common.geometry.motion import RelativeMotion

__all__ = ['panoramic_planar_motion']

_M = BASE_TO_CAMERA_ROTATION  # p_base = _M @ p_optical


def _panoramic_vectors(f_model: np.ndarray,
                       f_current: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return complex ``v``, ``w`` and the sign of the height of each point.

    ``v = tan(g2) (cos a1, sin a1)``, ``w = -tan(g1) (cos a2, sin a2)`` in the planar
    frames (azimuth ``a`` counter-clockwise, elevation ``g``): the thesis's ``v, w``
    (``cot`` form) times ``tan(g1) tan(g2)``, which leaves eq. 7.13 to 7.16 unchanged
    (each correspondence's pair is scaled by one number) and stays finite at the
    horizon. Then ``v + R_theta w = T z / (D1 D2)`` with ``z`` the point's height above
    the camera and ``D`` its horizontal distances.
    """
    b1, b2 = f_model @ _M.T, f_current @ _M.T       # planar (base_link) axes
    rho1, rho2 = np.hypot(b1[:, 0], b1[:, 1]), np.hypot(b2[:, 0], b2[:, 1])
    tan1, tan2 = b1[:, 2] / rho1, b2[:, 2] / rho2
    u1 = (b1[:, 0] + 1j * b1[:, 1]) / rho1
    u2 = (b2[:, 0] + 1j * b2[:, 1]) / rho2
    return tan2 * u1, -tan1 * u2, np.sign(tan1)


def _pair_rotations(v: np.ndarray, w: np.ndarray, j: np.ndarray,
                    k: np.ndarray) -> np.ndarray:
    """Return the two unit complex rotations of each pair ``(j, k)`` (eq. 7.15, 7.16)."""
    vj, vk, wj, wk = v[j], v[k], w[j], w[k]
    a = np.abs(vk) ** 2 - np.abs(wk) ** 2
    b = 2.0 * ((wk * wj.conj()).real - (vj * vk.conj()).real)
    c = np.abs(vj) ** 2 - np.abs(wj) ** 2
    disc = np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))   # < 0 only through noise
    scale = np.maximum(np.maximum(np.abs(a), np.abs(b)), np.abs(c))
    linear = np.abs(a) <= 1e-12 * scale
    with np.errstate(divide='ignore', invalid='ignore'):
        # Stable roots: q = -(b + sign(b) disc) / 2, r = q / a and c / q.
        q = -0.5 * (b + np.where(b >= 0, 1.0, -1.0) * disc)
        r1 = np.where(linear, -c / b, q / a)
        r2 = np.where(linear, np.nan, c / q)
    roots = np.stack([r1, r2], axis=1)                               # (m, 2)
    num = vj[:, None] - roots * vk[:, None]
    den = roots * wk[:, None] - wj[:, None]
    with np.errstate(divide='ignore', invalid='ignore'):
        rot = num / den
        rot = rot / np.abs(rot)       # |rot| = 1 up to noise (eq. 7.15)
    return rot.reshape(-1)


def _histogram_modes(thetas: np.ndarray, bins: int = 360, modes: int = 3,
                     half_width: int = 2, limit: int = 200) -> np.ndarray:
    """Return indices of the candidate angles near the histogram's highest modes.

    Half of the candidates are wrong roots and more come from outlier pairs, spread
    over the circle; the right ones pile up at ``theta``. Voting in one-degree bins
    (circularly smoothed over ``2 half_width + 1`` bins) keeps the candidates within
    ``half_width`` bins of the ``modes`` best bins, at most ``limit`` of them (evenly
    spaced), for the exact scoring.
    """
    index = np.floor((thetas + math.pi) / (2 * math.pi) * bins).astype(int) % bins
    votes = np.bincount(index, minlength=bins).astype(float)
    window = 2 * half_width + 1
    smooth = np.convolve(np.concatenate([votes[-half_width:], votes, votes[:half_width]]),
                         np.ones(window), mode='valid')
    chosen = np.zeros(bins, dtype=bool)
    for _ in range(modes):
        top = int(np.argmax(smooth))
        if smooth[top] <= 0:
            break
        near = np.arange(top - 2 * half_width, top + 2 * half_width + 1) % bins
        chosen[near[half_width:-half_width]] = True
        smooth[near] = 0.0
    keep = np.flatnonzero(chosen[index])
    if len(keep) > limit:
        keep = keep[np.linspace(0, len(keep) - 1, limit).astype(int)]
    return keep


def _principal_direction(t: np.ndarray, sign: np.ndarray) -> tuple[np.ndarray, float]:
    """Return the principal direction of complex vectors (sign by ``sign``) and the residual.

    The direction is the leading eigenvector of the 2 x 2 scatter of the vectors,
    oriented so that the signed vectors point along it; the residual is the smallest
    eigenvalue (zero when all are parallel).
    """
    xy = np.stack([t.real, t.imag], axis=1)
    scatter = xy.T @ xy
    values, vectors = np.linalg.eigh(scatter)
    d = vectors[:, 1]
    if np.sum(sign * (xy @ d)) < 0:
        d = -d
    return d, float(values[0])


def panoramic_planar_motion(rays_model: np.ndarray, rays_current: np.ndarray, *,
                            threshold: float = 1.5 / 163.0,
                            min_elevation: float = math.radians(2.0),
                            max_pairs: int = 1500, refine: bool = True,
                            noise_floor: float = 1e-4, min_parallax: float = 1.5e-3,
                            min_parallax_ratio: float = 2.5,
                            rng: np.random.Generator | int | None = None) -> RelativeMotion:
    """Estimate planar motion between two panoramas in closed form (thesis 7.5.2).

    Every pair ``(j, k)`` of usable correspondences gives the quadratic of eq. 7.15 in
    ``r`` and, from its two roots, two candidate rotations (eq. 7.16). The robust
    choice of ``theta`` is a consensus over these candidates (the thesis's
    ``psi_tau``, the largest set of correspondences agreeing on one direction): the
    candidates vote in one-degree bins, and those near the three highest modes (at
    most 200), each with the translation its own pair gives, are scored on all
    correspondences by a truncated sum of squared Sampson errors (MSAC), in one
    vectorised pass. The best candidate's inliers then refine ``theta`` by
    minimising the smallest eigenvalue of the scatter of ``v + R_theta w`` (the
    thesis's rank-one criterion), and ``T`` is the principal direction of those
    vectors, its sign fixed by the heights' signs (a point above the camera gives a
    vector along ``T``, one below it a vector against ``T``). With ``refine`` a few
    Gauss-Newton steps on the inliers' Sampson errors polish ``(theta, phi)``.

    Departures from the text: the thesis's ``v = cot(g1) (cos a1, sin a1)``,
    ``w = -cot(g2) (cos a2, sin a2)`` are multiplied by ``tan(g1) tan(g2)`` per
    correspondence, which leaves eqs. 7.13 to 7.16 unchanged and stays finite at
    elevation 0 (only ``y0`` matters, as "Advantages of Using Panoramic Cameras"
    says); the robust step is a consensus rather than EM on a mixture (EM needs a
    starting point, and the right candidates pile up in one bin: 2,450 candidates on
    50 points, a quarter of them right with 30 % outliers).
    Correspondences below ``min_elevation`` in either view are not used (eq. 7.20),
    nor are those whose two elevations have opposite signs (no point is above one
    camera and below the other when both are at the same height).

    Complexity ``O(p + c n)`` for ``p = min(n (n - 1) / 2, max_pairs)`` pairs and
    ``c <= 200`` scored candidates: about 3 ms of CPU on 50 points.

    Args:
        rays_model: ``(n, 3)`` unit rays of the model panorama (optical frame).
        rays_current: ``(n, 3)`` unit rays of the current panorama.
        threshold: inlier threshold on the Sampson error, radians.
        min_elevation: smallest usable absolute elevation, radians.
        max_pairs: at most this many pairs propose candidates (random when more).
        refine: polish by Gauss-Newton.
        noise_floor: smallest noise for the covariance, radians.
        min_parallax: smallest median parallax after rotation, radians.
        min_parallax_ratio: the parallax must also exceed this many times the
            inliers' RMS error (see :class:`TwoViewConfig`).
        rng: random generator or seed (used only with more than ``max_pairs`` pairs).

    Returns:
        The motion; ``inliers`` is ``False`` for unusable correspondences too.

    Raises:
        VbnCommonError: bad input, fewer than 3 usable correspondences (all at
            the horizon, say), no consensus, or views at the same place.

    Example:
        >>> motion = panoramic_planar_motion(rays_a, rays_b)  # doctest: +SKIP
        >>> motion.theta, motion.direction  # doctest: +SKIP
    """
    method = 'panoramic_planar'
    f1, f2 = check_rays(rays_model, rays_current, 3, method)
    n = len(f1)
    v, w, height_sign = _panoramic_vectors(f1, f2)
    b1, b2 = f1 @ _M.T, f2 @ _M.T
    elevation1 = np.arcsin(np.clip(b1[:, 2], -1, 1))
    elevation2 = np.arcsin(np.clip(b2[:, 2], -1, 1))
    usable = ((np.abs(elevation1) >= min_elevation) & (np.abs(elevation2) >= min_elevation)
              & (np.sign(elevation1) == np.sign(elevation2)))
    idx = np.flatnonzero(usable)
    if len(idx) < 3:
        raise VbnCommonError(
            f'{method}: needs at least 3 correspondences off the horizon (|elevation| >= '
            f'{math.degrees(min_elevation):.2f} deg in both views, same side), got '
            f'{len(idx)} of {n}')
    jj, kk = np.triu_indices(len(idx), 1)
    if len(jj) > max_pairs:
        rng = np.random.default_rng(rng)
        pick = rng.choice(len(jj), size=max_pairs, replace=False)
        jj, kk = jj[pick], kk[pick]
    j, k = idx[jj], idx[kk]
    rotations = _pair_rotations(v, w, j, k)                          # (2p,)
    pair_j = np.repeat(j, 2)
    t_pair = v[pair_j] + rotations * w[pair_j]
    good = np.isfinite(rotations) & (np.abs(t_pair) > 0)
    rotations, t_pair, pair_j = rotations[good], t_pair[good], pair_j[good]
    if not len(rotations):
        # All quadratics vanish: typically no translation at all; say so if it is that.
        check_translation(f1[idx], f2[idx], min_parallax, method)
        raise VbnCommonError(f'{method}: no pair of correspondences fixes the '
                             f'rotation (eq. 7.19 holds for all)')
    thetas = np.angle(rotations)
    phis = np.angle(t_pair * height_sign[pair_j])
    keep = _histogram_modes(thetas)
    thetas, phis = thetas[keep], phis[keep]
    # Score the candidates near the modes on every usable correspondence (MSAC).
    scores = np.empty(len(thetas))
    fu1, fu2 = f1[idx], f2[idx]
    gu1, gu2 = fu1 @ _M.T, fu2 @ _M.T
    for start in range(0, len(thetas), 512):
        sl = slice(start, start + 512)
        err = planar_sampson(gu1, gu2, thetas[sl, None], phis[sl, None])
        scores[sl] = np.sum(np.minimum(err * err, threshold * threshold), axis=1)
    best = int(np.argmin(scores))
    theta = float(thetas[best])
    phi = float(phis[best])
    inliers = np.zeros(n, dtype=bool)
    for _ in range(2):
        inliers[:] = False
        inliers[idx] = np.abs(planar_epipolar_residuals(fu1, fu2, theta, phi)) < threshold
        if inliers.sum() < 3:
            raise VbnCommonError(f'{method}: no consensus: {int(inliers.sum())} '
                                 f'inliers of {len(idx)} usable correspondences')
        vi, wi, si = v[inliers], w[inliers], height_sign[inliers]

        # The smallest eigenvalue of the scatter of t = v + e^(i eta) w is
        # (sum |t|^2 - |sum t^2|) / 2; both sums are trigonometric in eta, O(1) each.
        s0 = float(np.sum(np.abs(vi) ** 2 + np.abs(wi) ** 2))
        s1 = complex(np.sum(wi * vi.conj()))
        c0, c1, c2 = complex(np.sum(vi * vi)), complex(np.sum(vi * wi)), complex(np.sum(wi * wi))

        def spread(eta: float, s0: float = s0, s1: complex = s1, c0: complex = c0,
                   c1: complex = c1, c2: complex = c2) -> float:
            rot = complex(math.cos(eta), math.sin(eta))
            return 0.5 * (s0 + 2.0 * (rot * s1).real - abs(c0 + 2.0 * rot * c1 + rot * rot * c2))

        window = 4.0 * threshold + 1e-3
        res = minimize_scalar(spread, bounds=(theta - window, theta + window),
                              method='bounded', options={'xatol': 1e-10})
        theta = float(res.x)
        d, _ = _principal_direction(vi + np.exp(1j * theta) * wi, si)
        phi = float(math.atan2(d[1], d[0]))
        if refine:
            theta, phi = refine_planar(theta, phi, f1[inliers], f2[inliers])
    residual = rms(planar_epipolar_residuals(f1[inliers], f2[inliers], theta, phi))
    check_translation(f1[inliers], f2[inliers], min_parallax, method, residual,
                      min_parallax_ratio)
    return finish_motion(theta, phi, f1, f2, inliers, method, noise_floor)


