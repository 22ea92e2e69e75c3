"""Bundle adjustment of the estimated poses with odometry factors (beyond the thesis).

Section 6.1 fits rotations, then positions, to pairwise motions: each
pair's motion is a summary of its matches, and the two fits never see the points
themselves. The refinement minimises the reprojection errors of every track (a chain
of pairwise inlier matches: a connected component, at most one feature per image) over all
image poses and all points at once, with

- the odometry as relative-pose factors between consecutive images (its standard
  deviations as in :class:`~.pipeline.EstimationSettings`: the scale comes from it),
- for a robot on a floor, the planar constraint: each pose's height, roll and pitch held
  at zero by a tight prior (its position and heading free),
- the first image's pose fixed (the ``map`` frame of :mod:`.pipeline`).

**Library: GTSAM** (``gtsam`` 4.3, pinned in ``requirements.in``), chosen over
pycolmap's bundle adjustment and pyceres because its factors are what this problem is:
``BetweenFactorPose3`` for odometry and ``PriorFactorPose3`` for the planar constraint
come with it, and its projection factor runs in C++ (pyceres's Python cost functions and
GTSAM's ``CustomFactor`` call Python per residual). COLMAP has no model for a cylindrical
panorama. Every camera model of the project is reduced to unit rays (``unproject``), and
each ray is measured by GTSAM's ``GenericProjectionFactorCal3_S2`` through a virtual
pinhole on the body (``body_P_sensor``) that looks along the nearest of eight azimuths:
the rays of a panorama, a fisheye or a pinhole all become pinhole measurements within
22.5 degrees of a virtual optical axis, in pixels of the real camera's angular
resolution. Residuals are robust (Huber, ``huber_px``); the first solve's residuals
measure the keypoints' noise, observations more than ``outlier_sigmas`` of it off are
removed and the problem solved again with that noise.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from vbn_common.geometry.camera import CameraModel, pixels_per_radian
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION
from vbn_common.geometry.rays import intersect_rays
from visibility_builder.errors import VisibilityBuilderError

__all__ = ['GeneralRefinement', 'RefinementResult', 'RefinementSettings', 'refine_general',
           'refine_poses', 'tracks_from_pairs']

#: Virtual sensors: one per this many degrees of azimuth.
SECTOR_DEG = 45.0


@dataclass(frozen=True)
class RefinementSettings:
    """Settings of :func:`refine_poses`.

    Attributes:
        min_views: Fewest images of a track for it to enter.
        min_angle_deg: Smallest angle between a track's rays (its triangulation).
        huber_px: Huber threshold of the reprojection errors, pixels (first solve).
        outlier_px: Observations further off after the first solve are removed.
        noise_px: Standard deviation of a measured keypoint, pixels (first solve).
        min_noise_px: The second solve takes the keypoints' noise measured on the
            first's residuals, at least this and at most ``noise_px``...
        huber_sigmas: ... its Huber threshold this many of that noise...
        outlier_sigmas: ... and removes observations further off than this many of it
            (and ``outlier_px``). With a fixed 3 px on rendered images (0.2 px of
            noise), an observation of a wrong match 1 to 3 px off stayed and turned the
            room's headings: 0.017 deg median against 0.009 deg this way.
        planar: Hold heights, rolls and pitches at zero (a robot on a floor).
        tilt_std: With ``planar``, the rolls and pitches are held only this loosely
            (radians; a shaking camera), and the odometry's factors hold their changes
            from one image to the next at twice it; None holds them at zero.
        max_iterations: Levenberg-Marquardt iterations per solve.
    """

    min_views: int = 3
    min_angle_deg: float = 2.0
    huber_px: float = 1.5
    outlier_px: float = 3.0
    noise_px: float = 0.7
    min_noise_px: float = 0.1
    huber_sigmas: float = 2.0
    outlier_sigmas: float = 3.0
    planar: bool = True
    tilt_std: float | None = None
    max_iterations: int = 50


@dataclass(frozen=True)
class RefinementResult:
    """Refined poses.

    Attributes:
        camera_poses: ``(n, 3)`` planar camera poses ``(x, y, heading)`` in ``map``.
        tracks: Tracks used.
        observations: Observations used in the final solve.
        removed: Observations removed as outliers.
        rms_px: RMS reprojection error of the final solve, pixels.
        error_before: Total graph error at the start.
        error_after: ... at the end.
    """

    camera_poses: np.ndarray
    tracks: int
    observations: int
    removed: int
    rms_px: float
    error_before: float
    error_after: float


def tracks_from_pairs(n_features: list[int], pair_views: np.ndarray,
                      pair_features: list[np.ndarray]) -> tuple[np.ndarray, int]:
    """Join pairwise matches into tracks; drop tracks seen twice in one image.

    A track is a connected component of the graph of matched features.

    Args:
        n_features: Features per image.
        pair_views: ``(p, 2)`` the images of each pair.
        pair_features: Per pair, ``(k, 2)`` matched feature indices.

    Returns:
        ``(track, image, feature)`` rows as ``(m, 3)`` int64, and the number of tracks.
    """
    offsets = np.concatenate([[0], np.cumsum(n_features)]).astype(np.int64)
    total = int(offsets[-1])
    edges = [np.stack([offsets[a] + f[:, 0], offsets[b] + f[:, 1]], axis=1)
             for (a, b), f in zip(pair_views, pair_features, strict=True) if len(f)]
    if not edges:
        return np.zeros((0, 3), np.int64), 0
    edges = np.concatenate(edges)
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(total, total))
    _, roots = connected_components(graph, directed=False)
    used = np.zeros(total, bool)
    used[edges.ravel()] = True
    nodes = np.flatnonzero(used)
    image = np.searchsorted(offsets, nodes, side='right') - 1
    feature = nodes - offsets[image]
    _, track = np.unique(roots[nodes], return_inverse=True)
    # A track with two features of one image joined two different points: drop it.
    key = track * (len(n_features) + 1) + image
    keys, counts = np.unique(key, return_counts=True)
    doubled = np.unique(track[np.isin(key, keys[counts > 1])])
    keep = ~np.isin(track, doubled)
    track, image, feature = track[keep], image[keep], feature[keep]
    _, track = np.unique(track, return_inverse=True)
    return np.stack([track, image, feature], axis=1), int(track.max() + 1) if len(track) else 0


def _sensor_rotation(azimuth: float) -> np.ndarray:
    """Rotation of a virtual optical sensor looking along ``azimuth`` into the body frame."""
    c, s = math.cos(azimuth), math.sin(azimuth)
    yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return yaw @ BASE_TO_CAMERA_ROTATION   # optical into planar, then turned


def refine_poses(camera_poses: np.ndarray, observations: np.ndarray, rays: np.ndarray,
                 camera: CameraModel, odometry: tuple[np.ndarray, np.ndarray, np.ndarray],
                 settings: RefinementSettings = RefinementSettings()) -> RefinementResult:
    """Bundle-adjust planar camera poses and track points (module docstring).

    Args:
        camera_poses: ``(n, 3)`` initial ``(x, y, heading)`` of each camera.
        observations: ``(m, 2)`` ``(track, image)`` of each observation.
        rays: ``(m, 3)`` the observed unit rays in the camera's planar frame (``x``
            forward, ``y`` left, ``z`` up).
        camera: The camera (its angular resolution scales the pixels).
        odometry: ``(pairs (k, 2), relative poses (k, 3) of camera j in camera i's
            frame, standard deviations (k, 3) of x, y, yaw)``.
        settings: See :class:`RefinementSettings`.

    Returns:
        The refined poses and the solve's figures.
    """
    import gtsam

    poses = np.asarray(camera_poses, float)
    n = len(poses)
    observations = np.asarray(observations, np.int64).reshape(-1, 2)
    rays = np.asarray(rays, float).reshape(-1, 3)
    if len(observations) != len(rays):
        raise VisibilityBuilderError('observations and rays differ in length')
    if not np.all(np.isfinite(poses)):
        raise VisibilityBuilderError('every camera needs an initial pose to be refined')
    focal = pixels_per_radian(camera)
    # Triangulate the tracks from the initial poses; keep the well-conditioned ones.
    n_tracks = int(observations[:, 0].max()) + 1 if len(observations) else 0
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    img = observations[:, 1]
    world = np.stack([c[img] * rays[:, 0] - s[img] * rays[:, 1],
                      s[img] * rays[:, 0] + c[img] * rays[:, 1], rays[:, 2]], axis=1)
    centres = np.concatenate([poses[img, :2], np.zeros((len(img), 1))], axis=1)
    points = intersect_rays(world, centres, observations[:, 0], n_tracks)
    views = np.bincount(observations[:, 0], minlength=n_tracks)
    spread = np.zeros(n_tracks)
    mean_dir = np.zeros((n_tracks, 3))
    np.add.at(mean_dir, observations[:, 0], world)
    mean_dir /= np.maximum(np.linalg.norm(mean_dir, axis=1, keepdims=True), 1e-12)
    np.maximum.at(spread, observations[:, 0],
                  np.arccos(np.clip(np.einsum('ij,ij->i', world,
                                              mean_dir[observations[:, 0]]), -1, 1)))
    good = (views >= settings.min_views) & np.isfinite(points).all(axis=1) & \
        (2 * spread >= math.radians(settings.min_angle_deg))
    # In front of each ray (positive depth), within a pixel budget of it: an observation
    # that is not is left out (its track stays, with enough others).
    to_point = points[observations[:, 0]] - centres
    depth = np.einsum('ij,ij->i', to_point, world)
    miss = np.linalg.norm(np.cross(to_point, world), axis=1) / np.maximum(depth, 1e-9)
    fits = (depth > 0) & (miss * focal <= 4 * settings.outlier_px)
    good &= np.bincount(observations[fits, 0], minlength=n_tracks) >= settings.min_views
    use = good[observations[:, 0]] & fits
    if not use.any():
        raise VisibilityBuilderError('no track seen well enough to refine the poses')
    X = gtsam.symbol_shorthand.X
    L = gtsam.symbol_shorthand.L
    calibration = gtsam.Cal3_S2(focal, focal, 0.0, 0.0, 0.0)
    sensors = [gtsam.Pose3(gtsam.Rot3(_sensor_rotation(math.radians(k * SECTOR_DEG))),
                           np.zeros(3)) for k in range(int(round(360 / SECTOR_DEG)))]

    def pose3(p: np.ndarray) -> object:
        return gtsam.Pose3(gtsam.Rot3.Rz(float(p[2])), np.array([p[0], p[1], 0.0]))

    def build(active: np.ndarray, noise_px: float, huber_px: float) -> tuple[object, object]:
        noise = gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Huber.Create(huber_px / noise_px),
            gtsam.noiseModel.Isotropic.Sigma(2, noise_px))
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        for i in range(n):
            values.insert(X(i), pose3(poses[i]))
        for t in np.flatnonzero(good):
            values.insert(L(int(t)), points[t])
        for k in np.flatnonzero(active):
            ray = rays[k]
            azimuth = math.atan2(ray[1], ray[0])
            sector = int(round(azimuth / math.radians(SECTOR_DEG))) % len(sensors)
            sensor_r = _sensor_rotation(math.radians(sector * SECTOR_DEG))
            local = sensor_r.T @ ray
            if local[2] <= 0.2:
                continue
            uv = focal * local[:2] / local[2]
            graph.add(gtsam.GenericProjectionFactorCal3_S2(
                uv, noise, X(int(observations[k, 1])), L(int(observations[k, 0])),
                calibration, sensors[sector]))
        pairs, relative, sigmas = odometry
        for (a, b), rel, sig in zip(pairs, relative, sigmas, strict=True):
            tilt = 1e-3 if settings.tilt_std is None else 2.0 * settings.tilt_std
            model = gtsam.noiseModel.Diagonal.Sigmas(
                np.array([tilt, tilt, sig[2], sig[0], sig[1], 1e-3]))
            graph.add(gtsam.BetweenFactorPose3(X(int(a)), X(int(b)), pose3(rel), model))
        if settings.planar:
            tilt = 1e-5 if settings.tilt_std is None else settings.tilt_std
            flat = gtsam.noiseModel.Diagonal.Sigmas(np.array([tilt, tilt, 1e3, 1e3, 1e3, 1e-5]))
            for i in range(n):
                graph.add(gtsam.PriorFactorPose3(X(i), pose3(poses[i]), flat))
        tilt0 = 1e-6 if settings.tilt_std is None else settings.tilt_std
        graph.add(gtsam.PriorFactorPose3(X(0), pose3(poses[0]), gtsam.noiseModel.Diagonal.Sigmas(
            np.array([tilt0, tilt0, 1e-6, 1e-6, 1e-6, 1e-6]))))
        return graph, values

    def solve(active: np.ndarray, noise_px: float = settings.noise_px,
              huber_px: float = settings.huber_px) -> tuple[object, object, float, float]:
        graph, values = build(active, noise_px, huber_px)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(settings.max_iterations)
        before = graph.error(values)
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        return graph, result, before, graph.error(result)

    _, result, before, _ = solve(use)
    # Remove the observations still far off, solve again from the start.
    refined_points = np.array([result.atPoint3(L(int(t))) if good[t] else np.full(3, np.nan)
                               for t in range(n_tracks)])
    errors = _pixel_errors(result, observations, rays, refined_points, focal, X)
    # The keypoints' noise measured on the first solve (the median length of a 2-D
    # Gaussian error is 1.177 sigma) sets the second's weights and thresholds.
    measured = float(np.median(errors[use])) / 1.177 if use.any() else settings.noise_px
    noise_px = min(max(measured, settings.min_noise_px), settings.noise_px)
    keep = use & (errors <= min(settings.outlier_px, settings.outlier_sigmas * noise_px))
    graph, result, _, after = solve(keep, noise_px, min(settings.huber_px,
                                                        settings.huber_sigmas * noise_px))
    refined_points = np.array([result.atPoint3(L(int(t))) if good[t] else np.full(3, np.nan)
                               for t in range(n_tracks)])
    errors = _pixel_errors(result, observations, rays, refined_points, focal, X)
    rms = float(np.sqrt(np.mean(errors[keep] ** 2))) if keep.any() else math.nan
    out = np.zeros((n, 3))
    for i in range(n):
        p = result.atPose3(X(i))
        out[i] = [p.x(), p.y(), p.rotation().yaw()]
    return RefinementResult(out, int(good.sum()), int(keep.sum()), int((use & ~keep).sum()),
                            rms, float(before), float(after))


def _pixel_errors(result: object, observations: np.ndarray, rays: np.ndarray,
                  points: np.ndarray, focal: float, key: object) -> np.ndarray:
    """Angle between each observed ray and its refined point, in pixels."""
    n = int(observations[:, 1].max()) + 1
    poses = np.zeros((n, 3))
    for i in range(n):
        p = result.atPose3(key(i))
        poses[i] = [p.x(), p.y(), p.rotation().yaw()]
    img = observations[:, 1]
    d = points[observations[:, 0]] - np.concatenate([poses[img, :2],
                                                     np.zeros((len(img), 1))], axis=1)
    c, s = np.cos(poses[img, 2]), np.sin(poses[img, 2])
    local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
    local /= np.maximum(np.linalg.norm(local, axis=1, keepdims=True), 1e-12)
    cos = np.einsum('ij,ij->i', local, rays)
    out = np.arccos(np.clip(cos, -1.0, 1.0)) * focal
    return np.where(np.isfinite(out), out, np.inf)


@dataclass(frozen=True)
class GeneralRefinement:
    """Refined six-degree-of-freedom camera poses (:func:`refine_general`).

    Attributes:
        rotations: ``(n, 3, 3)`` each camera's planar frame into the world.
        centres: ``(n, 3)`` camera centres.
        observations: Observations in the final solve.
        rms_px: Their RMS reprojection error, pixels.
    """

    rotations: np.ndarray
    centres: np.ndarray
    observations: int
    rms_px: float


def refine_general(rotations: np.ndarray, centres: np.ndarray, observations: np.ndarray,
                   uv: np.ndarray, camera: CameraModel, solved: np.ndarray,
                   noise_px: float = 1.0, huber_px: float = 2.0, outlier_sigmas: float = 3.0,
                   max_iterations: int = 50) -> GeneralRefinement:
    """Bundle-adjust general camera poses (a hand-held camera) and their tracks' points.

    The cameras' own pixels are the measurements (a pinhole camera's
    ``GenericProjectionFactorCal3_S2`` with the optical frame on the body as
    ``body_P_sensor``). The first solved camera is held; a weak prior on the position of
    the camera farthest from it (a tenth of their distance) holds the scale, which
    nothing else fixes. As in :func:`refine_poses`, the first solve's residuals measure
    the keypoints' noise and the second removes observations beyond ``outlier_sigmas``
    of it.

    Args:
        rotations: ``(n, 3, 3)`` initial planar-frame-into-world rotations.
        centres: ``(n, 3)`` initial camera centres.
        observations: ``(m, 2)`` ``(track, image)``.
        uv: ``(m, 2)`` the observed pixels.
        camera: A pinhole camera (no distortion).
        solved: ``(n,)`` bool, the cameras to refine (the others are left out).
        noise_px: Keypoint noise of the first solve, pixels.
        huber_px: Its Huber threshold.
        outlier_sigmas: Observations beyond this many measured sigmas are removed.
        max_iterations: Levenberg-Marquardt iterations per solve.

    Returns:
        The refined poses (the unsolved cameras as they came).

    Raises:
        VisibilityBuilderError: not a pinhole camera, or no track seen twice.
    """
    import gtsam

    if camera.kind != 'pinhole':
        raise VisibilityBuilderError(f'refine_general needs a pinhole camera, got {camera.kind}')
    rotations = np.asarray(rotations, float)
    centres = np.asarray(centres, float)
    observations = np.asarray(observations, np.int64).reshape(-1, 2)
    uv = np.asarray(uv, float).reshape(-1, 2)
    solved = np.asarray(solved, bool)
    use = solved[observations[:, 1]]
    n_tracks = int(observations[:, 0].max()) + 1 if len(observations) else 0
    img = observations[:, 1]
    planar_rays = camera.unproject(uv) @ BASE_TO_CAMERA_ROTATION.T
    world = np.einsum('mij,mj->mi', rotations[img], planar_rays)
    points = intersect_rays(world, centres[img], observations[:, 0], n_tracks,
                            np.bincount(observations[use, 0], minlength=n_tracks) >= 2)
    depth = np.einsum('ij,ij->i', points[observations[:, 0]] - centres[img], world)
    use &= np.isfinite(depth) & (depth > 0)
    good = np.bincount(observations[use, 0], minlength=n_tracks) >= 2
    use &= good[observations[:, 0]]
    if not use.any():
        raise VisibilityBuilderError('no track seen twice to refine the poses')
    X = gtsam.symbol_shorthand.X
    L = gtsam.symbol_shorthand.L
    calibration = gtsam.Cal3_S2(camera.fx, camera.fy, 0.0, camera.cx, camera.cy)
    sensor = gtsam.Pose3(gtsam.Rot3(BASE_TO_CAMERA_ROTATION), np.zeros(3))
    cams = np.flatnonzero(solved)
    n_cams = len(solved)
    anchor = int(cams[0])
    far = int(cams[np.argmax(np.linalg.norm(centres[cams] - centres[anchor], axis=1))])
    spread = float(np.linalg.norm(centres[far] - centres[anchor]))

    def pose3(i: int) -> object:
        return gtsam.Pose3(gtsam.Rot3(rotations[i]), centres[i])

    def solve(active: np.ndarray, sigma: float, huber: float) -> object:
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(
            huber / sigma), gtsam.noiseModel.Isotropic.Sigma(2, sigma))
        for i in cams:
            values.insert(X(int(i)), pose3(int(i)))
        for t in np.flatnonzero(good):
            values.insert(L(int(t)), points[t])
        for k in np.flatnonzero(active):
            graph.add(gtsam.GenericProjectionFactorCal3_S2(
                uv[k], noise, X(int(img[k])), L(int(observations[k, 0])), calibration,
                sensor))
        graph.add(gtsam.PriorFactorPose3(X(anchor), pose3(anchor),
                                         gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
        if far != anchor:
            graph.add(gtsam.PriorFactorPose3(X(far), pose3(far), gtsam.noiseModel.Diagonal.Sigmas(
                np.array([1e3, 1e3, 1e3] + [0.1 * spread] * 3))))
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(max_iterations)
        return gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()

    def errors(result: object) -> np.ndarray:
        """Pixel distance of each used observation from its point's projection (else inf)."""
        optical = np.zeros((n_cams, 3, 3))          # optical axes into the world
        centre = np.zeros((n_cams, 3))
        for i in cams:
            pose = result.atPose3(X(int(i)))
            optical[i] = pose.rotation().matrix() @ BASE_TO_CAMERA_ROTATION
            centre[i] = pose.translation()
        point = np.full((n_tracks, 3), np.nan)
        for t in np.flatnonzero(good):
            point[t] = result.atPoint3(L(int(t)))
        local = np.einsum('mji,mj->mi', optical[img], point[observations[:, 0]] - centre[img])
        with np.errstate(invalid='ignore', divide='ignore'):
            projected = np.stack([camera.fx * local[:, 0] / local[:, 2] + camera.cx,
                                  camera.fy * local[:, 1] / local[:, 2] + camera.cy], axis=1)
            out = np.linalg.norm(projected - uv, axis=1)
        return np.where(use & (local[:, 2] > 0) & np.isfinite(out), out, np.inf)

    result = solve(use, noise_px, huber_px)
    first = errors(result)
    measured = float(np.median(first[use])) / 1.177
    sigma = min(max(measured, 0.1), noise_px)
    keep = use & (first <= outlier_sigmas * sigma)
    result = solve(keep, sigma, 2.0 * sigma)
    final = errors(result)
    out_r, out_c = rotations.copy(), centres.copy()
    for i in cams:
        pose = result.atPose3(X(int(i)))
        out_r[i] = pose.rotation().matrix()
        out_c[i] = pose.translation()
    seen = keep & np.isfinite(final)          # an observation behind its camera is not
    rms = float(np.sqrt(np.mean(final[seen] ** 2))) if seen.any() else math.nan
    return GeneralRefinement(out_r, out_c, int(keep.sum()), rms)
