"""Motion parameters between pairs of views (thesis Algorithm 6.1, Section 6.1.2).

For pairs of images that share at least ``min_matches`` features, the relative
rotation and the unit translation between them, estimated robustly by the Chapter 7
solvers (:func:`~vbn_common.geometry.two_view.relative_motion`: the planar
panoramic or pinhole solvers for a robot on a floor, the essential matrix otherwise).

The thesis tries every pair ``i < j``. A robot's exploration has too many for that
(the 25 cm floor: 2.9 million), and its odometry says which can overlap: the pairs
are the ones :func:`~.pipeline.estimate_poses` proposes (near in time, then near in a
first estimate). Features are SIFT's, matched by :func:`~visibility_builder.
pair_matching.match_pose_pair` (mutual nearest neighbours within ``tau``, the
relation (6.4) of the correspondence classes); a pair that passes keeps the solver's
inliers.

Each measurement carries the uncertainty that weighs it in 6.1.3 and 6.1.4: the
solver's covariance of the rotation angle and of the translation's bearing (from the
inliers' residuals and the Jacobian of the epipolar errors), inflated by the share of
matches the solver rejected, as the thesis asks ("from some measure of the residual
error ... and from the proportion of inliers"). Views taken at one place (a robot
turning on the spot) have no direction between them: the solvers refuse them and
:func:`rotation_only` measures their rotation alone.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.features import ImageFeatures
from vbn_common.geometry.camera import CameraModel, pixels_per_radian
from vbn_common.geometry.epipolar import planar_sampson
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION
from vbn_common.geometry.motion import TwoViewConfig
from vbn_common.geometry.two_view import relative_motion
from visibility_builder.pair_matching import match_pose_pair

__all__ = ['DIRECTION_STD_FLOOR', 'ROTATION_STD_FLOOR', 'PairMotion', 'PairSettings',
           'bearings_given_turns', 'measure_pair', 'rotation_only']


#: Least standard deviations a measurement claims, radians: a solver's covariance from a
#: few hundred inliers can claim microradians, and one wrong pair so weighted outweighs
#: every other (weights over 1e8 beside 1e-1 on the pinhole room).
ROTATION_STD_FLOOR = 3e-4
DIRECTION_STD_FLOOR = 1e-3


@dataclass(frozen=True)
class PairSettings:
    """How pairs are matched and measured.

    Attributes:
        tau: Largest SIFT descriptor distance of a match (the classes' ``tau``).
        ratio: Lowe's ratio test on matches, or None.
        min_matches: Fewest matches for a pair to be measured (the thesis's ``m``).
        min_inliers: Fewest solver inliers for a measurement to be kept.
        method: Two-view method (None: by the camera's kind).
        two_view: Thresholds and RANSAC of the solvers.
        seed: Seeds each pair's RANSAC (with the pair's indices).
    """

    tau: float = 150.0
    ratio: float | None = 0.8
    min_matches: int = 20
    min_inliers: int = 15
    method: str | None = None
    two_view: TwoViewConfig = TwoViewConfig()
    seed: int = 0


@dataclass(frozen=True)
class PairMotion:
    """The motion from view ``i`` to view ``j``.

    Attributes:
        i: First view.
        j: Second view.
        rotation: ``(3, 3)`` view ``i``'s planar frame (REP 103) into view ``j``'s.
        direction: ``(3,)`` unit direction from ``i`` to ``j`` in ``i``'s planar frame,
            or NaN (views at one place: rotation only).
        rotation_std: Standard deviation of the rotation, radians.
        direction_std: ... of the direction's bearing, radians (inf when NaN).
        matches: Matches tried.
        inliers: Matches the solver kept.
        residual: RMS angular error of the inliers, radians.
        method: The solver.
        features: ``(inliers, 2)`` the inlier matches' feature indices in ``i`` and ``j``
            (the tracks of the refinement).
    """

    i: int
    j: int
    rotation: np.ndarray
    direction: np.ndarray
    rotation_std: float
    direction_std: float
    matches: int
    inliers: int
    residual: float
    method: str
    features: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))

    @property
    def has_direction(self) -> bool:
        """Whether the pair measured a direction of translation."""
        return bool(np.all(np.isfinite(self.direction)))


def _inflation(matches: int, inliers: int) -> float:
    """Uncertainty factor from the inlier share: 1 when every match agreed."""
    share = inliers / max(matches, 1)
    return 1.0 / max(share, 0.1)


def measure_pair(i: int, j: int, a: ImageFeatures, b: ImageFeatures, camera: CameraModel,
                 settings: PairSettings, moved: bool | None = None
                 ) -> tuple[PairMotion | None, str]:
    """Match views ``i`` and ``j`` and measure their motion.

    ``moved``: whether the odometry says the views were taken at different places. When
    it does, views the solver finds at one place are refused rather than measured as a
    rotation alone: a wall far off, or one plane filling both views, shows no parallax
    for half a metre of motion, and the rotation that maps its rays was measured 16
    degrees off the true turn on the pinhole room (0.5 m sideways, 45 degrees turned).

    Returns:
        ``(motion, '')`` or ``(None, reason)``: too few matches, the solver's refusal
        or too few inliers.
    """
    if len(a) == 0 or len(b) == 0:
        return None, 'no features'
    pairs = match_pose_pair(a.descriptors, b.descriptors, settings.tau, settings.ratio).mutual
    if len(pairs) < settings.min_matches:
        return None, f'{len(pairs)} matches'
    uv_a = a.keypoints[pairs[:, 0]].astype(float)
    uv_b = b.keypoints[pairs[:, 1]].astype(float)
    rng = np.random.default_rng([settings.seed, i, j])
    try:
        motion = relative_motion(uv_a, uv_b, camera, method=settings.method,
                                 config=settings.two_view, rng=rng)
    except VbnCommonError as error:
        if 'same place' in str(error):
            if moved:
                return None, 'no parallax: moved between the views'
            return rotation_only(i, j, uv_a, uv_b, camera, settings, pairs)
        return None, str(error)
    inliers = int(motion.inliers.sum())
    if inliers < settings.min_inliers:
        return None, f'{inliers} inliers'
    factor = _inflation(len(pairs), inliers)
    cov = np.asarray(motion.covariance, float)
    rot_std = math.sqrt(max(cov[0, 0], 0.0)) if np.isfinite(cov[0, 0]) else math.inf
    dir_std = math.sqrt(max(cov[1, 1], 0.0)) if np.isfinite(cov[1, 1]) else math.inf
    if motion.method == 'general_essential':
        # The solver's covariance is the planar model's (a yaw and a bearing), which says
        # nothing of a general motion: on the Strecha fountain it gave 8-9 (1,598 inliers)
        # less weight than a wrong 5-10 (29). The residual over the inliers' count is
        # the general measure of how well the motion is pinned.
        f = pixels_per_radian(camera)
        noise = max(float(motion.residual), settings.two_view.noise_floor_px / f)
        rot_std = dir_std = noise / math.sqrt(inliers)
    direction = np.zeros(3)
    direction[:len(motion.direction)] = motion.direction
    direction /= np.linalg.norm(direction)
    return PairMotion(i, j, np.asarray(motion.rotation, float), direction,
                      factor * max(rot_std, ROTATION_STD_FLOOR),
                      factor * max(dir_std, DIRECTION_STD_FLOOR), len(pairs),
                      inliers, float(motion.residual), motion.method,
                      pairs[np.asarray(motion.inliers, bool)]), ''


def rotation_only(i: int, j: int, uv_a: np.ndarray, uv_b: np.ndarray, camera: CameraModel,
                  settings: PairSettings, matches: np.ndarray | None = None
                  ) -> tuple[PairMotion | None, str]:
    """Measure the rotation between two views taken at one place (no translation).

    Rays of matched features: ``b = R a`` for a pure rotation. RANSAC over pairs of
    matches (Kabsch on two rays), the rotation then refitted on the inliers.
    ``matches``: the feature indices of the rows of ``uv_a`` and ``uv_b`` (the motion's
    ``features``; default: the row numbers).
    """
    # Optical (z forward) rays into planar REP 103 frames (x forward, y left, z up).
    a = camera.unproject(uv_a) @ BASE_TO_CAMERA_ROTATION.T
    b = camera.unproject(uv_b) @ BASE_TO_CAMERA_ROTATION.T
    f = pixels_per_radian(camera)
    threshold = settings.two_view.threshold_px / f
    rng = np.random.default_rng([settings.seed, i, j, 1])
    n = len(a)
    best, best_count = None, -1
    for _ in range(200):
        pick = rng.choice(n, size=2, replace=False)
        rotation = _kabsch(a[pick], b[pick])
        count = int((np.linalg.norm(a @ rotation.T - b, axis=1) < threshold).sum())
        if count > best_count:
            best, best_count = rotation, count
    inliers = np.linalg.norm(a @ best.T - b, axis=1) < threshold
    if inliers.sum() < settings.min_inliers:
        return None, f'{int(inliers.sum())} inliers (rotation only)'
    rotation = _kabsch(a[inliers], b[inliers])
    errors = np.linalg.norm(a[inliers] @ rotation.T - b[inliers], axis=1)
    residual = float(np.sqrt(np.mean(errors ** 2)))
    noise = max(residual, settings.two_view.noise_floor_px / f)
    std = _inflation(n, int(inliers.sum())) * noise / math.sqrt(int(inliers.sum()))
    if matches is None:
        matches = np.repeat(np.arange(n)[:, None], 2, axis=1)
    return PairMotion(i, j, rotation, np.full(3, np.nan), std, math.inf, n,
                      int(inliers.sum()), residual, 'rotation_only',
                      np.asarray(matches, np.int64)[inliers]), ''


def _kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return the rotation ``R`` minimising ``sum |R a_k - b_k|^2``."""
    h = a.T @ b
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def bearings_given_turns(pairs: list[PairMotion], turns: np.ndarray,
                         features: list[ImageFeatures], camera: CameraModel,
                         settings: PairSettings, iterations: int = 6
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Each pair's bearing of translation refitted with its turn held at ``turns``.

    A pair's solver fits the turn and the bearing together, and where the two trade
    against each other (a pinhole looking at one wall) an error of the turn becomes one
    of the bearing that the pair's covariance does not show: on the pinhole room the
    bearings were 2 to 11 degrees off while claiming 0.06. Once the rotations of all
    views are fitted (6.1.3), the turn of each pair is known far better than the pair
    alone knew it; with it held, the bearing is a one-parameter fit to the pair's inlier
    rays (Gauss-Newton on the Sampson errors, all pairs at once), and its standard
    deviation follows from those residuals (floored and inflated as in
    :func:`measure_pair`). This is the step of global structure from motion that
    refits relative translations under the averaged rotations.

    Args:
        pairs: Pairs with a direction (``has_direction``).
        turns: ``(m,)`` the fitted turn of each pair (view ``j``'s yaw minus view
            ``i``'s), radians.
        features: Every view's features (the pairs' ``features`` index them).
        camera: The camera of the views.
        settings: The pairs' settings (the noise floor of their solver).
        iterations: Gauss-Newton steps.

    Returns:
        ``(m,)`` bearings (``atan2`` of the direction in view ``i``'s planar frame) and
        ``(m,)`` their standard deviations, radians.
    """
    m = len(pairs)
    if m == 0:
        return np.zeros(0), np.zeros(0)
    owner = np.concatenate([np.full(len(p.features), k) for k, p in enumerate(pairs)])
    uv_i = np.concatenate([features[p.i].keypoints[p.features[:, 0]] for p in pairs])
    uv_j = np.concatenate([features[p.j].keypoints[p.features[:, 1]] for p in pairs])
    g1 = camera.unproject(uv_i.astype(float)) @ BASE_TO_CAMERA_ROTATION.T
    g2 = camera.unproject(uv_j.astype(float)) @ BASE_TO_CAMERA_ROTATION.T
    theta = np.asarray(turns, float)[owner]
    phi = np.array([math.atan2(p.direction[1], p.direction[0]) for p in pairs])
    h = 1e-6
    for _ in range(iterations):
        r = planar_sampson(g1, g2, theta, phi[owner])
        jac = (planar_sampson(g1, g2, theta, phi[owner] + h)
               - planar_sampson(g1, g2, theta, phi[owner] - h)) / (2.0 * h)
        normal = np.bincount(owner, jac * jac, minlength=m)
        step = -np.bincount(owner, jac * r, minlength=m) / np.maximum(normal, 1e-300)
        phi = phi + np.where(normal > 0, step, 0.0)
        if np.max(np.abs(step)) < 1e-10:
            break
    r = planar_sampson(g1, g2, theta, phi[owner])
    jac = (planar_sampson(g1, g2, theta, phi[owner] + h)
           - planar_sampson(g1, g2, theta, phi[owner] - h)) / (2.0 * h)
    count = np.bincount(owner, minlength=m)
    floor = settings.two_view.noise_floor_px / pixels_per_radian(camera)
    sigma2 = np.maximum(np.bincount(owner, r * r, minlength=m) / np.maximum(count - 1, 1),
                        floor ** 2)
    std = np.sqrt(sigma2 / np.maximum(np.bincount(owner, jac * jac, minlength=m), 1e-300))
    inflation = np.array([_inflation(p.matches, p.inliers) for p in pairs])
    return np.angle(np.exp(1j * phi)), inflation * np.maximum(std, DIRECTION_STD_FLOOR)
