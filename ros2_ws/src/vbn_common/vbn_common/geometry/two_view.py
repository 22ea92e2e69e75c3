"""Relative motion between a model view and the current view (thesis Sections 7.3 to 7.5).

Four solvers of the thesis, each a function of point correspondences that returns a
:class:`RelativeMotion`; :func:`relative_motion` converts pixels with the project's
camera models and picks the solver by the camera's kind (a ``method`` argument
overrides it):

- :func:`panoramic_planar_motion` (7.5.2, "Computing T and theta"): the closed form
  for cylindrical panoramas under planar motion. Each pair of correspondences gives a
  quadratic in ``r`` (eq. 7.15) and two candidate rotations (eq. 7.16).
- :func:`pinhole_planar_essential` (7.5.1): the planar essential matrix, four unknowns
  ``(e12, e21, e23, e32)`` linear in at least four correspondences, rotation and
  translation read from it without the usual four-fold ambiguity.
- :func:`general_essential` (7.4): Hartley's normalised eight-point algorithm inside
  RANSAC and the textbook decomposition with the cheirality test, for any camera.
- :func:`linear_combination_of_views` (7.3): Basri and Rivlin's scheme under weak
  perspective, from two model views and the current one (pinhole only).

Conventions (shared with :mod:`vbn_common.geometry.localize`):

- Inputs are unit rays in the camera's optical frame (``z`` forward, ``x`` right,
  ``y`` down), as :meth:`CameraModel.unproject
  <vbn_common.geometry.camera.CameraModel.unproject>` returns them: the
  *model* view's rays and the *current* view's rays, row ``i`` of both the same
  scene point.
- The result is the current camera's pose in the model camera's *planar* frame
  (REP 103: ``x`` forward, ``y`` left, angles counter-clockwise seen from above):
  ``theta`` is the current camera's yaw minus the model camera's yaw and
  ``direction`` the unit vector from the model camera to the current camera. Two
  views fix the translation only up to its length, so
  ``compose_poses(model_pose, (s * direction[0], s * direction[1], theta))`` is the
  current camera's pose in ``map`` for some unknown ``s > 0``.
- Thresholds and residuals are angles in radians: the Sampson approximation of the
  epipolar error on the unit sphere (about one pixel divided by the focal length in
  pixels: 1 px is 6.1e-3 rad on a 1024-pixel-wide panorama).

The planar methods (and the general one, which ignores that the motion is planar)
work in the optical frame with the epipolar constraint ``p_cur^T E p_model = 0``,
``E = [T]x R``, ``X_cur = R X_model + T``, as the thesis writes them.

Limits: points on one plane (a single wall filling a pinhole view) leave the
essential matrices ambiguous; the general eight-point method needs a longer baseline
than the planar ones for the same accuracy (five unknowns instead of two). Speed:
everything is vectorised numpy on small matrices, where OpenBLAS threads only
contend; run with ``OPENBLAS_NUM_THREADS=1`` (measured 5 to 100 times faster on the
loaded 2-core machine, see ``docs/localization.md``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import logging
import math

import numpy as np
from scipy.optimize import minimize_scalar

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.camera import CameraModel
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION, wrap_angle

__all__ = [
    'METHODS',
    'RelativeMotion',
    'TwoViewConfig',
    'general_essential',
    'linear_combination_of_views',
    'panoramic_planar_motion',
    'pinhole_planar_essential',
    'planar_epipolar_residuals',
    'pointwise_planar_residuals',
    'relative_motion',
]

_LOG = logging.getLogger(__name__)

#: Names of the two-view methods of :func:`relative_motion`.
METHODS = ('panoramic_planar', 'pinhole_planar', 'general_essential')
#: Default method per camera kind (the database's camera model picks the method).
DEFAULT_METHOD = {'panoramic': 'panoramic_planar', 'pinhole': 'pinhole_planar'}

_M = BASE_TO_CAMERA_ROTATION  # p_base = _M @ p_optical
_RANSAC_BATCH = 64


@dataclass(frozen=True)
class RelativeMotion:
    """The motion from a model view to the current view (module conventions).

    Attributes:
        theta: the current camera's yaw relative to the model camera's, radians in
            ``[-pi, pi)``, counter-clockwise seen from above.
        direction: unit vector from the model camera to the current camera in the
            model camera's planar frame (``x`` forward, ``y`` left): ``(2,)`` for the
            planar methods, ``(3,)`` (``z`` up) for :func:`general_essential`.
        inliers: ``(n,)`` bool, the correspondences the estimate kept.
        residual: RMS Sampson angular error of the inliers, radians.
        method: the method's name.
        covariance: ``(2, 2)`` covariance of ``(theta, phi)``, radians squared, where
            ``phi = atan2(direction[1], direction[0])`` is the planar bearing of the
            translation; from the inliers' residuals and the Jacobian of the planar
            epipolar errors.
        rotation: ``(3, 3)`` rotation of the model camera's planar (REP 103) frame
            into the current one's, ``x_current = rotation @ x_model`` for
            directions; a rotation about ``z`` by ``-theta`` except for
            :func:`general_essential`.
    """

    theta: float
    direction: np.ndarray
    inliers: np.ndarray
    residual: float
    method: str
    covariance: np.ndarray = field(default_factory=lambda: np.full((2, 2), np.nan))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    @property
    def phi(self) -> float:
        """Return the planar bearing of the translation, ``atan2(d_y, d_x)``, radians."""
        return float(math.atan2(self.direction[1], self.direction[0]))

    @property
    def planar_direction(self) -> np.ndarray:
        """Return the translation's unit ``(2,)`` direction in the plane."""
        d = np.asarray(self.direction[:2], dtype=float)
        return d / np.linalg.norm(d)


