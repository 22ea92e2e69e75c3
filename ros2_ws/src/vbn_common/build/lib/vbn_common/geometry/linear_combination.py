"""Localization by a linear combination of two model views (thesis 7.3, Basri and Rivlin).

Under weak perspective the current view's image coordinates are linear combinations of
the model views'; the coefficients (fitted inside the shared MSAC loop of
:mod:`.ransac`) give the current rotation and, with the known baseline between the
model views, the position. Pinhole cameras only. Conventions in
:mod:`vbn_common.geometry.two_view`.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.epipolar import (
    check_rays,
    finish_motion,
    optical_to_planar,
    planar_to_optical,
)
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION, wrap_angle
from vbn_common.geometry.motion import RelativeMotion
from vbn_common.geometry.ransac import msac_loop

__all__ = ['linear_combination_of_views']

_M = BASE_TO_CAMERA_ROTATION  # p_base = _M @ p_optical


def _centring_pan(f: np.ndarray) -> np.ndarray:
    """Return the rotation about the optical ``y`` axis that puts the rays' mean at ``x = 0``."""
    mean = f.mean(axis=0)
    alpha = -math.atan2(mean[0], mean[2])
    c, s = math.cos(alpha), math.sin(alpha)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass(frozen=True)
class _LcvFrame:
    pans: tuple[np.ndarray, np.ndarray, np.ndarray]   # rotations applied to views a, b, c
    rotation_ab: np.ndarray                            # optical a -> b between panned views
    m: tuple[np.ndarray, np.ndarray, np.ndarray]       # (n, 2) normalised image points
    design: np.ndarray                                 # (n, 4) columns x1, y1, x2, 1


def _lcv_frame(rays: tuple[np.ndarray, np.ndarray, np.ndarray], mask: np.ndarray,
               rotation_ab: np.ndarray, min_view_angle: float, method: str) -> _LcvFrame:
    """Pan the three views to centre the masked points; image points and the basis."""
    pans = tuple(_centring_pan(f[mask]) for f in rays)
    panned = [f @ V.T for f, V in zip(rays, pans)]
    if any(np.any(f[mask, 2] <= 0) for f in panned):
        raise VbnCommonError(f'{method}: the points span more than 180 degrees')
    R_b = pans[1] @ rotation_ab @ pans[0].T
    turn = math.asin(min(abs(R_b[0, 2]), 1.0))
    if turn < min_view_angle:
        raise VbnCommonError(
            f'{method}: the model views see the points from directions only '
            f'{math.degrees(turn):.2f} deg apart (< {math.degrees(min_view_angle):.1f} '
            f'deg): x_b is nearly a multiple of x_a, the depth is not observable')
    with np.errstate(divide='ignore', invalid='ignore'):
        # Points behind a panned view (outliers only) get far-away coordinates.
        m = tuple(np.where(f[:, 2:3] > 0, f[:, :2] / f[:, 2:3], 1e6) for f in panned)
    design = np.column_stack([m[0][:, 0], m[0][:, 1], m[1][:, 0], np.ones(len(m[0]))])
    return _LcvFrame(pans=pans, rotation_ab=R_b, m=m, design=design)


def _lcv_fit(design: np.ndarray, target: np.ndarray) -> np.ndarray:
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    return coef


