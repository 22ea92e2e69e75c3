"""Turn renders into rosbag2 MCAP bags: exploration, run and kidnapped run.

Topics and frames (fixed by the design):

==============================  =============================  ==========================
topic                           type                           when
==============================  =============================  ==========================
``/camera/image_raw``           ``sensor_msgs/Image``          every image (raw)
``/camera/image_raw/compressed`` ``sensor_msgs/CompressedImage`` every image (compressed)
``/camera/camera_info``         ``sensor_msgs/CameraInfo``     every image
``/ground_truth/pose``          ``geometry_msgs/PoseStamped``  every image, frame ``map``
``/odom``                       ``nav_msgs/Odometry``          runs and driven explorations,
                                                               50 Hz, frame ``odom``
``/tf``                         ``tf2_msgs/TFMessage``         see below
``/tf_static``                  ``tf2_msgs/TFMessage``         once, ``base_link -> camera``
==============================  =============================  ==========================

``/tf`` holds ``map -> base_link`` (ground truth) at every image of an exploration
bag. In a run bag it holds ``odom -> base_link`` with every odometry message and
``map -> odom`` at every image, chosen so that ``map -> odom -> base_link`` is the
ground truth at the image times (a perfect localizer's output). Images, camera
info and ground truth carry frame ``camera`` / ``map`` and the same stamp as
their bag time; every header stamp equals the message's bag timestamp.

A driven exploration (``odometry``: :mod:`.exploration_drive`) records what a real
robot records: ``/odom`` and ``odom -> base_link`` on ``/tf`` at 50 Hz from the wheels
(:mod:`.odometry`, its errors scaled by ``drift``), the images taken standing, and
``/ground_truth/pose`` at every image for judging; no ``map`` frame on ``/tf``.

Exploration: the robot stops at every pose of :func:`~.grid.exploration_poses`
(one per second) and records one panorama at yaw 0, or pinhole images at evenly
spaced headings, turning in place (:func:`default_headings`: four, 0.25 s apart, like
the thesis's Room 408 data set, Section 8.3.2; ``headings`` N gives N). Runs:
:mod:`.trajectory`, images at 10 Hz, odometry from :mod:`.odometry` at 50 Hz.

Everything is deterministic in the scene, the seed and the parameters: the bag
clock starts at :data:`START_NS`, and every random draw comes from a generator
seeded with ``seed`` (and the frame index, for per-frame image effects).
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
import logging
import math
from pathlib import Path

import numpy as np

from landmark_db.scene import Scene
from vbn_common import names
from vbn_common.bags import BagWriter, default_qos, messages
from vbn_common.geometry.camera import CameraModel, make_camera
from vbn_common.geometry.frames import compose_poses, invert_pose
from vbn_common.geometry.mount import tilt_matrix, tilted
from vbn_worlds.errors import WorldsError
from vbn_worlds.render.effects import ImageEffects
from vbn_worlds.render.lens_view import make_renderer
from vbn_worlds.render.textures import build_wall_atlas
from vbn_worlds.synthesis.exploration_drive import (
    DrivenExploration,
    driven_exploration,
    visiting_order,
)
from vbn_worlds.synthesis.grid import exploration_poses
from vbn_worlds.synthesis.odometry import OdometryNoise, simulate_odometry
from vbn_worlds.synthesis.people import walkers
from vbn_worlds.synthesis.trajectory import (
    RunParameters,
    Trajectory,
    kidnapped_trajectory,
    run_trajectory,
)
from vbn_worlds.synthesis.world_changes import WorldChanges

__all__ = ['KINDS', 'START_NS', 'BagSpec', 'BagSummary', 'write_bag']

_LOG = logging.getLogger(__name__)

#: Bag clock origin: 2025-01-01T00:00:00Z, so that bags do not depend on the wall clock.
START_NS = 1_735_689_600 * 1_000_000_000
KINDS = ('exploration', 'run', 'run-kidnapped')
IMAGE_PERIOD_NS = 100_000_000  # 10 Hz
ODOM_PERIOD_NS = 20_000_000  # 50 Hz
POSE_PERIOD_NS = 1_000_000_000  # exploration: one grid pose per second
HEADING_PERIOD_NS = 250_000_000  # pinhole exploration: four headings per pose


@dataclass(frozen=True)
class BagSpec:
    """What to synthesise.

    Attributes:
        kind: ``'exploration'``, ``'run'`` or ``'run-kidnapped'``.
        camera: ``'panoramic'``, ``'pinhole'`` or ``'fisheye'``.
        width: image width, pixels (``None``: the camera's default).
        height: image height, pixels (``None``: the camera's default).
        hfov_deg: horizontal field of view, degrees (``None``: 90 pinhole, 180
            fisheye).
        headings: exploration headings per position (``None``:
            :func:`default_headings`).
        distortion: ``(model, coefficients)`` of the lens (``None``: none).
        camera_pitch_deg: the mount's pitch, degrees (positive: looking up).
        camera_roll_deg: the mount's roll about the optical axis, degrees.
        camera_height: the camera's height above the floor, metres (``None``: the
            scene's).
        vibration_deg: per-frame random pitch and roll of the robot (normal, this
            standard deviation, degrees) on top of the mount; the ground truth pose
            carries them.
        spacing: exploration grid spacing, metres.
        clearance: minimum distance from an exploration pose to a wall, metres.
        seed: seeds odometry noise and image effects.
        encoding: ``'bgr8'`` or ``'mono8'``.
        compression: ``None`` (``sensor_msgs/Image`` on ``/camera/image_raw``) or
            ``'jpeg'``/``'png'`` (``sensor_msgs/CompressedImage`` on
            ``/camera/image_raw/compressed``).
        jpeg_quality: JPEG quality, 1..100.
        effects: per-frame exposure, blur and noise.
        run: planning and timing of runs.
        duration: cut runs after this many seconds (``None``: the whole path).
        odometry_noise: wheel-odometry error model.
        odometry: an exploration driven between its positions, with wheel odometry
            (:mod:`.exploration_drive`), instead of images placed at them.
        drift: multiplies every error of ``odometry_noise`` (0: perfect odometry).
        changes: the world on the day of the recording, when it changed after the
            exploration (:mod:`.world_changes`: furniture, posters, light, people).
        path_seed: varies a run's path (None: ``seed``; 0: the scene's own path).
        rate_hz: a run's camera rate, Hz (50 divided by a whole number: 10, 5, 2, 1).
        slip_bursts: a run's odometry slips (+20 %, :class:`OdometryNoise`) this many
            times, for a second each, at times drawn from ``seed``.
        odom_dropouts: a run's odometry (``/odom`` and ``odom -> base_link``) is missing
            this many times, for a second each, at times drawn from ``seed``.
    """

    kind: str = 'exploration'
    camera: str = 'panoramic'
    width: int | None = None
    height: int | None = None
    hfov_deg: float | None = None
    headings: int | None = None
    distortion: tuple[str, tuple[float, ...]] | None = None
    camera_pitch_deg: float = 0.0
    camera_roll_deg: float = 0.0
    camera_height: float | None = None
    vibration_deg: float = 0.0
    spacing: float = 0.25
    clearance: float = 0.2
    seed: int = 0
    encoding: str = 'bgr8'
    compression: str | None = None
    jpeg_quality: int = 90
    effects: ImageEffects = field(default_factory=ImageEffects)
    run: RunParameters = field(default_factory=RunParameters)
    duration: float | None = None
    odometry_noise: OdometryNoise = field(default_factory=OdometryNoise)
    odometry: bool = False
    drift: float = 1.0
    changes: WorldChanges | None = None
    path_seed: int | None = None
    rate_hz: float = 10.0
    slip_bursts: int = 0
    odom_dropouts: int = 0

    def check(self) -> None:
        """Raise :class:`WorldsError` for an invalid field."""
        if self.kind not in KINDS:
            raise WorldsError(f'unknown bag kind {self.kind!r} '
                                         f'(expected {", ".join(KINDS)})')
        if self.encoding not in ('bgr8', 'mono8'):
            raise WorldsError(f'unknown encoding {self.encoding!r} '
                                         '(expected bgr8 or mono8)')
        if self.compression not in (None, 'jpeg', 'png'):
            raise WorldsError(f'unknown compression {self.compression!r} '
                                         '(expected jpeg or png)')
        if not 1 <= int(self.jpeg_quality) <= 100:
            raise WorldsError(f'JPEG quality must be 1..100, got {self.jpeg_quality}')
        if not (math.isfinite(self.spacing) and self.spacing > 0):
            raise WorldsError(f'spacing must be positive, got {self.spacing}')
        if self.seed < 0:
            raise WorldsError(f'seed must be non-negative, got {self.seed}')
        if self.headings is not None and not 1 <= int(self.headings) <= 72:
            raise WorldsError(f'headings must be 1..72, got {self.headings}')
        if self.odometry and self.kind != 'exploration':
            raise WorldsError('odometry is for explorations (runs always have it)')
        if not (math.isfinite(self.drift) and 0 <= self.drift <= 100):
            raise WorldsError(f'drift must be 0 to 100, got {self.drift}')
        if self.headings is not None and self.kind != 'exploration':
            raise WorldsError('headings are for explorations only')
        per_image = 1e9 / ODOM_PERIOD_NS / self.rate_hz if self.rate_hz > 0 else 0.0
        if not (math.isfinite(per_image) and per_image >= 1
                and abs(per_image - round(per_image)) < 1e-9):
            raise WorldsError(f'rate must be 50 Hz divided by a whole number, '
                                         f'got {self.rate_hz}')
        if self.kind == 'exploration' and (self.rate_hz != 10.0 or self.slip_bursts
                                           or self.odom_dropouts):
            raise WorldsError('rate, slip and odometry dropouts are for runs')
        if not 0 <= self.slip_bursts <= 100 or not 0 <= self.odom_dropouts <= 100:
            raise WorldsError('slip bursts and odometry dropouts must be 0 to 100')
        for name in ('camera_pitch_deg', 'camera_roll_deg'):
            if not (math.isfinite(getattr(self, name)) and abs(getattr(self, name)) <= 45):
                raise WorldsError(f'{name.replace("_deg", "")} must be within 45 '
                                             f'degrees, got {getattr(self, name)}')
        if not (math.isfinite(self.vibration_deg) and 0 <= self.vibration_deg <= 5):
            raise WorldsError(f'vibration must be 0 to 5 degrees, got '
                                         f'{self.vibration_deg}')
        if self.camera_height is not None and not (math.isfinite(self.camera_height)
                                                   and self.camera_height > 0):
            raise WorldsError(f'camera height must be positive, got '
                                         f'{self.camera_height}')
        self.camera_model()

    def scaled_odometry_noise(self) -> OdometryNoise:
        """Return the odometry error model with every error multiplied by ``drift``."""
        noise = self.odometry_noise
        return replace(noise, scale_error=noise.scale_error * self.drift,
                       speed_noise=noise.speed_noise * self.drift,
                       speed_noise_floor=noise.speed_noise_floor * self.drift)

    def mount_tilt(self) -> np.ndarray | None:
        """Return the mount's tilt (:func:`~vbn_common.geometry.mount.tilt_matrix`), or None."""
        if self.camera_pitch_deg == 0 and self.camera_roll_deg == 0:
            return None
        return tilt_matrix(self.camera_pitch_deg, self.camera_roll_deg)

    def camera_model(self) -> CameraModel:
        """Return the camera the bag is rendered through."""
        return make_camera(self.camera, self.width, self.height, self.hfov_deg,
                           self.distortion)

    def exploration_headings(self) -> int:
        """Return the headings per exploration position (:func:`default_headings`)."""
        if self.headings is not None:
            return int(self.headings)
        return default_headings(self.camera)


def default_headings(camera: str) -> int:
    """Return the exploration's headings per position for a camera: 1 for a panorama.

    Otherwise 4, the thesis's Room 408 layout, whose images a build merges into one
    pose per position (``sampling.headings`` 1). The heading pose space
    (``sampling.headings`` 0 or N) joins neighbouring headings, which must then share
    features: headings at most half the field of view apart, e.g. ``headings=8`` for a
    90 degree pinhole.
    """
    return 1 if camera == 'panoramic' else 4


@dataclass
class BagSummary:
    """What a synthesised bag holds.

    Attributes:
        path: the bag directory.
        counts: messages per topic.
        duration_s: time from the first to the last message, seconds.
        images: number of images.
    """

    path: Path
    counts: dict[str, int]
    duration_s: float
    images: int


class _Bag:
    """A BagWriter with the topics of a synthesised bag and per-topic counts."""

    def __init__(self, writer: BagWriter, compressed: bool, run: bool) -> None:
        self.writer = writer
        self.counts: dict[str, int] = {}
        self.image_topic = names.IMAGE_COMPRESSED if compressed else names.IMAGE_RAW
        image_type = 'sensor_msgs/msg/CompressedImage' if compressed else 'sensor_msgs/msg/Image'
        reliable = [default_qos()]
        topics = [(self.image_topic, image_type, reliable),
                  (names.CAMERA_INFO, 'sensor_msgs/msg/CameraInfo', reliable),
                  (names.GROUND_TRUTH_POSE, 'geometry_msgs/msg/PoseStamped', reliable),
                  (names.TF, 'tf2_msgs/msg/TFMessage', [default_qos(depth=100)]),
                  (names.TF_STATIC, 'tf2_msgs/msg/TFMessage',
                   [default_qos(durability='transient_local', depth=1)])]
        if run:
            topics.append((names.ODOM, 'nav_msgs/msg/Odometry', [default_qos(depth=50)]))
        self.connections = {topic: writer.add_topic(topic, msgtype, qos)
                            for topic, msgtype, qos in topics}

    def write(self, topic: str, stamp_ns: int, message: object) -> None:
        self.writer.write(self.connections[topic], stamp_ns, message)
        self.counts[topic] = self.counts.get(topic, 0) + 1


def _camera_frames(spec: BagSpec, scene: Scene) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(stamp_ns, base pose)`` of every exploration image."""
    positions = exploration_poses(scene, spec.spacing, spec.clearance)
    count = spec.exploration_headings()
    headings = [2.0 * math.pi * h / count for h in range(count)]
    period = HEADING_PERIOD_NS if count <= 4 else POSE_PERIOD_NS // count
    for i, (x, y) in enumerate(positions):
        for h, heading in enumerate(headings):
            yaw = math.remainder(heading, 2 * math.pi)
            yield START_NS + i * POSE_PERIOD_NS + h * period, np.array([x, y, yaw])


def write_bag(scene: Scene, spec: BagSpec, out: str | Path,
              progress: Callable[[int, int], None] | None = None) -> BagSummary:
    """Render ``scene`` and write the bag that ``spec`` describes to ``out``.

    Args:
        scene: the scene.
        spec: the bag's kind, camera and parameters.
        out: bag directory to create (must not exist).
        progress: called as ``progress(images_done, images_total)``.

    Returns:
        The summary of what was written.

    Raises:
        WorldsError: invalid parameters, an existing ``out`` or a scene
            that leaves no room for the robot.
    """
    spec.check()
    out = Path(out)
    if out.exists():
        raise WorldsError(f'{out} exists already, not overwriting')
    camera = tilted(spec.camera_model(), spec.mount_tilt())
    if spec.camera_height is not None:
        scene = replace(scene, camera_height=float(spec.camera_height))
    changes = spec.changes or WorldChanges()
    changes.check(scene)
    # The robot goes round the furniture; the renderer draws the new walls.
    drawn, scene = changes.render_scene(scene), changes.planning_scene(scene)
    # Plan before opening the bag: bad input must leave nothing behind.
    driven = None
    if spec.kind == 'exploration' and spec.odometry:
        grid = exploration_poses(scene, spec.spacing, spec.clearance)
        grid = grid[visiting_order(scene, grid, spec.clearance)]
        driven = driven_exploration(scene, grid, spec.exploration_headings(), spec.run,
                                    spec.clearance)
        frames, trajectory = [], driven.trajectory
    elif spec.kind == 'exploration':
        frames = list(_camera_frames(spec, scene))
        trajectory = None
    else:
        trajectory = run_trajectory(scene, spec.run, spec.duration,
                                    spec.seed if spec.path_seed is None else spec.path_seed)
        if spec.kind == 'run-kidnapped':
            trajectory = kidnapped_trajectory(trajectory)
        frames = []
    vibration = float(spec.vibration_deg)
    atlas = None if spec.changes is None else build_wall_atlas(drawn,
                                                               appearance=changes.appearance)
    renderer = make_renderer(drawn, camera, atlas, margin_deg=4.0 * vibration)
    furniture = changes.occluders(scene)
    people = None
    if changes.people:
        last = trajectory.duration if trajectory is not None else \
            (frames[-1][0] - START_NS) / 1e9 if frames else 0.0
        people = walkers(scene, changes.people, changes.seed, last + 1.0)
    mount = np.eye(3) if spec.mount_tilt() is None else spec.mount_tilt()
    info = camera.camera_info()
    with BagWriter(out) as writer:
        bag = _Bag(writer, spec.compression is not None, trajectory is not None)
        bag.write(names.TF_STATIC, START_NS, messages.tf_message(
            [messages.camera_static_transform(START_NS, scene.camera_height,
                                              spec.mount_tilt())]))

        def write_image(index: int, stamp: int, pose: np.ndarray) -> None:
            rng = np.random.default_rng([spec.seed, index])
            shake = None
            if vibration:   # this frame's pitch and roll, within four sigma
                pitch, roll = np.clip(np.random.default_rng([spec.seed, index, 7]).normal(
                    0.0, vibration, 2), -4.0 * vibration, 4.0 * vibration)
                shake = tilt_matrix(float(pitch), float(roll))
            own = {} if shake is None else {'tilt': shake @ mount}   # a lens renderer's
            around = furniture if people is None else \
                furniture + people.occluders((stamp - START_NS) / 1e9, pose[:2])
            image = renderer.render(pose, encoding=spec.encoding, effects=spec.effects, rng=rng,
                                    occluders=around if len(around) else None, **own).image
            if spec.compression is None:
                message = messages.image_message(stamp, image)
            else:
                message = messages.compressed_image_message(stamp, image, spec.compression,
                                                            spec.jpeg_quality)
            bag.write(bag.image_topic, stamp, message)
            bag.write(names.CAMERA_INFO, stamp, messages.camera_info_message(stamp, info))
            bag.write(names.GROUND_TRUTH_POSE, stamp,
                      messages.pose_stamped_message(stamp, pose, tilt=shake))

        if trajectory is None:
            for index, (stamp, pose) in enumerate(frames):
                write_image(index, stamp, pose)
                bag.write(names.TF, stamp, messages.tf_message(
                    [messages.planar_transform(stamp, names.MAP_FRAME, names.BASE_FRAME, pose)]))
                if progress:
                    progress(index + 1, len(frames))
            images = len(frames)
        elif driven is not None:
            images = _write_driven(bag, driven, spec, write_image, progress)
        else:
            images = _write_run(bag, trajectory, spec, write_image, progress)
    duration = 0.0
    if trajectory is not None:
        duration = math.floor(trajectory.duration / 0.02 + 1e-9) * 0.02
    elif frames:
        duration = (frames[-1][0] - START_NS) / 1e9
    _LOG.debug('wrote %s: %d images, %.1f s', out, images, duration)
    return BagSummary(out, dict(sorted(bag.counts.items())), duration, images)


def _write_driven(bag: _Bag, driven: DrivenExploration, spec: BagSpec,
                  write_image: Callable[[int, int, np.ndarray], None],
                  progress: Callable[[int, int], None] | None) -> int:
    """Odometry and ``odom -> base_link`` every 20 ms, each image at its standing tick."""
    odom = simulate_odometry(driven.trajectory, 1e9 / ODOM_PERIOD_NS,
                             spec.scaled_odometry_noise(),
                             np.random.default_rng([spec.seed, 1_000_003]))
    period_s = ODOM_PERIOD_NS / 1e9
    ticks = np.rint(driven.image_times / period_s).astype(np.int64)
    if np.any(np.diff(ticks) <= 0) or ticks[-1] >= len(odom.times):
        raise WorldsError('exploration images closer than the odometry period')
    image_at = {int(t): i for i, t in enumerate(ticks)}
    for k in range(len(odom.times)):  # time order: odometry, then the image at the same stamp
        stamp = START_NS + k * ODOM_PERIOD_NS
        bag.write(names.ODOM, stamp, messages.odometry_message(
            stamp, odom.poses[k], odom.twist[k], odom.pose_variance[k], odom.twist_variance))
        bag.write(names.TF, stamp, messages.tf_message([messages.planar_transform(
            stamp, names.ODOM_FRAME, names.BASE_FRAME, odom.poses[k])]))
        i = image_at.get(k)
        if i is not None:
            write_image(i, stamp, driven.image_poses[i])
            if progress:
                progress(i + 1, len(ticks))
    return len(ticks)


def _write_run(bag: _Bag, trajectory: Trajectory, spec: BagSpec,
               write_image: Callable[[int, int, np.ndarray], None],
               progress: Callable[[int, int], None] | None) -> int:
    faults = np.random.default_rng([spec.seed, 2_000_003])
    slip, missing = (tuple((float(s), float(s) + 1.0) for s in np.sort(faults.uniform(
        0.5, max(trajectory.duration - 1.5, 0.5), n))) for n in (spec.slip_bursts,
                                                                 spec.odom_dropouts))
    odom = simulate_odometry(trajectory, 1e9 / ODOM_PERIOD_NS,
                             replace(spec.odometry_noise, slip=slip),
                             np.random.default_rng([spec.seed, 1_000_003]))
    n_odom = len(odom.times)
    image_period = int(round(1e9 / spec.rate_hz))
    per_image = image_period // ODOM_PERIOD_NS
    n_images = (n_odom - 1) // per_image + 1
    ground_truth = trajectory.pose_at(np.arange(n_images) * image_period / 1e9)
    for k in range(n_odom):  # time order: odometry, then the image at the same stamp
        stamp = START_NS + k * ODOM_PERIOD_NS
        lost = any(start <= odom.times[k] < end for start, end in missing)
        if not lost:
            bag.write(names.ODOM, stamp, messages.odometry_message(
                stamp, odom.poses[k], odom.twist[k], odom.pose_variance[k],
                odom.twist_variance))
        transforms = [] if lost else [messages.planar_transform(
            stamp, names.ODOM_FRAME, names.BASE_FRAME, odom.poses[k])]
        if k % per_image == 0:
            i = k // per_image
            # map -> odom such that map -> odom -> base_link is the ground truth now.
            map_to_odom = compose_poses(ground_truth[i], invert_pose(odom.poses[k]))
            transforms.insert(0, messages.planar_transform(stamp, names.MAP_FRAME,
                                                           names.ODOM_FRAME, map_to_odom))
            bag.write(names.TF, stamp, messages.tf_message(transforms))
            write_image(i, stamp, ground_truth[i])
            if progress:
                progress(i + 1, n_images)
        elif transforms:
            bag.write(names.TF, stamp, messages.tf_message(transforms))
    return n_images