@dataclass(frozen=True)
class TwoViewConfig:
    """Parameters of the two-view solvers (pixels are converted with the camera).

    Attributes:
        threshold_px: inlier threshold on the Sampson error, pixels.
        min_elevation_deg: panoramic method: correspondences with an elevation below
            this in either view are not used (``cot`` of the elevation explodes near
            the horizon, eq. 7.20).
        max_pairs: panoramic method: at most this many correspondence pairs
            (random, with ``rng``) propose rotations; all pairs when there are fewer.
        max_iterations: RANSAC hypotheses at most.
        confidence: RANSAC stops when an all-inlier sample was drawn with this
            probability.
        refine: polish ``(theta, phi)`` of the planar methods by Gauss-Newton on the
            inliers' Sampson errors.
        noise_floor_px: smallest noise assumed for the covariance, pixels (exact
            data would otherwise give a zero covariance).
        min_parallax_px: the median parallax after undoing the rotation must exceed
            this, pixels, and 2.5 times the inliers' RMS epipolar error (the ratio
            measured 1.3 to 2.3 for identical poses with 0.5 px of noise, 1.8 to 3.8
            for 2 cm apart, 2.3 to 8 for 5 cm); otherwise the views are (nearly) at
            the same place and the direction of translation is undetermined.
        min_parallax_ratio: the factor 2.5 above (0 disables this test).
    """

    threshold_px: float = 1.5
    min_elevation_deg: float = 2.0
    max_pairs: int = 1500
    max_iterations: int = 1000
    confidence: float = 0.999
    refine: bool = True
    noise_floor_px: float = 0.1
    min_parallax_px: float = 0.25
    min_parallax_ratio: float = 2.5

    def __post_init__(self) -> None:
        """Reject invalid values with a :class:`VbnCommonError`."""
        for name in ('threshold_px', 'min_parallax_px', 'noise_floor_px'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise VbnCommonError(f'{name} must be a positive number, got {value}')
        if not (math.isfinite(self.min_parallax_ratio) and self.min_parallax_ratio >= 0):
            raise VbnCommonError(f'min_parallax_ratio must be >= 0, got '
                                         f'{self.min_parallax_ratio}')
        if not 0.0 <= self.min_elevation_deg < 90.0:
            raise VbnCommonError(
                f'min_elevation_deg must be in [0, 90), got {self.min_elevation_deg}')
        if self.max_pairs < 1 or self.max_iterations < 1:
            raise VbnCommonError(f'max_pairs and max_iterations must be >= 1, got '
                                         f'{self.max_pairs} and {self.max_iterations}')
        if not 0.0 < self.confidence < 1.0:
            raise VbnCommonError(f'confidence must be in (0, 1), got {self.confidence}')


# -- shared helpers ---------------------------------------------------------------------
def _check_rays(rays_model: np.ndarray, rays_current: np.ndarray, minimum: int,
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


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _skew(t: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])


def _planar_to_optical(theta: float, phi: float) -> tuple[np.ndarray, np.ndarray]:
    """Return optical ``(R, T)``, ``X_cur = R X_model + T``, of a planar motion.

    The current camera sits at ``(cos phi, sin phi)`` in the model camera's planar
    frame, turned by ``theta``.
    """
    rz_t = _rot_z(theta).T
    centre = np.array([math.cos(phi), math.sin(phi), 0.0])
    return _M.T @ rz_t @ _M, -_M.T @ rz_t @ centre


def _optical_to_planar(R: np.ndarray, T: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Return ``(theta, centre, planar_rotation)`` of an optical motion ``X_cur = R X + T``.

    ``centre`` is the current camera's centre in the model camera's planar frame
    (``(3,)``, ``z`` up), ``planar_rotation`` maps model planar directions to current
    ones.
    """
    orientation = _M @ R.T @ _M.T  # current axes in the model's planar frame
    theta = float(math.atan2(orientation[1, 0], orientation[0, 0]))
    return theta, _M @ (-R.T @ T), orientation.T


def _essential(theta: float, phi: float) -> np.ndarray:
    R, T = _planar_to_optical(theta, phi)
    return _skew(T) @ R


def _sampson(E: np.ndarray, f_model: np.ndarray, f_current: np.ndarray) -> np.ndarray:
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
    return _sampson(_essential(theta, phi), np.asarray(rays_model, dtype=float),
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
    return _planar_sampson(np.asarray(rays_model, dtype=float) @ _M.T,
                           np.asarray(rays_current, dtype=float) @ _M.T,
                           np.asarray(theta, dtype=float), np.asarray(phi, dtype=float))


def _planar_sampson(g1: np.ndarray, g2: np.ndarray, theta: np.ndarray, phi: np.ndarray
                    ) -> np.ndarray:
    """Sampson errors of planar motions from rays in the planar frame, broadcasting.

    ``g1``, ``g2``: ``(n, 3)`` unit rays (z up); ``theta``, ``phi`` broadcast against
    ``(n,)``: ``(n,)`` for one motion per correspondence, ``(m, 1)`` for ``m`` motions
    scored on every correspondence (``(m, n)`` errors). In the planar frame
    ``E = [T]x Rz(theta)^T`` with ``T = -(cos psi, sin psi, 0)``, ``psi = phi - theta``,
    and for unit rays ``|E g1|^2 = 1 - (T.h)^2`` (``h = Rz(theta)^T g1``) and
    ``|E^T g2|^2 = 1 - (T.g2)^2``: no matrix per motion is formed (equal to
    :func:`planar_epipolar_residuals`, ``tests/unit/vbn_common/test_two_view.py``).
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


def _triangulate_depths(R: np.ndarray, T: np.ndarray, f_model: np.ndarray,
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


def _parallax(f_model: np.ndarray, f_current: np.ndarray) -> float:
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


def _sample_indices(rng: np.random.Generator, n: int, size: int, count: int) -> np.ndarray:
    return np.argpartition(rng.random((count, n)), size - 1, axis=1)[:, :size]


def _ransac_needed(inlier_ratio: float, size: int, confidence: float) -> float:
    good = inlier_ratio ** size
    if good >= 1.0:
        return 0.0
    if good <= 0.0:
        return math.inf
    return math.log(1.0 - confidence) / math.log(1.0 - good)


def _msac(E: np.ndarray, f1: np.ndarray, f2: np.ndarray,
          threshold: float) -> tuple[float, np.ndarray]:
    err = _sampson(E, f1, f2)
    return float(np.sum(np.minimum(err * err, threshold * threshold))), np.abs(err) < threshold


def _optimise_locally(E: np.ndarray, score: float, f1: np.ndarray, f2: np.ndarray,
                      threshold: float, fit, minimum: int) -> tuple[np.ndarray, float]:
    """LO-RANSAC: refit a new best hypothesis on its inliers while the score drops.

    A minimal sample's model is noisy and, with a short baseline, finds few of the
    inliers at the final threshold; least squares on the points within a wider
    threshold, shrinking to the final one, recovers them (iterative local
    optimisation, Chum, Matas and Kittler 2003).
    """
    for factor in (4.0, 3.0, 2.0, 1.5, 1.0, 1.0):
        inliers = np.abs(_sampson(E, f1, f2)) < factor * threshold
        if inliers.sum() < minimum:
            continue
        candidate = fit(f1[inliers], f2[inliers])
        new_score, _ = _msac(candidate, f1, f2, threshold)
        if new_score < score:
            E, score = candidate, new_score
    return E, score


def _refine_planar(theta: float, phi: float, f_model: np.ndarray, f_current: np.ndarray,
                   iterations: int = 6) -> tuple[float, float]:
    """Gauss-Newton on the Sampson errors over ``(theta, phi)`` (numerical Jacobian)."""
    x = np.array([theta, phi])
    cost, step = math.inf, np.zeros(2)
    for _ in range(iterations):
        r, J = _residual_jacobian(x, f_model, f_current)
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


def _residual_jacobian(x: np.ndarray, f_model: np.ndarray, f_current: np.ndarray,
                       h: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Residuals at ``x`` and their central-difference Jacobian, in one batched pass."""
    offsets = np.array([[0.0, 0.0], [h, 0.0], [-h, 0.0], [0.0, h], [0.0, -h]])
    points = x + offsets
    err = _planar_sampson(f_model @ _M.T, f_current @ _M.T, points[:, :1],
                          points[:, 1:])                                   # (5, n)
    J = np.stack([err[1] - err[2], err[3] - err[4]], axis=1) / (2.0 * h)
    return err[0], J


def _finish(theta: float, phi: float, f_model: np.ndarray, f_current: np.ndarray,
            inliers: np.ndarray, method: str, noise_floor: float,
            rotation: np.ndarray | None = None,
            direction: np.ndarray | None = None) -> RelativeMotion:
    """Residual and covariance of ``(theta, phi)`` over the inliers; the result."""
    x = np.array([theta, phi])
    r, J = _residual_jacobian(x, f_model[inliers], f_current[inliers])
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
        rotation = _rot_z(-theta)
    return RelativeMotion(theta=float(wrap_angle(theta)), direction=direction,
                          inliers=inliers, residual=rms, method=method,
                          covariance=covariance, rotation=rotation)


def _check_translation(f_model: np.ndarray, f_current: np.ndarray, min_parallax: float,
                       method: str, residual: float = 0.0, ratio: float = 2.5) -> None:
    """Refuse views whose parallax is not above the noise.

    The median angle that the best pure rotation leaves between the rays must
    exceed ``min_parallax`` and ``ratio`` times the inliers' RMS epipolar error: with
    less, a rotation alone explains the data and the direction of translation is
    noise.
    """
    parallax = _parallax(f_model, f_current)
    needed = max(min_parallax, ratio * residual)
    if parallax < needed:
        raise VbnCommonError(
            f'{method}: the views are at (nearly) the same place: median parallax '
            f'{parallax:.2e} rad < {needed:.2e} rad, the direction of translation is '
            f'undetermined')


def _rms(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(errors * errors))) if len(errors) else 0.0


# -- 7.5.2: panoramic cameras, planar motion --------------------------------------------
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
    f1, f2 = _check_rays(rays_model, rays_current, 3, method)
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
        _check_translation(f1[idx], f2[idx], min_parallax, method)
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
        err = _planar_sampson(gu1, gu2, thetas[sl, None], phis[sl, None])
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
            theta, phi = _refine_planar(theta, phi, f1[inliers], f2[inliers])
    residual = _rms(planar_epipolar_residuals(f1[inliers], f2[inliers], theta, phi))
    _check_translation(f1[inliers], f2[inliers], min_parallax, method, residual,
                       min_parallax_ratio)
    return _finish(theta, phi, f1, f2, inliers, method, noise_floor)


# -- 7.5.1: pinhole cameras, planar essential matrix ------------------------------------
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
        l1, l2 = _triangulate_depths(R, cand, f1, f2)
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
    f1, f2 = _check_rays(rays_model, rays_current, 4, method)
    n = len(f1)
    rows = _planar_rows(f1, f2)                                        # (n, 4)
    rng = np.random.default_rng(rng)
    best_score, best_E = math.inf, None
    needed, drawn = float(max_iterations), 0
    while drawn < min(needed, max_iterations):
        count = min(_RANSAC_BATCH, max_iterations - drawn)
        samples = _sample_indices(rng, n, 4, count) if n > 4 else np.arange(4)[None]
        _, _, vt = np.linalg.svd(rows[samples])
        es = vt[:, -1, :]                                              # (count, 4)
        err = _sampson(_planar_e_matrix(es), f1, f2)                   # (count, n)
        scores = np.sum(np.minimum(err * err, threshold * threshold), axis=1)
        i = int(np.argmin(scores))
        if scores[i] < best_score:
            E, score = _optimise_locally(_planar_e_matrix(es[i]), float(scores[i]), f1, f2,
                                         threshold, _planar_fit, 4)
            best_score, best_E = score, E
            ratio = float(np.mean(_msac(E, f1, f2, threshold)[1]))
            needed = _ransac_needed(ratio, 4, confidence)
        drawn += len(samples)
        if n == 4:
            break
    inliers = _msac(best_E, f1, f2, threshold)[1]
    e = np.array([best_E[0, 1], best_E[1, 0], best_E[1, 2], best_E[2, 1]])
    if inliers.sum() < 4:
        raise VbnCommonError(f'{method}: no consensus: {int(inliers.sum())} inliers '
                                     f'of {n} correspondences (needs 4)')
    R, T = _planar_e_motion(e, f1[inliers], f2[inliers])
    theta, centre, _ = _optical_to_planar(R, T)
    phi = float(math.atan2(centre[1], centre[0]))
    if refine:
        theta, phi = _refine_planar(theta, phi, f1[inliers], f2[inliers])
    residual = _rms(planar_epipolar_residuals(f1[inliers], f2[inliers], theta, phi))
    _check_translation(f1[inliers], f2[inliers], min_parallax, method, residual,
                       min_parallax_ratio)
    return _finish(theta, phi, f1, f2, inliers, method, noise_floor)


# -- 7.4: the general essential matrix, normalised eight-point --------------------------
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
            l1, l2 = _triangulate_depths(R, T, f1, f2)
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
    f1, f2 = _check_rays(rays_model, rays_current, 8, method)
    n = len(f1)
    p1, N1 = _hartley(f1)
    p2, N2 = _hartley(f2)
    A = np.einsum('ni,nj->nij', p2, p1).reshape(n, 9)
    rng = np.random.default_rng(rng)
    best_score, best_E = math.inf, None
    needed, drawn = float(max_iterations), 0
    while drawn < min(needed, max_iterations):
        count = min(_RANSAC_BATCH, max_iterations - drawn)
        samples = _sample_indices(rng, n, 8, count) if n > 8 else np.arange(8)[None]
        _, _, vt = np.linalg.svd(A[samples])                           # (count, 9, 9)
        Es = N2.T @ vt[:, -1, :].reshape(-1, 3, 3) @ N1
        U, _, Vt = np.linalg.svd(Es)
        Es = U @ (np.array([1.0, 1.0, 0.0])[:, None] * Vt)
        err = _sampson(Es, f1, f2)
        scores = np.sum(np.minimum(err * err, threshold * threshold), axis=1)
        i = int(np.argmin(scores))
        if scores[i] < best_score:
            E, score = _optimise_locally(Es[i], float(scores[i]), f1, f2, threshold,
                                         _eight_point, 8)
            best_score, best_E = score, E
            ratio = float(np.mean(_msac(E, f1, f2, threshold)[1]))
            needed = _ransac_needed(ratio, 8, confidence)
        drawn += len(samples)
        if n == 8:
            break
    E = best_E
    inliers = _msac(E, f1, f2, threshold)[1]
    if inliers.sum() < 8:
        raise VbnCommonError(f'{method}: no consensus: {int(inliers.sum())} inliers '
                                     f'of {n} correspondences (needs 8)')
    R, T = _decompose_essential(E, f1[inliers], f2[inliers])
    residual = _rms(_sampson(E, f1[inliers], f2[inliers]))
    _check_translation(f1[inliers], f2[inliers], min_parallax, method, residual,
                       min_parallax_ratio)
    theta, centre, planar_rotation = _optical_to_planar(R, T)
    direction = centre / np.linalg.norm(centre)
    phi = float(math.atan2(direction[1], direction[0]))
    return _finish(theta, phi, f1, f2, inliers, method, noise_floor,
                   rotation=planar_rotation, direction=direction)


# -- 7.3: linear combination of views (Basri and Rivlin) --------------------------------
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
    fa, fb = _check_rays(rays_model_a, rays_model_b, 4, method)
    _, fc = _check_rays(rays_model_a, rays_current, 4, method)
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
    R_ab, _ = _planar_to_optical(yaw_ab, 0.0)                 # optical rotation a -> b
    frame = _lcv_frame(rays, np.ones(n, dtype=bool), R_ab, min_view_angle, method)
    mc, design = frame.m[2], frame.design
    rng = np.random.default_rng(rng)
    best_score, best_in = math.inf, np.ones(n, dtype=bool)
    if n > 4:
        needed, drawn = float(max_iterations), 0
        while drawn < min(needed, max_iterations):
            count = min(_RANSAC_BATCH, max_iterations - drawn)
            samples = _sample_indices(rng, n, 4, count)
            D = design[samples]                                             # (m, 4, 4)
            ok = np.abs(np.linalg.det(D)) > 1e-12
            if not np.any(ok):
                drawn += count
                continue
            coef = np.linalg.solve(D[ok], mc[samples[ok]])                   # (m, 4, 2)
            err = np.linalg.norm(np.einsum('nk,mkc->mnc', design, coef) - mc, axis=2)
            scores = np.sum(np.minimum(err * err, threshold * threshold), axis=1)
            i = int(np.argmin(scores))
            if scores[i] < best_score:
                best_score, best_in = scores[i], err[i] < threshold
                needed = _ransac_needed(float(best_in.mean()), 4, confidence)
            drawn += count
    inliers = best_in
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
    theta_a, _, _ = _optical_to_planar(U, np.zeros(3))
    if np.linalg.norm(position) <= 0 or not np.all(np.isfinite(position)):
        raise VbnCommonError(f'{method}: the current view is at model view a')
    phi_a = float(math.atan2(position[1], position[0]))
    # The same position seen from view b: rotate into b's planar frame.
    cb, sb = math.cos(yaw_ab), math.sin(yaw_ab)
    rel = position - pose_b[:2]
    in_b = np.array([cb * rel[0] + sb * rel[1], -sb * rel[0] + cb * rel[1]])
    theta_b = float(wrap_angle(theta_a - yaw_ab))
    phi_b = float(math.atan2(in_b[1], in_b[0]))
    motion_a = _finish(theta_a, phi_a, fa, fc, inliers, method, noise_floor)
    motion_b = _finish(theta_b, phi_b, fb, fc, inliers, method, noise_floor)
    return motion_a, motion_b


# -- dispatcher -------------------------------------------------------------------------
def _focal(camera: CameraModel) -> float:
    """Pixels per radian at the image centre (panorama: ``f_az``; pinhole: ``fx``)."""
    return float(camera.f_az if camera.kind == 'panoramic' else camera.fx)


def relative_motion(uv_model: np.ndarray, uv_current: np.ndarray, camera: CameraModel, *,
                    method: str | None = None, config: TwoViewConfig | None = None,
                    rng: np.random.Generator | int | None = None) -> RelativeMotion:
    """Estimate the motion from a model view to the current view from matched pixels.

    Converts pixels to rays with ``camera`` (the same model for both views) and
    pixel thresholds to angles with its focal length, then calls the method:
    ``camera.kind`` picks it (``'panoramic'`` -> :func:`panoramic_planar_motion`,
    ``'pinhole'`` -> :func:`pinhole_planar_essential`) unless ``method`` names one of
    :data:`METHODS`.

    Args:
        uv_model: ``(n, 2)`` pixel coordinates in the model view.
        uv_current: ``(n, 2)`` pixel coordinates of the same points in the current view.
        camera: the camera model of both views.
        method: ``None`` (by camera kind), or a name from :data:`METHODS`.
        config: thresholds and RANSAC settings (default :class:`TwoViewConfig`).
        rng: random generator or seed.

    Returns:
        The motion (module conventions).

    Raises:
        VbnCommonError: an unknown method, a method that needs another camera,
            or the method's own errors.
    """
    config = config or TwoViewConfig()
    method = method or DEFAULT_METHOD.get(camera.kind)
    if method not in METHODS:
        raise VbnCommonError(f'unknown two-view method {method!r} (expected one of '
                                     f'{", ".join(METHODS)})')
    uv_model = np.asarray(uv_model, dtype=float).reshape(-1, 2)
    uv_current = np.asarray(uv_current, dtype=float).reshape(-1, 2)
    rays_model, rays_current = camera.unproject(uv_model), camera.unproject(uv_current)
    f = _focal(camera)
    common = {'threshold': config.threshold_px / f, 'noise_floor': config.noise_floor_px / f,
              'min_parallax': config.min_parallax_px / f,
              'min_parallax_ratio': config.min_parallax_ratio, 'rng': rng}
    if method == 'panoramic_planar':
        if camera.kind != 'panoramic':
            raise VbnCommonError(f'panoramic_planar needs a panoramic camera, got '
                                         f'{camera.kind!r}')
        return panoramic_planar_motion(
            rays_model, rays_current, min_elevation=math.radians(config.min_elevation_deg),
            max_pairs=config.max_pairs, refine=config.refine, **common)
    ransac = {'max_iterations': config.max_iterations, 'confidence': config.confidence}
    if method == 'pinhole_planar':
        motion = pinhole_planar_essential(rays_model, rays_current, refine=config.refine,
                                          **ransac, **common)
    else:
        motion = general_essential(rays_model, rays_current, **ransac, **common)
    _LOG.debug('%s: %d of %d inliers, residual %.2f px', method, int(motion.inliers.sum()),
               len(uv_model), motion.residual * f)
    return motion
