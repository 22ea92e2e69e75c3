"""The camera pose from the database's 3-D class points, where no region serves.

The thesis localizes only inside a region: the two model views and the region's k
features give the pose (7.4, 7.5). A camera that does not see all around leaves much
of its pose space without k features visible from every pose of a neighbourhood
(close to a wall, turned towards a bare corner), and the decomposition then has no
region there. The database still holds what a structure-based localizer needs: every
class seen by two model views has a triangulated point (``DatabaseIndex.points``).
When voting finds no region, :func:`solve_absolute` computes the pose from the
frame's SIFT matches to those points, so the robot keeps a pose between regions
(the localizer stays LOST and votes again on the next frame).

Model: the camera at ``(x, y)`` in ``map``, at the exploration's camera height (the
points' ``z`` is measured from it), heading ``yaw``; a frame's rays are levelled by the
mount already (:class:`~vbn_common.geometry.mount.TiltedCamera`).

- Hypotheses: three matches fix the planar pose linearly. A ray with horizontal
  direction ``(a, b)`` in the camera's base frame through the point ``(X, Y)`` gives
  ``c (X b - Y a) + s (X a + Y b) + p a + q b = 0`` with ``c, s = cos yaw, sin yaw``,
  ``p = y c - x s`` and ``q = -(x c + y s)``: three points give the null vector of a
  3 x 4 matrix, normalised to ``c^2 + s^2 = 1``, its sign chosen so the points lie in
  front. RANSAC draws the samples in one vectorised batch and scores them by the
  angle between each observed ray and the direction to its point (3-D).
- Refinement: Gauss-Newton with Huber weights on the angular errors of the inliers,
  over ``(x, y, yaw)`` and the frame's own pitch, roll and height offset, each of
  these three with a Gaussian prior (vibration, an uneven floor, another robot's
  camera height: :mod:`.tilt_refinement` does the same on the epipolar errors).
- Acceptance: at least ``min_inliers`` inliers whose bearings span at least
  ``min_spread`` radians (points in one narrow patch pin the pose poorly).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math

import numpy as np

from landmark_localizer.angular_kernels import coarse_inliers, gauss_newton, normal_equations
from landmark_localizer.config import LocalizerConfig
from landmark_localizer.index import DatabaseIndex, tilt_rotation
from landmark_localizer.pose import PoseSolution
from vbn_common.features import ImageFeatures
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION, wrap_angle
from vbn_common.geometry.localize import PoseEstimate

#: Least tracked features with a point to judge a two-view pose by (polishing it takes
#: ``min_inliers``).
JUDGE_POINTS = 5
#: RANSAC: the probability of having drawn one sample of three inliers, and the most
#: batches of samples drawn to reach it.
CONFIDENCE = 0.999
MAX_BATCHES = 4
#: A hypothesis further than this from the winner (metres) with at least this share of
#: its inliers makes the frame ambiguous: no pose.
AMBIGUITY_DISTANCE_M = 0.3
AMBIGUITY_RATIO = 0.8
#: Hypotheses refined (the strongest, at least ``AMBIGUITY_DISTANCE_M`` apart).
CANDIDATES = 3
#: Gauss-Newton stops when a step moves the position less than this (metres) and the
#: heading less than ``STOP_RAD``.
STOP_M = 1e-4
STOP_RAD = 1e-5

__all__ = ['AMBIGUITY_DISTANCE_M', 'AMBIGUITY_RATIO', 'CANDIDATES', 'CONFIDENCE', 'JUDGE_POINTS',
           'MAX_BATCHES', 'AbsolutePose', 'absolute_solution', 'base_rays', 'hypotheses',
           'refine_absolute', 'solve_absolute']


@dataclass(frozen=True)
class AbsolutePose:
    """A camera pose from 2D-3D matches.

    Attributes:
        pose: (3,) camera pose ``(x, y, yaw)`` in ``map``.
        covariance: (3, 3) covariance of the pose (the tilt and height marginalised).
        inliers: (n,) bool over the matches.
        rms: RMS angular error of the inliers, radians.
        tilt: ``(pitch, roll, dz)`` the refinement found (radians, radians, metres).
    """

    pose: np.ndarray
    covariance: np.ndarray
    inliers: np.ndarray
    rms: float
    tilt: np.ndarray

    @property
    def n_inliers(self) -> int:
        """Matches kept."""
        return int(self.inliers.sum())


def base_rays(optical_rays: np.ndarray) -> np.ndarray:
    """(n, 3) unit rays in the camera's level base frame (x forward, y left, z up)."""
    rays = np.asarray(optical_rays, float).reshape(-1, 3) @ BASE_TO_CAMERA_ROTATION.T
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def hypotheses(rays: np.ndarray, points: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """Planar camera poses from triples of matches, ``(s, 3)`` (NaN rows: degenerate).

    Args:
        rays: (n, 3) unit rays in the camera's level base frame.
        points: (n, 3) their points in ``map`` (``z`` from the camera height).
        samples: (s, 3) indices of the triples.

    Example:
        >>> pts = np.array([[3., 0, 0.5], [0, 3, -0.2], [-2, -1, 0.1]])
        >>> pose = np.array([0.5, -0.2, 0.3])
        >>> d = pts - [pose[0], pose[1], 0]
        >>> c, s = np.cos(pose[2]), np.sin(pose[2])
        >>> r = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], 1)
        >>> hypotheses(r / np.linalg.norm(r, axis=1)[:, None], pts, np.array([[0, 1, 2]]))
        ... # doctest: +NORMALIZE_WHITESPACE
        array([[ 0.5, -0.2,  0.3]])
    """
    a, b = rays[samples, 0], rays[samples, 1]
    centre = points[samples, :2].mean(axis=1)  # conditioning: coordinates near zero
    x = points[samples, 0] - centre[:, :1]
    y = points[samples, 1] - centre[:, 1:]
    design = np.stack([x * b - y * a, x * a + y * b, a, b], axis=2)  # (s, 3, 4)
    _, _, vt = np.linalg.svd(design)
    null = vt[:, -1, :]
    norm = np.hypot(null[:, 0], null[:, 1])
    out = np.full((len(samples), 3), np.nan)
    good = norm > 1e-9
    null = null[good] / norm[good, None]
    c, s, p, q = null.T
    px, py = -s * p - c * q, c * p - s * q
    # The sign: the points in front (the ray's horizontal direction towards them).
    dx = x[good] - px[:, None]
    dy = y[good] - py[:, None]
    along = (c[:, None] * a[good] - s[:, None] * b[good]) * dx + \
        (s[:, None] * a[good] + c[:, None] * b[good]) * dy
    flip = along.sum(axis=1) < 0
    yaw = np.arctan2(s, c) + np.where(flip, math.pi, 0.0)
    out[good] = np.column_stack([px + centre[good, 0], py + centre[good, 1], wrap_angle(yaw)])
    return out


def _predicted(poses: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(m, n, 3) unit directions from camera poses to points, in each camera's base frame."""
    dx = points[None, :, 0] - poses[:, None, 0]
    dy = points[None, :, 1] - poses[:, None, 1]
    dz = np.broadcast_to(points[None, :, 2], dx.shape)
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    v = np.stack([c * dx + s * dy, -s * dx + c * dy, dz], axis=2)
    return v / np.maximum(np.linalg.norm(v, axis=2, keepdims=True), 1e-12)


def _angular_errors(poses: np.ndarray, rays: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(m, n) angles between the observed rays and the directions to the points."""
    cos = np.einsum('mnk,nk->mn', _predicted(poses, points), rays)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def _coarse_inliers(poses: np.ndarray, rays: np.ndarray, points: np.ndarray,
                    threshold: float, tilt_prior: float, height_prior: float) -> np.ndarray:
    """(m, n) bool: matches a planar hypothesis explains before the tilt is known.

    The bearing (azimuth) within ``threshold``; the elevation within ``threshold``
    plus three prior deviations of the frame's tilt and of its height offset seen at
    the point's distance (a pitch of half a degree moves every ray more than a
    threshold of a few pixels). Compiled (:func:`.angular_kernels.coarse_inliers`).
    """
    return coarse_inliers(np.ascontiguousarray(poses, float), np.ascontiguousarray(rays, float),
                          np.ascontiguousarray(points, float), float(threshold),
                          float(tilt_prior), float(height_prior))


def _residuals(state: np.ndarray, rays: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, 3) observed ray (tilted by the state) minus the predicted direction.

    The same as :func:`tilt_rotation` and :func:`_predicted`; the refinement's compiled
    steps compute it with its derivatives (:func:`.angular_kernels.linearise`).
    """
    x, y, yaw, pitch, roll, dz = (float(v) for v in state)
    turned = rays @ tilt_rotation(pitch, roll).T
    dx, dy, dzp = points[:, 0] - x, points[:, 1] - y, points[:, 2] - dz
    c, s = math.cos(yaw), math.sin(yaw)
    v = np.column_stack([c * dx + s * dy, -s * dx + c * dy, dzp])
    return turned - v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)


def refine_absolute(pose: np.ndarray, rays: np.ndarray, points: np.ndarray,
                    threshold: float, sigma: float, tilt_prior: float,
                    height_prior: float, iterations: int = 8,
                    motion_prior: tuple[np.ndarray, np.ndarray] | None = None,
                    point_weights: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """Gauss-Newton with Huber weights: ``(state (6,), covariance of (x, y, yaw))``.

    The covariance takes the rays' noise as their RMS angular error at the state found
    (at least ``sigma``) and the priors as given: scaling the whole information by the
    residuals would widen the priors too, and a motion prior carried on from the last
    pose's covariance (:func:`~.points_refinement.motion_prior`) then grew frame after
    frame wherever the points leave a direction to the prior.

    Args:
        pose: (3,) starting camera pose, or (6,) a starting state with its tilt and
            height offset (where a refinement on some of the points found them).
        rays: (n, 3) unit rays in the camera's level base frame.
        points: (n, 3) their points.
        threshold: Huber threshold, radians.
        sigma: angular noise of a ray (whitens the priors against the data), radians.
        tilt_prior: prior standard deviation of the frame's pitch and roll, radians
            (0: kept level).
        height_prior: prior standard deviation of its height offset, metres (0: none).
        iterations: at most this many Gauss-Newton steps.
        motion_prior: ``(predicted pose (3,), standard deviations (3,))`` of the camera's
            ``(x, y, yaw)`` from the motion model, or None (no prior on the pose).
        point_weights: (n,) each ray's weight beside its Huber weight, the inverse of
            its variance relative to the others' (a source measured less well counts
            less); the rays' noise is then that of a ray of weight 1, the RMS of the
            weighted squared errors. None: all 1.
    """
    state = np.concatenate([np.asarray(pose, float), np.zeros(3)])[:6]
    free = np.flatnonzero([True, True, True, tilt_prior > 0, tilt_prior > 0,
                           height_prior > 0])
    prior = np.array([0, 0, 0, tilt_prior, tilt_prior, height_prior], float)
    centre = np.zeros(6)
    if motion_prior is not None:
        centre[:3], prior[:3] = motion_prior[0], motion_prior[1]
    prior_info = np.where(prior[free] > 0, (sigma / np.maximum(prior[free], 1e-12)) ** 2, 0.0)
    rays, points = np.ascontiguousarray(rays, float), np.ascontiguousarray(points, float)
    weights = np.ones(len(rays)) if point_weights is None else \
        np.ascontiguousarray(point_weights, float)
    if iterations < 1 or gauss_newton(state, rays, points, threshold, weights, free,
                                      prior_info, centre, iterations, STOP_M, STOP_RAD) < 0:
        return None
    hessian, gradient = np.empty((6, 6)), np.empty(6)
    squares = normal_equations(state, rays, points, threshold, weights, hessian, gradient)
    noise = max(math.sqrt(squares / len(rays)), sigma) if len(rays) else sigma
    info = hessian[np.ix_(free, free)] * (sigma / noise) ** 2 + np.diag(prior_info)
    try:
        cov = sigma ** 2 * np.linalg.inv(info)[:3, :3]
    except np.linalg.LinAlgError:
        return None
    return state, 0.5 * (cov + cov.T)


def solve_absolute(rays: np.ndarray, points: np.ndarray, rng: np.random.Generator, *,
                   threshold: float, sigma: float, min_inliers: int, min_spread: float,
                   tilt_prior: float = 0.0, height_prior: float = 0.0,
                   iterations: int = 256, prior_pose: np.ndarray | None = None,
                   max_distance: float = math.inf, max_turn: float = math.inf,
                   huber: float | None = None) -> AbsolutePose | None:
    """Robust camera pose from rays to known points; None when nothing trustworthy.

    Args:
        rays: (n, 3) unit rays of the frame's matches, camera's level base frame.
        points: (n, 3) the matched classes' points in ``map``.
        rng: Random generator of the samples.
        threshold: inlier angle, radians.
        sigma: angular noise of a ray, radians (the covariance's scale floor).
        min_inliers: least inliers accepted.
        min_spread: least spread of the inliers' horizontal bearings, radians.
        tilt_prior: see :func:`refine_absolute`.
        height_prior: see :func:`refine_absolute`.
        iterations: RANSAC samples.
        prior_pose: (3,) the predicted camera pose, if any: hypotheses further than
            ``max_distance`` from it are not considered.
        max_distance: see ``prior_pose``, metres.
        max_turn: with ``prior_pose``, how far the heading may be from it (radians):
            matches whose bearing no pose within both bounds explains are set aside
            before sampling (among many wrong matches, the few right ones are then
            drawn together).
        huber: the refinement's Huber threshold, radians (default ``threshold``): a
            smaller one for measurements good to a few tenths of a pixel.
    """
    rays = np.asarray(rays, float).reshape(-1, 3)
    points = np.asarray(points, float).reshape(-1, 3)
    if prior_pose is not None and math.isfinite(max_turn) and math.isfinite(max_distance):
        kept = _gate(rays, points, np.asarray(prior_pose, float), max_distance,
                     max_turn + threshold)
        found = solve_absolute(rays[kept], points[kept], rng, threshold=threshold,
                               sigma=sigma, min_inliers=min_inliers, min_spread=min_spread,
                               tilt_prior=tilt_prior, height_prior=height_prior,
                               iterations=iterations, prior_pose=prior_pose,
                               max_distance=max_distance, huber=huber)
        if found is None:
            return None
        inliers = np.zeros(len(rays), bool)
        inliers[np.flatnonzero(kept)[found.inliers]] = True
        return replace(found, inliers=inliers)
    n = len(rays)
    if n < max(3, min_inliers):
        return None
    poses, counts = _sample(rays, points, rng, iterations, threshold, tilt_prior,
                            height_prior, prior_pose, max_distance)
    if counts.size == 0 or counts.max() < min_inliers:
        return None
    # The strongest hypotheses, a few apart, each refined: the coarse count (elevation
    # slack for the unknown tilt) can favour a wrong pose the refinement then shrinks.
    tried: list[np.ndarray] = []
    results: list[AbsolutePose] = []
    for j in np.argsort(-counts, kind='stable'):
        if len(tried) == CANDIDATES or counts[j] < min_inliers:
            break
        if any(np.hypot(*(poses[j, :2] - t[:2])) <= AMBIGUITY_DISTANCE_M for t in tried):
            continue
        tried.append(poses[j])
        found = _finish(poses[j], rays, points, threshold, sigma, min_inliers, min_spread,
                        tilt_prior, height_prior, huber or threshold)
        if found is not None and (prior_pose is None or np.hypot(
                *(found.pose[:2] - prior_pose[:2])) <= max_distance):
            results.append(found)
    if not results:
        return None
    best = max(results, key=lambda r: r.n_inliers)
    # Ambiguity: another pose, far from the best, that explains nearly as many matches
    # (a repeated pattern, a second wall that fits) leaves the frame undecided.
    for other in results:
        if other is not best and other.n_inliers >= AMBIGUITY_RATIO * best.n_inliers and \
                np.hypot(*(other.pose[:2] - best.pose[:2])) > AMBIGUITY_DISTANCE_M:
            return None
    return best


def _finish(start: np.ndarray, rays: np.ndarray, points: np.ndarray, threshold: float,
            sigma: float, min_inliers: int, min_spread: float, tilt_prior: float,
            height_prior: float, huber: float) -> AbsolutePose | None:
    """Refine a hypothesis on its inliers, re-select them, refine again (or None)."""
    inliers = _coarse_inliers(start[None], rays, points, threshold, tilt_prior,
                              height_prior)[0]
    if inliers.sum() < min_inliers:
        return None
    found = refine_absolute(start, rays[inliers], points[inliers], huber, sigma,
                            tilt_prior, height_prior)
    if found is None:
        return None
    state, _ = found
    turned = rays @ tilt_rotation(state[3], state[4]).T
    shifted = points - np.array([0.0, 0.0, state[5]])
    inliers = _angular_errors(state[None, :3], turned, shifted)[0] <= threshold
    if inliers.sum() < min_inliers or _spread(rays[inliers]) < min_spread:
        return None
    found = refine_absolute(state[:3], rays[inliers], points[inliers], huber, sigma,
                            tilt_prior, height_prior)
    if found is None:
        return None
    state, covariance = found   # the rays' noise: their RMS error, floored at sigma
    residual = np.linalg.norm(_residuals(state, rays[inliers], points[inliers]), axis=1)
    rms = float(np.sqrt(np.mean(residual ** 2)))
    return AbsolutePose(state[:3].copy(), covariance, inliers, rms, state[3:].copy())


def _sample(rays: np.ndarray, points: np.ndarray, rng: np.random.Generator, iterations: int,
            threshold: float, tilt_prior: float, height_prior: float,
            prior_pose: np.ndarray | None, max_distance: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """RANSAC hypotheses and their coarse inlier counts, ``((h, 3), (h,))``.

    Batches of ``iterations`` triples until a sample of three inliers was drawn with
    probability :data:`CONFIDENCE` at the best inlier ratio seen (adaptive termination;
    at most :data:`MAX_BATCHES` batches); the prior pose, if any, is a hypothesis too.
    Hypotheses further than ``max_distance`` from the prior are left out.
    """
    n = len(rays)
    poses_all, counts_all = [], []
    if prior_pose is not None:
        poses_all.append(np.asarray(prior_pose, float).reshape(1, 3))
        counts_all.append(_coarse_inliers(poses_all[0], rays, points, threshold, tilt_prior,
                                          height_prior).sum(axis=1))
    drawn = 0
    for _ in range(MAX_BATCHES):
        samples = np.argsort(rng.random((iterations, n)), axis=1)[:, :3]
        poses = hypotheses(rays, points, samples)
        ok = np.all(np.isfinite(poses), axis=1)
        if prior_pose is not None:
            ok &= np.hypot(*(poses[:, :2] - prior_pose[:2]).T) <= max_distance
        drawn += iterations
        if ok.any():
            poses_all.append(poses[ok])
            counts_all.append(_coarse_inliers(poses[ok], rays, points, threshold, tilt_prior,
                                              height_prior).sum(axis=1))
        best = max((int(c.max()) for c in counts_all if c.size), default=0)
        ratio = min(best / n, 1.0)
        if ratio >= 1.0 or drawn * math.log1p(-ratio ** 3 + 1e-300) <= math.log(
                1.0 - CONFIDENCE):
            break
    if not poses_all:
        return np.zeros((0, 3)), np.zeros(0, int)
    return np.concatenate(poses_all), np.concatenate(counts_all)


def _gate(rays: np.ndarray, points: np.ndarray, prior: np.ndarray, radius: float,
          turn: float) -> np.ndarray:
    """Return ``(n,)`` bool: the matches a pose near ``prior`` can explain.

    Near: within ``radius`` metres and ``turn`` radians; a point ``d`` away moves by
    ``asin(radius / d)`` in bearing as the camera moves by ``radius``.
    """
    v = _predicted(prior[None], points)[0]
    azimuth = np.arctan2(v[:, 1], v[:, 0]) - np.arctan2(rays[:, 1], rays[:, 0])
    azimuth = np.abs((azimuth + math.pi) % (2 * math.pi) - math.pi)
    distance = np.hypot(points[:, 0] - prior[0], points[:, 1] - prior[1])
    moved = np.where(distance <= radius, math.pi,
                     np.arcsin(np.clip(radius / np.maximum(distance, 1e-9), 0.0, 1.0)))
    return azimuth <= moved + turn


def _spread(rays: np.ndarray) -> float:
    """Angular extent of the rays' horizontal bearings (the smallest arc holding them)."""
    if len(rays) < 2:
        return 0.0
    bearing = np.sort(np.arctan2(rays[:, 1], rays[:, 0]))
    gaps = np.diff(np.concatenate([bearing, bearing[:1] + 2 * math.pi]))
    return float(2 * math.pi - gaps.max())


def absolute_solution(index: DatabaseIndex, features: ImageFeatures,
                      nearest: tuple[np.ndarray, np.ndarray, np.ndarray],
                      config: LocalizerConfig, rng: np.random.Generator,
                      prior_pose: np.ndarray | None = None,
                      scene: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                      min_inliers: int | None = None, max_distance: float | None = None,
                      max_turn: float = math.inf,
                      measured: tuple[np.ndarray, np.ndarray] | None = None,
                      huber_px: float | None = None) -> PoseSolution | None:
    """Return the frame's camera pose from its matches to the 3-D points, as a solve.

    Args:
        index: The database index (points, the frame's camera).
        features: The frame's SIFT features (voting's).
        nearest: ``index.nearest_classes`` of their descriptors (matches to the class
            points, used when ``scene`` is None).
        config: ``absolute_*``, ``max_jump_m``, ``tilt_prior_deg``, ``height_prior_m``.
        rng: Random generator of the samples.
        prior_pose: (3,) the camera pose the motion predicts from a recent pose, if any.
        scene: ``index.nearest_scene_points`` of the descriptors: the matches to the
            database's scene points (those of dropped classes too).
        min_inliers: least inliers (default: ``absolute_min_inliers``, twice that
            without a prior).
        max_distance: how far from the prior the pose may be, metres (default:
            ``max_jump_m``).
        max_turn: ... and its heading, radians (matches no such pose explains are set
            aside before sampling; default: any heading).
        measured: ``(uv (m, 2), rows (m,))`` scene points measured in the frame by
            their patches (:mod:`.map_search`), with ``scene``: they join the matches
            (and replace a match to the same point).
        huber_px: the refinement's Huber threshold, pixels (default: the inlier
            threshold).

    Returns:
        A :class:`~landmark_localizer.pose.PoseSolution` with no model view
        (``views_used`` 0; its classes those of the inlier points that have one), or
        None.
    """
    if config.absolute_min_inliers <= 0 or len(features) == 0:
        return None
    best, d1, d_other = nearest if scene is None else scene
    xyz = index.points if scene is None else index.scene_xyz
    good = (best >= 0) & (d1 <= config.vote_max_distance) & \
        (d1 < config.absolute_ratio * d_other)
    good &= np.all(np.isfinite(xyz[np.maximum(best, 0)]), axis=1)
    rows = np.flatnonzero(good)
    need = min_inliers or config.absolute_min_inliers * (1 if prior_pose is not None else 2)
    extra = 0 if measured is None or scene is None else len(measured[1])
    if rows.size + extra < need:
        return None
    # One keypoint per class: its nearest.
    order = rows[np.lexsort((d1[rows], best[rows]))]
    first = np.concatenate([[True], np.diff(best[order]) != 0])[:order.size]
    rows = order[first]
    classes = best[rows]
    rays = base_rays(index.frame_camera.unproject(features.keypoints[rows].astype(float)))
    if extra:
        uv, ids = measured
        other = ~np.isin(classes, ids)
        classes = np.concatenate([classes[other], np.asarray(ids, np.int64)])
        rays = np.concatenate([rays[other], base_rays(index.frame_camera.unproject(
            np.asarray(uv, float).reshape(-1, 2)))])
    focal = index.residual_focal
    found = solve_absolute(
        rays, xyz[classes], rng, threshold=config.absolute_threshold_px / focal,
        sigma=0.5 / focal, min_inliers=need,
        min_spread=math.radians(config.absolute_min_spread_deg),
        tilt_prior=math.radians(config.tilt_prior_deg), height_prior=config.height_prior_m,
        prior_pose=prior_pose, max_distance=max_distance or config.max_jump_m,
        max_turn=max_turn, huber=None if huber_px is None else huber_px / focal)
    if found is None:
        return None
    x, y, yaw = (float(v) for v in found.pose)
    estimate = PoseEstimate(x, y, yaw, found.covariance, _spread(rays[found.inliers]),
                            found.rms, 0, True)
    inlier = classes[found.inliers]
    if scene is not None:
        inlier = index.scene_class[inlier]
        inlier = inlier[inlier >= 0]
    return PoseSolution(estimate, np.sort(inlier), 0, found.n_inliers, found.rms * focal)