def linear_combination_of_views(rays_model_a: np.ndarray, rays_model_b: np.ndarray,
                                rays_current: np.ndarray, pose_b_in_a: np.ndarray, *,
                                threshold: float = 3.0 / 320.0, max_iterations: int = 500,
                                confidence: float = 0.999, noise_floor: float = 1e-4,
                                min_view_angle: float = math.radians(5.0),
                                rng: np.random.Generator | int | None = None,
                                ) -> tuple[RelativeMotion, RelativeMotion]:
    """Estimate the current view's motion by a linear combination of two model views (7.3).

    Basri and Rivlin's scheme, as the thesis gives it: under weak perspective the
    current view's image coordinates are linear combinations
    ``x' = a1 x1 + a2 y1 + a3 x2 + a4``, ``y' = b1 x1 + b2 y1 + b3 x2 + b4`` of the
    model views' (``x1, y1`` of view a, ``x2`` of view b). The coefficients are fitted
    by least squares inside RANSAC on minimal samples of four (outliers); with the
    known rotation ``R`` between the model views and their scale ratio ``s``, the rows
    ``s_n u1 = (a1 + a3 s r11, a2 + a3 s r12, a3 s r13)`` and ``s_n u2`` (same with the
    ``b``) give the scale ``s_n`` (eqs. 7.7, 7.8, averaged) and the current rotation
    ``U`` (its third row the cross product, then projected on the rotations).

    Departures, all forced by what the text leaves open: ``s`` (the ratio of the
    model views' mean depths) is read from the ``y`` coordinates, which under planar
    motion scale by ``s`` alone (``y2 = s y1``); the translation comes from the image
    centroids, which weak perspective maps to the scene centroid: at mean depth
    ``Z_a = 1`` the centroid is ``(m_a, 1)`` in view a, ``(m_b, 1) / s`` in view b and
    ``(m_n, 1) / s_n`` in the current view, so the camera centres follow up to one
    scale, which the known baseline between the model views fixes (the thesis's
    ``t_nz`` formula is this relation between depth and scale). The approximation
    is honest only when the scene's depth range is small against its distance; near
    walls give errors of the order of (depth range / distance) times the baseline,
    which no amount of data removes (see ``docs/localization.md``). Weak perspective
    also needs the points near the optical axis, so each view is first panned
    virtually (its rays rotated about the vertical, a known rotation undone at the
    end) to centre its points. The two centred model views must then look at the
    points from directions at least ``min_view_angle`` apart (``r13 != 0``):
    otherwise ``x2`` is a multiple of ``x1`` and the basis is degenerate.

    Args:
        rays_model_a: ``(n, 3)`` unit rays of model view a (pinhole, optical frame).
        rays_model_b: ``(n, 3)`` unit rays of model view b.
        rays_current: ``(n, 3)`` unit rays of the current view.
        pose_b_in_a: ``(3,)`` planar pose ``(x, y, yaw)`` of camera b in camera a's
            planar frame, metres and radians (from the database's poses:
            ``compose_poses(invert_pose(pose_a), pose_b)``).
        threshold: inlier threshold on the fit's residual, normalised image units.
        max_iterations: RANSAC samples at most.
        confidence: RANSAC confidence.
        noise_floor: smallest noise for the covariance, radians.
        min_view_angle: smallest angle between the centred model views' axes.
        rng: random generator or seed.

    Returns:
        ``(motion_a, motion_b)``: the current view relative to model view a and to
        model view b (module conventions; the same metric position seen from both).

    Raises:
        VbnCommonError: bad input, rays behind a pinhole camera, fewer than 4
            correspondences or inliers, model views that see the points from (nearly)
            one direction, or a degenerate fit.
    """
    method = 'linear_combination'
    fa, fb = check_rays(rays_model_a, rays_model_b, 4, method)
    _, fc = check_rays(rays_model_a, rays_current, 4, method)
    if np.any(fa[:, 2] <= 0) or np.any(fb[:, 2] <= 0) or np.any(fc[:, 2] <= 0):
        raise VbnCommonError(f'{method}: needs pinhole rays in front of every camera '
                             f'(optical z > 0)')
    pose_b = np.asarray(pose_b_in_a, dtype=float).reshape(-1)
    if pose_b.shape != (3,) or not np.all(np.isfinite(pose_b)):
        raise VbnCommonError(f'{method}: pose_b_in_a must be a finite (x, y, yaw), '
                             f'got {pose_b_in_a!r}')
    yaw_ab = float(wrap_angle(pose_b[2]))
    baseline = float(np.hypot(pose_b[0], pose_b[1]))
    if baseline <= 0:
        raise VbnCommonError(f'{method}: the model views are at the same place')
    n = len(fa)
    # Pan each view virtually (a known rotation about the vertical) to centre its
    # points: weak perspective holds near the optical axis, not 20 degrees off it.
    # The pans follow the inliers once they are known.
    rays = (fa, fb, fc)
    R_ab, _ = planar_to_optical(yaw_ab, 0.0)                 # optical rotation a -> b
    frame = _lcv_frame(rays, np.ones(n, dtype=bool), R_ab, min_view_angle, method)
    mc, design = frame.m[2], frame.design

    def hypotheses(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        D = design[samples]                                                 # (m, 4, 4)
        ok = np.abs(np.linalg.det(D)) > 1e-12                               # not degenerate
        coef = np.linalg.solve(D[ok], mc[samples[ok]])                       # (m', 4, 2)
        return coef, np.linalg.norm(np.einsum('nk,mkc->mnc', design, coef) - mc, axis=2)

    inliers = np.ones(n, dtype=bool)
    if n > 4:
        best = msac_loop(n, 4, hypotheses, threshold, max_iterations=max_iterations,
                         confidence=confidence, rng=np.random.default_rng(rng))
        if best.model is not None:
            inliers = best.inliers
    for _ in range(3):
        if inliers.sum() < 4:
            raise VbnCommonError(f'{method}: no consensus: {int(inliers.sum())} '
                                 f'inliers of {n} correspondences (needs 4)')
        frame = _lcv_frame(rays, inliers, R_ab, min_view_angle, method)
        coef = _lcv_fit(frame.design[inliers], frame.m[2][inliers])          # (4, 2)
        inliers = np.linalg.norm(frame.design @ coef - frame.m[2], axis=1) < threshold
    if inliers.sum() < 4:
        raise VbnCommonError(f'{method}: no consensus: {int(inliers.sum())} inliers '
                             f'of {n} correspondences (needs 4)')
    Va, Vb, Vc = frame.pans
    R_b = frame.rotation_ab
    ma, mb, mc = frame.m
    a, b = coef[:, 0], coef[:, 1]
    ya, yb = ma[inliers, 1] - ma[inliers, 1].mean(), mb[inliers, 1] - mb[inliers, 1].mean()
    s = float(ya @ yb / (ya @ ya)) if ya @ ya > 0 else math.nan
    if not (math.isfinite(s) and s > 0):
        raise VbnCommonError(f'{method}: the model views give no scale (the points '
                             f'span no height), s = {s}')
    r1 = R_b[0]
    row1 = np.array([a[0] + a[2] * s * r1[0], a[1] + a[2] * s * r1[1], a[2] * s * r1[2]])
    row2 = np.array([b[0] + b[2] * s * r1[0], b[1] + b[2] * s * r1[1], b[2] * s * r1[2]])
    s_n = math.sqrt(0.5 * (row1 @ row1 + row2 @ row2))          # eqs. 7.7 and 7.8
    if not s_n > 0:
        raise VbnCommonError(f'{method}: degenerate combination coefficients')
    u = np.stack([row1, row2, np.cross(row1, row2) / s_n]) / s_n
    uu, _, vt = np.linalg.svd(u)
    U = uu @ np.diag([1.0, 1.0, np.linalg.det(uu @ vt)]) @ vt
    centroid = (np.append(ma[inliers].mean(axis=0), 1.0),
                np.append(mb[inliers].mean(axis=0), 1.0) / s,
                np.append(mc[inliers].mean(axis=0), 1.0) / s_n)
    centre_b = Va.T @ (centroid[0] - R_b.T @ centroid[1])      # view a's optical frame,
    centre_c = Va.T @ (centroid[0] - U.T @ centroid[2])        # mean depth Z_a = 1
    U = Vc.T @ U @ Va                                          # undo the pans
    planar_b = (_M @ centre_b)[:2]
    scale = float(planar_b @ pose_b[:2] / (planar_b @ planar_b))
    position = scale * (_M @ centre_c)[:2]                       # metres, in view a
    theta_a, _, _ = optical_to_planar(U, np.zeros(3))
    if np.linalg.norm(position) <= 0 or not np.all(np.isfinite(position)):
        raise VbnCommonError(f'{method}: the current view is at model view a')
    phi_a = float(math.atan2(position[1], position[0]))
    # The same position seen from view b: rotate into b's planar frame.
    cb, sb = math.cos(yaw_ab), math.sin(yaw_ab)
    rel = position - pose_b[:2]
    in_b = np.array([cb * rel[0] + sb * rel[1], -sb * rel[0] + cb * rel[1]])
    theta_b = float(wrap_angle(theta_a - yaw_ab))
    phi_b = float(math.atan2(in_b[1], in_b[0]))
    motion_a = finish_motion(theta_a, phi_a, fa, fc, inliers, method, noise_floor)
    motion_b = finish_motion(theta_b, phi_b, fb, fc, inliers, method, noise_floor)
    return motion_a, motion_b


