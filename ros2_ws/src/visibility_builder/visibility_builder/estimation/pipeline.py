"""The poses of an exploration's images from the images and the odometry (thesis 6.1).

Steps (each timed and counted in :class:`PoseEstimation`):

1. **Stations.** Consecutive images whose odometry stands still (within
   ``station_tolerance_m``) were taken at one place: they share one position unknown
   (a robot turning through its headings), each keeps its own rotation.
2. **Features**: SIFT of every image, with the builder's settings.
3. **Pairs, first pass** (Algorithm 6.1, :mod:`.view_pairs`): each image with the
   images of the next ``window`` stations, and with the other images of its station;
   for a camera that does not see all around, only views whose odometry headings are
   within the camera's field of each other. A measured motion that contradicts the
   odometry's (rotation beyond 3 degrees and three of its standard deviations, direction
   beyond 30 degrees) is refused: a planar scene lets a pinhole solver fit a second
   motion as well as the true one (on a pinhole room: rotation errors median 0.96 ->
   0.13 deg, directions 13 -> 0.5 deg).
4. **Rotations** (6.1.3, :mod:`.rotations`) over the measured relative rotations and
   the odometry's turns, robustly (:mod:`.global_fit`: least-absolute angles first for
   a planar robot, then the thesis's least squares over the pairs they keep).
5. **Positions** (6.1.4, :mod:`.positions`): each pair's bearing refitted under the
   fitted turns, carried into the world; the thesis's system, the linear joint system
   with the odometry's displacements between consecutive stations, and (planar) the
   robust non-linear fit of bearings and odometry that the linear fits seed.
   After the first fit its headings calibrate the odometry's wheels (:mod:`.scale`:
   the turns the images measured against the odometry's), and every later fit uses the
   odometry integrated again with them: its distances, and so the estimate's scale.
6. **Pairs, second pass**: the pairs of stations within ``radius_m`` of each other in
   that estimate that the first pass did not try (the exploration's other rows, a
   loop's return) and that lie in one piece of the view graph, measured and checked
   against that estimate, then rotations and positions fitted again over all. Pairs
   between pieces (rooms joined only by the odometry of a drive through a door) are
   judged together instead (:mod:`.linking`: the correction most of them agree on,
   within what the odometry allows), and the second pass is repeated on the joined
   estimate. The odometry's uncertainty follows the path driven and turned between
   images (:mod:`.odometry_path`).
7. **The thesis's own result**: the positions from the directions alone (no odometry
   rows), scaled by the length of the odometry's path, kept beside the joint estimate
   (the robust fit where there is one); the joint estimate is the bundle adjustment's
   start.
8. **Frame**: ``map`` is the odometry's frame at the first image (the first image's
   estimated pose is its odometry pose; REP 105's ``map`` and ``odom`` start equal).

Images are poses of ``base_link``: the camera's planar offset on the base (from the
bag's ``base_link -> camera``) is undone. The result keeps the thesis-only estimate,
the pairs with the reason each was dropped, and per-step times.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
import logging
import math
import os
import time

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.exploration import Exploration, ReadConfig, read_exploration
from vbn_common.features import ImageFeatures, SiftConfig, extract_many
from vbn_common.geometry.frames import (
    BASE_TO_CAMERA_ROTATION,
    compose_poses,
    invert_pose,
    wrap_angle,
)
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.estimation.global_fit import TILT_STD, fit_views
from visibility_builder.estimation.linking import join_pieces, link_candidates, near_pairs
from visibility_builder.estimation.odometry_path import (
    read_track,
    step_stds,
    straight_steps,
    track_steps,
)
from visibility_builder.estimation.refinement import (
    RefinementResult,
    RefinementSettings,
    refine_poses,
    tracks_from_pairs,
)
from visibility_builder.estimation.rotations import matrix_to_quat, quat_yaw
from visibility_builder.estimation.scale import (
    WheelCalibration,
    calibrate_wheels,
    recalibrated_poses,
    signed_motion,
    turn_sigmas,
)
from visibility_builder.estimation.view_pairs import PairMotion, PairSettings, measure_pair

__all__ = ['EstimationSettings', 'PoseEstimation', 'estimate_from_odometry', 'estimate_poses',
           'estimated_exploration', 'matrix_to_quat']

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class EstimationSettings:
    """Settings of :func:`estimate_poses`.

    Attributes:
        pairs: Matching and two-view settings.
        sift: SIFT settings (the builder's).
        window: First pass: each station is paired with the next ``window`` stations.
        radius_m: Second pass: stations this close in the first estimate are paired.
        link_radius_m: Views of different pieces this close in the estimate are paired
            and the pairs judged together (:mod:`.linking`).
        link_rounds: At most this many rounds of joining pieces.
        station_tolerance_m: Consecutive images whose odometry moved less are one place.
        odometry_std_per_m: Standard deviation of an odometry displacement per metre.
        odometry_std_floor_m: ... added to every displacement, metres.
        odometry_turn_std: Standard deviation of an odometry turn per radian turned.
        odometry_yaw_drift_std: ... per metre driven, radians.
        odometry_yaw_floor: ... added to every turn, radians.
        max_rotation_error_deg: A pair whose rotation misses the fit by more than
            this, four of its standard deviations and four robust standard deviations
            of all pairs' misses is dropped.
        max_direction_error_deg: A pair whose direction misses the fitted positions by
            more is dropped.
        refine: Bundle-adjust the result (:mod:`.refinement`).
        refinement: Its settings.
        wheel_calibration: Calibrate the odometry's wheels by the images' turns
            (:mod:`.scale`); off for an odometry whose heading is not its wheels'.
        workers: Processes for the feature extraction (None: every core).
    """

    pairs: PairSettings = PairSettings()
    sift: SiftConfig = SiftConfig(n_octave_layers=5, precise_upscale=True)
    window: int = 4
    radius_m: float = 0.75
    link_radius_m: float = 2.5
    link_rounds: int = 3
    station_tolerance_m: float = 0.01
    odometry_std_per_m: float = 0.02
    odometry_std_floor_m: float = 0.002
    odometry_turn_std: float = 0.02
    odometry_yaw_drift_std: float = 0.01
    odometry_yaw_floor: float = 0.002
    max_rotation_error_deg: float = 0.05
    max_direction_error_deg: float = 10.0
    refine: bool = True
    refinement: RefinementSettings = RefinementSettings()
    wheel_calibration: bool = True
    workers: int | None = None

    def __post_init__(self) -> None:
        if self.window < 1:
            raise VisibilityBuilderError(f'window must be at least 1, got {self.window}')
        for name in ('radius_m', 'link_radius_m', 'station_tolerance_m', 'odometry_std_per_m',
                     'odometry_std_floor_m', 'odometry_turn_std', 'odometry_yaw_floor',
                     'max_rotation_error_deg', 'max_direction_error_deg'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise VisibilityBuilderError(f'{name} must be positive, got {value}')


@dataclass
class PoseEstimation:
    """What :func:`estimate_poses` found.

    Attributes:
        base_poses: ``(n, 3)`` ``(x, y, yaw)`` of ``base_link`` in ``map`` per image:
            the bundle adjustment's (:mod:`.refinement`), or :attr:`unrefined_poses`
            without it.
        unrefined_poses: :attr:`thesis_poses` when the directions fix every image,
            else :attr:`joint_poses`.
        thesis_poses: the poses from the directions alone (6.1.4 as written), scaled
            by the odometry's path length.
        joint_poses: the poses from the directions and the odometry's displacements in
            one system (held where the directions leave views free; less accurate
            where both reach: the odometry's errors enter, measured 1.5 cm median
            against 0.1 cm on the room).
        odometry_poses: ``(n, 3)`` the odometry's poses of the images in ``map``.
        stations: ``(n,)`` the place index of each image.
        pairs: Every measured pair.
        kept_rotation: ``(len(pairs),)`` bool, pairs the final rotation fit kept.
        kept_direction: ``(len(pairs),)`` bool, pairs the final position fit kept.
        tried: Pairs tried per pass, ``{'first': .., 'second': ..}``.
        refused: Count of pairs refused per reason.
        times: Seconds per step.
        components: Station components the pairs join (the largest is estimated).
        refinement: The bundle adjustment's figures (None without it).
        warnings: What the estimate had to work round (a tilting camera).
        pieces: ``(n,)`` each image's piece of the view graph (0: the largest).
        wheels: The odometry's calibration by the images' turns (None: no odometry
            stream, or not asked for).
    """

    base_poses: np.ndarray
    thesis_poses: np.ndarray
    joint_poses: np.ndarray
    unrefined_poses: np.ndarray
    odometry_poses: np.ndarray
    stations: np.ndarray
    pairs: list[PairMotion]
    kept_rotation: np.ndarray
    kept_direction: np.ndarray
    tried: dict[str, int] = field(default_factory=dict)
    refused: dict[str, int] = field(default_factory=dict)
    times: dict[str, float] = field(default_factory=dict)
    components: list[int] = field(default_factory=list)
    refinement: RefinementResult | None = None
    warnings: list[str] = field(default_factory=list)
    pieces: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    wheels: WheelCalibration | None = None


def _stations(odom: np.ndarray, tolerance: float) -> np.ndarray:
    station = np.zeros(len(odom), np.int64)
    start = 0
    for k in range(1, len(odom)):
        if np.linalg.norm(odom[k, :2] - odom[start, :2]) > tolerance:
            start = k
            station[k] = station[k - 1] + 1
        else:
            station[k] = station[k - 1]
    return station


def _field_deg(exploration: Exploration) -> float:
    camera = exploration.camera_model()
    if camera.kind == 'panoramic':
        return 360.0
    hfov = getattr(camera, 'hfov_deg', None)
    if hfov is None:
        info = exploration.camera_info
        hfov = math.degrees(2.0 * math.atan2(0.5 * info.width, info.k[0]))
    return float(hfov)


class _Progress:
    def __init__(self, callback: Callable[[str, int, int], None] | None) -> None:
        self.callback = callback

    def __call__(self, step: str, done: int, total: int) -> None:
        if self.callback is not None:
            self.callback(step, done, total)


def estimate_poses(exploration: Exploration, settings: EstimationSettings = EstimationSettings(),
                   progress: Callable[[str, int, int], None] | None = None,
                   features: list[ImageFeatures] | None = None,
                   steps: np.ndarray | None = None,
                   track: np.ndarray | None = None) -> PoseEstimation:
    """Estimate every image's pose from the images and the odometry (module docstring).

    Args:
        exploration: The exploration read with its odometry as the pose source (its
            ``base_pose`` the odometry's, in ``odom``).
        settings: See :class:`EstimationSettings`.
        progress: Called as ``(step, done, total)``.
        features: The images' SIFT features when already extracted.
        steps: ``(n - 1, 2)`` the path driven (m) and turned (rad) between consecutive
            images (:func:`~.odometry_path.odometry_steps`); None: the straight lines
            between their odometry poses.
        track: ``(m, 4)`` the odometry stream (:func:`~.odometry_path.read_track`) for
            the wheels' calibration (None: none).

    Returns:
        The estimate (see :class:`PoseEstimation`).

    Raises:
        VisibilityBuilderError: fewer than two images, or no pair of images that
            overlap.
    """
    report = _Progress(progress)
    times: dict[str, float] = {}
    n = len(exploration.frames)
    if n < 2:
        raise VisibilityBuilderError(f'{n} image(s): pose estimation needs at least two')
    odom_base = exploration.base_poses()
    odom_cam = exploration.camera_poses()
    mount = compose_poses(invert_pose(odom_base[0]), odom_cam[0])   # camera on the base
    steps = straight_steps(odom_base) if steps is None else np.asarray(steps, float)
    if steps.shape != (n - 1, 2):
        raise VisibilityBuilderError(f'steps: {n} images need ({n - 1}, 2) path lengths and '
                                     f'turnings, got {steps.shape}')
    t = time.perf_counter()
    station = _stations(odom_base, settings.station_tolerance_m)
    times['stations'] = time.perf_counter() - t
    t = time.perf_counter()
    if features is None:
        extracted = extract_many([f.image for f in exploration.frames], settings.sift,
                                 settings.workers,
                                 progress=lambda k, c=[0]: (c.__setitem__(0, c[0] + k),
                                                            report('features', c[0], n)))
        bad = [r for r in extracted if isinstance(r, str)]
        if bad:
            raise VisibilityBuilderError(f'{len(bad)} image(s) cannot be decoded: {bad[0]}')
        features = [r for r in extracted if not isinstance(r, str)]
    times['features'] = time.perf_counter() - t
    camera = exploration.camera_model()
    field_deg = _field_deg(exploration)
    measured: dict[tuple[int, int], PairMotion] = {}
    seen: dict[tuple[int, int], tuple[PairMotion | None, str]] = {}   # every measurement
    verdict: dict[tuple[int, int], str] = {}                          # why refused, or ''
    tried: dict[str, int] = {}

    def raw(pairs: list[tuple[int, int]], name: str) -> list[PairMotion | None]:
        t0 = time.perf_counter()
        todo = [c for c in pairs if c not in seen]
        tried[name] = tried.get(name, 0) + len(todo)
        for k, (i, j) in enumerate(todo):
            seen[(i, j)] = measure_pair(i, j, features[i], features[j], camera, settings.pairs,
                                        moved=bool(station[i] != station[j]))
            report(f'pairs ({name})', k + 1, len(todo))
        times[f'pairs ({name})'] = times.get(f'pairs ({name})', 0.0) + time.perf_counter() - t0
        return [seen[c][0] for c in pairs]

    def measure(candidates: list[tuple[int, int]], name: str, reference: np.ndarray,
                turn_std: np.ndarray, path: np.ndarray) -> None:
        raw([c for c in candidates if c not in measured], name)
        for i, j in candidates:
            if (i, j) in measured:
                continue
            motion, why = seen[(i, j)]
            if motion is not None:
                driven = abs(float(path[j] - path[i]))
                why = _disagrees(motion, compose_poses(invert_pose(reference[i]), reference[j]),
                                 abs(float(turn_std[j] - turn_std[i])),
                                 settings.odometry_std_per_m * driven)
            verdict[(i, j)] = why
            if not why:
                measured[(i, j)] = motion

    # First pass: near in time.
    first = []
    for i in range(n):
        for j in range(i + 1, n):
            gap = station[j] - station[i]
            if gap > settings.window:
                break
            if field_deg < 360.0 and abs(wrap_angle(odom_cam[j, 2] - odom_cam[i, 2])) > \
                    math.radians(field_deg):
                continue
            first.append((i, j))
    # The odometry predicts the motion of images near in time; the gates on the straight
    # lines (on the path driven, a drive through a door opened them: docs/estimation.md).
    along = np.concatenate([np.zeros((1, 2)), np.cumsum(straight_steps(odom_base), axis=0)])
    moved, odo_turn_std = along[:, 0], step_stds(along, settings)[1]   # differences used
    measure(first, 'first', odom_cam, odo_turn_std, moved)
    warnings: list[str] = []
    tilting = _tilting(measured, features, camera, settings) if settings.pairs.method is None \
        else ''
    if tilting:
        # The planar solvers' assumption does not hold: the general one, tilts set free.
        warnings.append(tilting)
        _LOG.warning(tilting)
        settings = replace(settings, pairs=replace(settings.pairs, method='general_essential'),
                           refinement=replace(settings.refinement, tilt_std=TILT_STD))
        measured.clear()
        seen.clear()
        verdict.clear()
        measure(first, 'first', odom_cam, odo_turn_std, moved)
    if not measured:
        raise VisibilityBuilderError('no two images overlap: no pair of images has '
                                     f'{settings.pairs.min_matches} matches that one motion '
                                     'explains')
    def refit(name: str) -> dict:
        t0 = time.perf_counter()
        out = fit_views(n, station, odom_base, mount, measured, settings,
                        (features, camera, settings.pairs), steps)
        times[name] = times.get(name, 0.0) + time.perf_counter() - t0
        return out

    def near_in_space(fit: dict) -> dict:
        # Within a piece each pair is judged against the estimate; between two pieces
        # the estimate is as far off as the odometry, and the pairs are judged together.
        near = near_pairs(fit['camera'], station, settings.radius_m, settings.window,
                          field_deg)
        pieces = fit['pieces']
        measure([c for c in near if pieces[c[0]] == pieces[c[1]]], 'second', fit['camera'],
                np.zeros(n), np.zeros(n))
        return refit('fit (final)')

    # Second pass: near in space in the first estimate.
    fit = refit('fit (first)')
    wheels = None
    if track is not None and settings.wheel_calibration:
        # The first fit's headings calibrate the wheels; every later fit uses them.
        stamps = exploration.stamps_ns()
        wheels = _calibrate(fit, track, stamps, steps)
        if wheels.applied:
            odom_base = recalibrated_poses(track, stamps, odom_base, wheels)
            odom_cam = compose_poses(odom_base, mount)
            steps = steps * np.array([wheels.distance_scale, 1.0])
    step_std = step_stds(steps, settings)
    fit = near_in_space(fit)
    # Pieces joined by the consensus of their pairs (.linking), then near in space again.
    for round_ in range(settings.link_rounds):
        pieces = fit['pieces']
        if int(pieces.max()) == 0:
            break
        candidates = sorted(set(link_candidates(fit['camera'], pieces, settings.link_radius_m,
                                                field_deg=field_deg)) |
                            {c for c in near_pairs(fit['camera'], station, settings.radius_m,
                                                   settings.window, field_deg)
                             if pieces[c[0]] != pieces[c[1]]})
        added = join_pieces(fit['camera'], pieces,
                            [m for m in raw(candidates, 'links') if m is not None],
                            settings.pairs.seed + round_, step_std,
                            lambda c: raw(c, 'one place'), field_deg)
        for c in candidates:
            verdict.setdefault(c, seen[c][1] or 'between pieces: no consensus')
        if not added:
            break
        for motion in added:
            measured[(motion.i, motion.j)] = motion
            verdict[(motion.i, motion.j)] = ''
        fit = near_in_space(refit('fit (final)'))
    refused: dict[str, int] = {}
    for key, why in verdict.items():
        if why and key not in measured:
            reason = why.split(':')[0] if ':' in why else why.split(' ', 1)[-1]
            refused[reason] = refused.get(reason, 0) + 1
    pairs = list(measured.values())
    refined = None
    if settings.refine:
        t = time.perf_counter()
        refined = _refine(fit, pairs, features, camera, odom_cam, settings, steps)
        times['refine'] = time.perf_counter() - t
    joint = np.array([compose_poses(c, invert_pose(mount)) if np.all(np.isfinite(c))
                      else np.full(3, np.nan) for c in fit['camera']])
    thesis = np.array([compose_poses(c, invert_pose(mount)) if np.all(np.isfinite(c))
                       else np.full(3, np.nan) for c in fit['thesis']])
    # The joint fit, or the directions alone where it failed (one frame, not a mix).
    unrefined = joint if np.isfinite(joint).all() else thesis
    base = unrefined
    if refined is not None:
        base = np.array([compose_poses(c, invert_pose(mount)) for c in refined.camera_poses])
    return PoseEstimation(base, thesis, joint, unrefined, odom_base.copy(), station, pairs,
                          fit['kept_rotation'], fit['kept_direction'], tried, refused, times,
                          fit['components'], refined, warnings, fit['pieces'], wheels)


#: A planar solver keeping less than this share of the matches the essential matrix keeps
#: (median over a sample of pairs) means the camera tilts: 0.84 on the level room, 0.58
#: and 0.59 with 1 degree of pitch and roll per image (the room at 0.5 and 0.25 m).
PLANAR_SHARE_RATIO = 0.65


def _tilting(measured: dict[tuple[int, int], PairMotion], features: list[ImageFeatures],
             camera: object, settings: EstimationSettings, sample: int = 40) -> str:
    """Return a warning when the views' motion breaks the planar assumption, else ''.

    Up to ``sample`` measured pairs with a direction (evenly through the exploration) are
    measured again by the essential matrix; the planar solvers' inlier share against the
    general one's, at the median, tells a level camera from one that pitches and rolls
    (a shaking robot, a ramp): the planar model then explains half the matches.
    """
    chosen = [p for p in measured.values() if p.has_direction]
    if len(chosen) < 5 or any(p.method == 'general_essential' for p in chosen):
        return ''
    chosen = [chosen[k] for k in np.unique(np.linspace(0, len(chosen) - 1, sample).astype(int))]
    general = replace(settings.pairs, method='general_essential')
    ratios = []
    for pair in chosen:
        other, _ = measure_pair(pair.i, pair.j, features[pair.i], features[pair.j], camera,
                                general, moved=True)
        if other is not None:
            ratios.append((pair.inliers / pair.matches) / (other.inliers / other.matches))
    if len(ratios) < 5 or float(np.median(ratios)) >= PLANAR_SHARE_RATIO:
        return ''
    return (f'the planar solvers keep {100 * float(np.median(ratios)):.0f} % of the matches '
            f'the essential matrix keeps ({len(ratios)} pairs, median): the camera pitches '
            'or rolls (a shaking robot, a ramp); estimating with the general solver and '
            'free tilts')


#: A measured rotation further than this from the predicted one (and three of the
#: prediction's standard deviations) is refused, degrees; a direction further than
#: ``GATE_DIRECTION_DEG`` from the predicted bearing (pairs predicted 5 cm apart or more).
GATE_TURN_DEG = 3.0
GATE_DIRECTION_DEG = 30.0


def _disagrees(motion: PairMotion, predicted: np.ndarray, turn_std: float,
               position_std: float) -> str:
    """Return why a motion contradicts the predicted relative pose, or ''.

    The prediction is the odometry's (near in time) or the first estimate's, with the
    standard deviations of its turn and of its displacement (metres): the gates widen
    with them (a detour round a wall leaves the odometry's relative pose loose). A planar
    scene (one wall filling a pinhole view) admits a second motion that fits the matches
    as well; the prediction tells them apart.
    """
    theta = float(-quat_yaw(matrix_to_quat(motion.rotation)))
    if abs(float(wrap_angle(theta - predicted[2]))) > max(math.radians(GATE_TURN_DEG),
                                                          3.0 * turn_std):
        return 'rotation against the prediction'
    length = float(np.hypot(predicted[0], predicted[1]))
    if motion.has_direction and length >= 0.05 and 3.0 * position_std < length:
        bearing = math.atan2(motion.direction[1], motion.direction[0])
        gate = max(math.radians(GATE_DIRECTION_DEG), math.asin(3.0 * position_std / length))
        if abs(float(wrap_angle(bearing - math.atan2(predicted[1], predicted[0])))) > gate:
            return 'direction against the prediction'
    return ''


def estimated_exploration(exploration: Exploration, result: PoseEstimation) -> Exploration:
    """Return ``exploration`` with each frame posed by ``result`` (unposed frames dropped).

    ``exploration`` is the one :func:`estimate_poses` read (odometry poses); its camera
    mount carries the estimated base poses to camera poses.
    """
    odom_base = exploration.base_poses()
    odom_cam = exploration.camera_poses()
    mount = compose_poses(invert_pose(odom_base[0]), odom_cam[0])
    frames = []
    for frame, pose in zip(exploration.frames, result.base_poses, strict=True):
        if not np.all(np.isfinite(pose)):
            continue
        camera = compose_poses(pose, mount)
        frames.append(replace(frame, base_pose=tuple(float(v) for v in pose),
                              camera_pose=tuple(float(v) for v in camera)))
    if len(frames) < 2:
        raise VisibilityBuilderError('fewer than two images could be posed from the images '
                                     'and the odometry')
    skipped = dict(exploration.skipped)
    skipped['no_pose'] = skipped.get('no_pose', 0) + len(exploration.frames) - len(frames)
    return replace(exploration, frames=tuple(frames), pose_source='estimated',
                   skipped=skipped)


def estimate_from_odometry(bag: str | os.PathLike[str], read: ReadConfig,
                           workers: int | None, missing: Exception) -> Exploration:
    """Read ``bag``'s images and odometry and pose them (``vbn build`` on a robot's bag).

    ``missing`` is why the bag's own poses could not be read; without odometry either,
    the error says both.
    """
    try:
        odometry = read_exploration(bag, replace(read, pose_source='tf', map_frame='odom'))
    except VbnCommonError as error:
        raise VisibilityBuilderError(f'{missing}; nor odometry (odom -> base_link on /tf) to '
                                     'estimate them from') from error
    _LOG.warning('%s has no poses of its images: estimating them from the images and the '
                 'odometry (thesis 6.1; vbn estimate-poses writes them into a bag once)', bag)
    track = read_track(bag)
    steps = track_steps(track, odometry.stamps_ns(), odometry.base_poses())
    result = estimate_poses(odometry, EstimationSettings(workers=workers), steps=steps,
                            track=track)
    if result.wheels is not None:
        _LOG.info('%s', result.wheels.line())
    return estimated_exploration(odometry, result)


def _calibrate(fit: dict, track: np.ndarray, stamps_ns: np.ndarray,
               steps: np.ndarray) -> WheelCalibration:
    """Calibrate the wheels by the fit's headings over segments inside its largest piece."""
    camera, pieces = np.asarray(fit['camera'], float), np.asarray(fit['pieces'])
    usable = (pieces[:-1] == pieces[1:]) & np.isfinite(camera).all(axis=1)[:-1] & \
        np.isfinite(camera).all(axis=1)[1:]
    wheels = calibrate_wheels(camera[:, 2], signed_motion(track, stamps_ns), usable,
                              turn_sigmas(steps))
    if not wheels.applied:
        _LOG.warning('%s', wheels.line())
    return wheels


def _refine(fit: dict[str, object], pairs: list[PairMotion], features: list[ImageFeatures],
            camera: object, odom_cam: np.ndarray, settings: EstimationSettings,
            steps: np.ndarray) -> RefinementResult | None:
    """Bundle-adjust the fitted camera poses over the kept pairs' tracks and the odometry."""
    start = np.asarray(fit['camera'], float)
    if not np.isfinite(start).all():
        start = np.asarray(fit['thesis'], float)
    if not np.isfinite(start).all():
        _LOG.warning('refinement skipped: some images have no pose to start from')
        return None
    kept = np.asarray(fit['kept_rotation'], bool)
    chosen = [p for p, k in zip(pairs, kept, strict=True) if k and len(p.features)]
    if not chosen:
        return None
    rows, _ = tracks_from_pairs([len(f) for f in features],
                                np.array([(p.i, p.j) for p in chosen], np.int64),
                                [np.asarray(p.features, np.int64).reshape(-1, 2)
                                 for p in chosen])
    if not len(rows):
        return None
    rows = rows[np.argsort(rows[:, 1], kind='stable')]     # image by image
    uv = np.concatenate([features[i].keypoints[rows[rows[:, 1] == i, 2]]
                         for i in range(len(features))])
    rays = camera.unproject(uv.astype(float)) @ BASE_TO_CAMERA_ROTATION.T
    n = len(features)
    rel = np.array([compose_poses(invert_pose(odom_cam[i]), odom_cam[i + 1])
                    for i in range(n - 1)]).reshape(-1, 3)
    sig_xy, sig_yaw = step_stds(steps, settings)
    odometry = (np.stack([np.arange(n - 1), np.arange(1, n)], axis=1), rel,
                np.stack([sig_xy, sig_xy, sig_yaw], axis=1))
    try:
        return refine_poses(start, rows[:, :2], rays, camera, odometry, settings.refinement)
    except VisibilityBuilderError as error:
        _LOG.warning('refinement skipped: %s', error)
        return None
