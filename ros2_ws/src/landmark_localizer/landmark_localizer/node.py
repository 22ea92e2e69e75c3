"""The localizer as a ROS 2 node: ``ros2 run landmark_localizer localizer --ros-args -p db:=DB``.

Thin glue over :class:`~landmark_localizer.localizer.Localizer`: each camera image is
decoded, checked and given to ``Localizer.step`` with the odometry at its stamp, and
the estimate is published.

Subscribes:
    ``/camera/image_raw`` (``sensor_msgs/Image``) and ``/camera/image_raw/compressed``
    (``sensor_msgs/CompressedImage``), sensor-data QoS with depth 1: frames that arrive
    while one is processed replace each other, never queue (``image_reliable`` makes
    them reliable, for raw images over 0.5 MB); ``/camera/camera_info``
    (checked against the database's camera); ``/odom`` (``nav_msgs/Odometry``,
    optional); ``/initialpose`` (``geometry_msgs/PoseWithCovarianceStamped``, as nav2's
    AMCL: voting is restricted to regions near it).
Publishes:
    ``/localizer/pose`` (``geometry_msgs/PoseStamped``) and
    ``/localizer/pose_with_covariance`` (``PoseWithCovarianceStamped``) in ``map`` with
    the image's stamp; ``/localizer/region`` (``std_msgs/Int32``, -1 when LOST);
    ``/diagnostics`` (state, region, features tracked, latency, switches, drops; 1 Hz);
    ``/localizer/regions`` (``visualization_msgs/MarkerArray``, transient-local);
    ``map -> odom`` on ``/tf`` whenever odometry is present (REP 105, stamped
    ``transform_tolerance`` ahead as AMCL does, and republished every
    ``transform_publish_period`` so that tf users never time out).
Service:
    ``~/reinitialize_global_localization`` (``std_srvs/srv/Empty``, AMCL's name):
    forget the region and vote globally.

Bad input never ends the node: an image that cannot be decoded or does not fit the
camera, a mismatched or changing CameraInfo, non-finite or jumping odometry and stamps
that go back are each logged once (then at most every 10 s with a count) and the frame
or message is dropped; a stamp more than a second back (a bag that loops) resets the
state. A database that is missing, of a newer version or damaged ends the node at
start-up with ``localizer: error: ...`` on stderr and exit code 2.

One thread spins a single-threaded executor and only files messages: odometry and
CameraInfo into their buffers, each image into a one-slot mailbox (a newer image
replaces one not yet taken: counted as dropped, ``overrun``). A worker thread takes the
newest image, waits briefly for the odometry of its stamp and runs the localizer. The
executor thus never holds a long callback: rclpy's multi-threaded executor, given a
callback group busy with a frame, re-polls its wait set in Python without pause and
took a whole core and most of the GIL from the frame it waited for (48 s of CPU over
a 49 s replay of ``bags/room_run``, of which the localizer used 3 s; 65 of 439 frames
processed).
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable
import ctypes
from dataclasses import asdict, dataclass, fields
import re
import sys
import threading
import time
from typing import Any

import numpy as np

from landmark_localizer.config import LocalizerConfig
from landmark_localizer.errors import LocalizerError
from vbn_common.ros_tools.node_main import run_node

__all__ = ['IMAGE_TOPICS', 'Mailbox', 'NodeSettings', 'config_descriptions', 'main']

#: The image topics (fixed by the design, as the builder's).
IMAGE_TOPICS = ('/camera/image_raw', '/camera/image_raw/compressed')
#: A stamp this far back or further is a new run of time (a looping bag): reset.
RESET_BACK_NS = 1_000_000_000
#: Odometry is extrapolated at most this far past its newest message.
ODOM_MAX_EXTRAPOLATION_S = 0.1
#: An image newer than the newest odometry waits at most this long for the odometry of
#: its stamp (which arrives on another topic, often a moment later), as tf2's message
#: filter waits for a transform.
ODOM_WAIT_S = 0.1
#: How long ``destroy_node`` waits for the frame being processed.
WORKER_JOIN_S = 5.0
#: Frames in the latency window of /diagnostics.
LATENCY_WINDOW = 200
#: Seconds of images without any CameraInfo before the node says it uses the database's
#: camera (CameraInfo and the first image arrive in either order).
CAMERA_INFO_GRACE_S = 2.0
#: A repeated warning is logged again at most this often, with a count.
WARN_REPEAT_S = 10.0
#: glibc's ``M_ARENA_MAX`` (malloc.h) and the arenas the node allows.
_M_ARENA_MAX, _ARENAS = -8, 2


@dataclass(frozen=True)
class NodeSettings:
    """The node's own parameters (the core's are :class:`LocalizerConfig`'s).

    Attributes:
        db: The landmark database file (required).
        tf_broadcast: Broadcast ``map -> odom`` on ``/tf`` (AMCL's parameter).
        transform_tolerance: How far ahead of the image's (or latest odometry's) stamp
            the ``map -> odom`` transform is stamped, seconds (AMCL's parameter).
        transform_publish_period: Republish the last ``map -> odom`` this often, seconds
            (0 disables republishing).
        global_frame_id: The map frame.
        odom_frame_id: The odometry frame.
        base_frame_id: The robot's frame.
        odom_max_jump_m: Consecutive odometry poses further apart than this are a jump:
            the odometry history restarts.
        image_reliable: Subscribe to the images reliable (still depth 1) instead of best
            effort; for raw images over 0.5 MB, which Fast DDS drops between processes when
            best effort (rmw_fastrtps issue 739); needs a reliable publisher.
    """

    db: str = ''
    tf_broadcast: bool = True
    transform_tolerance: float = 0.1
    transform_publish_period: float = 0.1
    global_frame_id: str = 'map'
    odom_frame_id: str = 'odom'
    base_frame_id: str = 'base_link'
    odom_max_jump_m: float = 1.0
    image_reliable: bool = False

    def __post_init__(self) -> None:
        for name in ('transform_tolerance', 'transform_publish_period', 'odom_max_jump_m'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise LocalizerError(f'{name} must be a finite number >= 0, got {value}')
        frames = (self.global_frame_id, self.odom_frame_id, self.base_frame_id)
        if not all(frames) or len(set(frames)) != 3:
            raise LocalizerError(f'global_frame_id, odom_frame_id and base_frame_id must be '
                                 f'three different names, got {frames}')


def config_descriptions(cls: type = LocalizerConfig) -> dict[str, str]:
    """Return each field's description from a dataclass's ``Attributes:`` docstring."""
    doc = cls.__doc__ or ''
    section = doc.split('Attributes:', 1)[-1]
    out: dict[str, str] = {}
    name = None
    for line in section.splitlines():
        match = re.match(r'^ {8}(\w+): (.*)$', line)
        if match:
            name = match.group(1)
            out[name] = match.group(2).strip()
        elif name and line.startswith(' ' * 12):
            out[name] += ' ' + line.strip()
        elif line.strip():
            name = None
    return {f.name: out.get(f.name, '') for f in fields(cls)}


class Warnings:
    """Log each kind of problem once, then at most every ``repeat_s`` with a count.

    Args:
        log: Where a line goes (the node logger's ``warning``).
        repeat_s: Least time between two lines of the same kind.
        clock: Monotonic seconds (injectable for tests).
    """

    def __init__(self, log: Callable[[str], Any], repeat_s: float = WARN_REPEAT_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.log, self.repeat_s, self.clock = log, repeat_s, clock
        self._last: dict[str, float] = {}
        self._since: dict[str, int] = {}

    def warn(self, kind: str, text: str) -> bool:
        """Log ``text`` unless ``kind`` was logged within ``repeat_s``; say whether logged."""
        now = self.clock()
        last = self._last.get(kind)
        if last is not None and now - last < self.repeat_s:
            self._since[kind] = self._since.get(kind, 0) + 1
            return False
        more = self._since.pop(kind, 0)
        self._last[kind] = now
        self.log(text + (f' ({more} more since the last warning)' if more else ''))
        return True


def reason_kind(text: str) -> str:
    """Return a warning's kind: its text without numbers (one warning per kind)."""
    return re.sub(r'[0-9.]+', '#', text)


class FrameStats:
    """What /diagnostics reports about the frames: counts, drops by reason, latency.

    The executor thread and the frame worker both write it, the diagnostics timer reads
    it: drops and latencies go through a lock (each count has one writer).
    """

    def __init__(self, window: int = LATENCY_WINDOW) -> None:
        self.received = 0
        self.processed = 0
        self.poses = 0
        self.dropped: dict[str, int] = {}
        self.latency: deque[float] = deque(maxlen=window)
        self._lock = threading.Lock()

    def drop(self, reason: str) -> None:
        """Count a dropped frame."""
        with self._lock:
            self.dropped[reason] = self.dropped.get(reason, 0) + 1

    def dropped_counts(self) -> dict[str, int]:
        """Return a copy of the drops by reason."""
        with self._lock:
            return dict(self.dropped)

    def add_latency(self, seconds: float) -> None:
        """Add one processed frame's latency to the window."""
        with self._lock:
            self.latency.append(seconds)

    def latency_ms(self) -> dict[str, float]:
        """p50, p95 and max of the per-frame latency over the window, milliseconds."""
        with self._lock:
            values = np.fromiter(self.latency, float) * 1e3
        if not len(values):
            return {'latency_p50_ms': float('nan'), 'latency_p95_ms': float('nan'),
                    'latency_max_ms': float('nan')}
        p50, p95 = np.percentile(values, [50, 95])
        return {'latency_p50_ms': float(p50), 'latency_p95_ms': float(p95),
                'latency_max_ms': float(values.max())}


class Mailbox:
    """One slot between the executor (``put``) and the frame worker (``take``).

    A ``put`` while the slot is full replaces the waiting item and returns it (the caller
    counts it as dropped): the worker always gets the newest frame and nothing queues.
    """

    def __init__(self) -> None:
        self._ready = threading.Condition()
        self._item: Any = None
        self._full = False
        self._closed = False

    def put(self, item: Any) -> tuple[bool, Any]:
        """Leave ``item``; return ``(replaced, the replaced item or None)``."""
        with self._ready:
            replaced, old = self._full, self._item
            self._item, self._full = item, True
            self._ready.notify()
        return replaced, old

    def take(self, timeout: float | None = None) -> tuple[bool, Any]:
        """Wait for an item; ``(False, None)`` once closed (or after ``timeout``)."""
        with self._ready:
            self._ready.wait_for(lambda: self._full or self._closed, timeout=timeout)
            if not self._full or self._closed:
                return False, None
            item, self._item, self._full = self._item, None, False
            return True, item

    def close(self) -> None:
        """Wake the worker for good: every later ``take`` returns ``(False, None)``."""
        with self._ready:
            self._closed = True
            self._ready.notify_all()


def limit_malloc_arenas(arenas: int = _ARENAS) -> bool:
    """Share at most ``arenas`` glibc malloc arenas between all threads; say if it took.

    glibc gives threads their own arenas (up to 8 per core). When frames were processed
    on two executor threads in turn, freed memory was left scattered over several arenas
    and the node's resident memory grew by a quarter over 10,000 frames (239 to 301 MiB);
    with two arenas it stayed flat (1.02x). The frame worker and the executor thread still
    allocate both, so the cap stays (tests/integration/test_localizer_node.py checks
    10,000 frames). Elsewhere than glibc this does nothing.
    """
    try:
        libc = ctypes.CDLL(None)
        return bool(libc.mallopt(_M_ARENA_MAX, arenas))
    except (OSError, AttributeError):
        return False


def main(args: list[str] | None = None) -> int:
    """Run the localizer node until Ctrl-C; 2 on a start-up error (one line on stderr)."""
    limit_malloc_arenas()
    return run_node('localizer', _make_node, args)


def _make_node() -> Any:
    """Create the node (imports rclpy and the messages only once the environment is OK)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
    from nav_msgs.msg import Odometry
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.exceptions import ParameterException
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, CompressedImage, Image
    from std_msgs.msg import Int32
    from std_srvs.srv import Empty
    from visualization_msgs.msg import MarkerArray

    from landmark_db.database import open_database
    from landmark_localizer import conversions
    from landmark_localizer.index import DatabaseIndex
    from landmark_localizer.localizer import TRACKING, Frame, Localizer
    from landmark_localizer.odometry import ACCEPTED, JUMP, TIME_BACK, OdometryBuffer
    from vbn_common.geometry.transforms import StampedTransform, correction
    from vbn_common.images import ImageDecodeError, decode_image
    from vbn_common.ros_tools.markers import LATCHED_QOS, region_markers
    from vbn_common.ros_tools.tf_broadcast import TransformBroadcaster

    class LocalizerNode(Node):
        """Declares the parameters, opens the database, localizes each image."""

        def __init__(self) -> None:
            super().__init__('localizer')
            self.settings, config = self._read_parameters()
            database = open_database(self.settings.db)
            self.index = DatabaseIndex(database)
            self.localizer = Localizer(self.index, config)
            self.camera = self.index.camera
            self.log = self.get_logger()
            self.warnings = Warnings(self.log.warning)
            self.stats = FrameStats()
            self.lock = threading.Lock()  # odometry, camera info, transform
            self.odom_arrived = threading.Condition(self.lock)
            self.odometry = OdometryBuffer(max_jump_m=self.settings.odom_max_jump_m,
                                           max_extrapolation_s=ODOM_MAX_EXTRAPOLATION_S)
            self.odom_restarted = False
            self.camera_info_seen = False
            self.camera_problem = ''
            self.camera_key: tuple | None = None
            self.first_image: float | None = None
            self.last_stamp: int | None = None
            self.transform: StampedTransform | None = None
            self.estimate = None
            # The localizer is stepped by the worker and reset or hinted by callbacks.
            self.localizer_lock = threading.Lock()
            self.frames = Mailbox()
            self.last_received: int | None = None  # stamp of the last image filed

            frame_qos = QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=1, durability=DurabilityPolicy.VOLATILE,
                reliability=ReliabilityPolicy.RELIABLE if self.settings.image_reliable else
                ReliabilityPolicy.BEST_EFFORT)
            # Best effort matches reliable and best-effort publishers alike (drivers use
            # both); a lost odometry or camera-info message only widens a gap.
            sensor_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=50,
                                    reliability=ReliabilityPolicy.BEST_EFFORT)
            self.pose_pub = self.create_publisher(PoseStamped, '/localizer/pose', 10)
            self.pose_cov_pub = self.create_publisher(
                PoseWithCovarianceStamped, '/localizer/pose_with_covariance', 10)
            self.region_pub = self.create_publisher(Int32, '/localizer/region', 10)
            self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
            self.markers_pub = self.create_publisher(MarkerArray, '/localizer/regions',
                                                     LATCHED_QOS)
            self.tf = TransformBroadcaster(self) if self.settings.tf_broadcast else None
            self.create_subscription(Odometry, '/odom', self._guarded('/odom', self._on_odom),
                                     sensor_qos)
            self.create_subscription(CameraInfo, '/camera/camera_info',
                                     self._guarded('/camera/camera_info', self._on_camera_info),
                                     sensor_qos)
            self.create_subscription(Image, IMAGE_TOPICS[0], self._on_image, frame_qos)
            self.create_subscription(CompressedImage, IMAGE_TOPICS[1], self._on_image,
                                     frame_qos)
            self.create_subscription(PoseWithCovarianceStamped, '/initialpose',
                                     self._guarded('/initialpose', self._on_initial_pose), 10)
            self.create_service(Empty, '~/reinitialize_global_localization',
                                self._on_reinitialize)
            if self.tf is not None and self.settings.transform_publish_period > 0:
                self.create_timer(self.settings.transform_publish_period,
                                  self._republish_transform)
            self.create_timer(1.0, self._publish_diagnostics)
            self.markers_pub.publish(region_markers(
                database, frame_id=self.settings.global_frame_id,
                stamp=self.get_clock().now().to_msg()))
            camera = self.camera
            self.log.info(
                f'localizer ready: {self.settings.db}: {database.n_regions} regions, '
                f'k={self.index.k}, {self.index.n_classes} classes, camera {camera.width}x'
                f'{camera.height} {camera.kind}; listening on {", ".join(IMAGE_TOPICS)}')
            self.worker = threading.Thread(target=self._work, name='localizer-frames',
                                           daemon=True)
            self.worker.start()

        def destroy_node(self) -> None:
            self.frames.close()
            if self.worker.is_alive():
                self.worker.join(timeout=WORKER_JOIN_S)
            super().destroy_node()

        # -- parameters ------------------------------------------------------------------
        def _read_parameters(self) -> tuple[NodeSettings, LocalizerConfig]:
            described = {**config_descriptions(NodeSettings),
                         **config_descriptions(LocalizerConfig)}
            described['db'] += ' (-p db:=FILE)'
            values: dict[str, Any] = {}
            defaults = {**asdict(NodeSettings()), **LocalizerConfig().as_dict()}
            for name, default in defaults.items():
                try:
                    self.declare_parameter(name, default, ParameterDescriptor(
                        description=described.get(name, '')))
                    values[name] = self.get_parameter(name).value
                except ParameterException as error:
                    raise LocalizerError(f'parameter {name}: {error}'.splitlines()[0]) \
                        from None
            node_names = {f.name for f in fields(NodeSettings)}
            settings = NodeSettings(**{k: v for k, v in values.items() if k in node_names})
            if not settings.db:
                raise LocalizerError('parameter db is required (-p db:=FILE)')
            config = LocalizerConfig().with_values(
                {k: v for k, v in values.items() if k not in node_names})
            return settings, config

        # -- inputs ----------------------------------------------------------------------
        def _guarded(self, topic: str, callback: Callable[[Any], None]
                     ) -> Callable[[Any], None]:
            """Return ``callback`` that logs what it raises instead of ending the node."""
            def guarded(msg: Any) -> None:
                try:
                    callback(msg)
                except Exception as error:  # noqa: BLE001 - a node reports, it does not die
                    if self.context.ok():
                        text = f'{type(error).__name__}: {error}'.splitlines()[0]
                        self.warnings.warn(f'{topic}:{reason_kind(text)}',
                                           f'{topic}: message ignored: {text}')
            return guarded

        def _on_odom(self, msg: Any) -> None:
            frames = (msg.header.frame_id, msg.child_frame_id)
            wanted = (self.settings.odom_frame_id, self.settings.base_frame_id)
            if any(got and got != want for got, want in zip(frames, wanted, strict=True)):
                self.warnings.warn('odom_frames', f'/odom is {frames[0]} -> {frames[1]}, '
                                   f'expected {wanted[0]} -> {wanted[1]}: ignored')
                return
            try:
                stamp, pose = conversions.odometry_pose(msg)
            except LocalizerError as error:
                stamp, pose = conversions.stamp_to_ns(msg.header.stamp), np.full(3, np.nan)
                self.warnings.warn('odom_bad', f'/odom: {error}: ignored, odometry history '
                                   'restarted')
            with self.lock:
                result = self.odometry.add(stamp, pose)
                if result != ACCEPTED:
                    self.odom_restarted = True
                self.odom_arrived.notify_all()
            if result == JUMP:
                self.warnings.warn('odom_jump', f'/odom jumped by more than '
                                   f'{self.settings.odom_max_jump_m:g} m: odometry history '
                                   'restarted')
            elif result == TIME_BACK:
                self.warnings.warn('odom_back', '/odom stamps went back: odometry history '
                                   'restarted')

        def _on_camera_info(self, msg: Any) -> None:
            # Bytes, so that a NaN equals itself and an unchanged CameraInfo is one check.
            key = (int(msg.width), int(msg.height), str(msg.distortion_model),
                   np.asarray(msg.k, float).tobytes(), np.asarray(msg.d, float).tobytes())
            with self.lock:
                self.camera_info_seen = True
                if key == self.camera_key:
                    return
                changed = self.camera_key is not None
                self.camera_key = key
                problem = conversions.camera_mismatch(msg, self.camera)
                was = self.camera_problem
                self.camera_problem = problem
            if problem:
                prefix = 'CameraInfo changed: ' if changed else ''
                self.warnings.warn('camera:' + reason_kind(problem),
                                   f'{prefix}{problem}: frames are dropped until it matches')
            elif was:
                self.log.info('CameraInfo matches the database camera again: frames resume')

        def _on_initial_pose(self, msg: Any) -> None:
            try:
                x, y, radius = conversions.initial_pose_hint(
                    msg, self.settings.global_frame_id, self.localizer.config.hint_radius_m)
            except LocalizerError as error:
                self.warnings.warn('initialpose:' + reason_kind(str(error)),
                                   f'/initialpose: {error}: ignored')
                return
            with self.localizer_lock:
                self.localizer.set_hint(x, y, radius)
            self.log.info(f'/initialpose ({x:.2f}, {y:.2f}): voting among the regions '
                          f'within {radius:.2f} m')

        def _on_reinitialize(self, _request: Any, response: Any) -> Any:
            with self.localizer_lock:
                self.localizer.reset()
            self.log.info('reinitialize_global_localization: region forgotten, voting '
                          'globally')
            return response

        # -- one frame -------------------------------------------------------------------
        def _drop(self, reason: str, text: str) -> None:
            self.stats.drop(reason)
            self.warnings.warn(f'{reason}:{reason_kind(text)}', f'frame dropped: {text}')

        def _on_image(self, msg: Any) -> None:
            """File the image for the worker (the executor never waits for a frame)."""
            start = time.perf_counter()
            self.stats.received += 1
            try:
                stamp = conversions.stamp_to_ns(msg.header.stamp)
            except Exception as error:  # noqa: BLE001 - a node reports, it does not die
                self._drop('error', f'{type(error).__name__}: {error}'.splitlines()[0])
                return
            if stamp == self.last_received:
                self.stats.drop('repeated_stamp')  # the same frame on both topics
                return
            self.last_received = stamp
            replaced, _ = self.frames.put((msg, start))
            if replaced:
                self.stats.drop('overrun')  # a newer frame came before it was taken

        def _work(self) -> None:
            """Localize the newest filed image, frame after frame, until the node ends."""
            while True:
                ok, item = self.frames.take()
                if not ok:
                    return
                msg, start = item
                try:
                    self._process(msg, start)
                except Exception as error:  # noqa: BLE001 - a node reports, it does not die
                    if not self.context.ok():
                        return  # shutting down: the publishers are gone
                    self._drop('error', f'{type(error).__name__}: {error}'.splitlines()[0])

        def _process(self, msg: Any, start: float) -> None:
            stamp = conversions.stamp_to_ns(msg.header.stamp)
            if self.last_stamp is not None and stamp <= self.last_stamp:
                back = self.last_stamp - stamp
                if back == 0:
                    self.stats.drop('repeated_stamp')  # the same frame on both topics
                    return
                if back < RESET_BACK_NS:
                    self._drop('stamp_went_back', f'stamp {stamp * 1e-9:.3f} s is '
                               f"{back * 1e-9:.3f} s older than the last frame's")
                    return
                self.log.warning(f'time went back by {back * 1e-9:.1f} s (a bag that '
                                 'loops?): state reset, voting again')
                with self.lock:
                    self.transform = None
            with self.lock:
                problem, seen = self.camera_problem, self.camera_info_seen
                restarted, self.odom_restarted = self.odom_restarted, False
            if problem:
                self.stats.drop('camera_info')  # said once when the CameraInfo came
                return
            if self.first_image is None:
                self.first_image = start
            if not seen and start - self.first_image >= CAMERA_INFO_GRACE_S:
                self.warnings.warn('no_camera_info', 'no CameraInfo on /camera/camera_info: '
                                   f'assuming the database camera {self.camera.width}x'
                                   f'{self.camera.height} {self.camera.kind}')
            try:
                image = decode_image(msg)
            except ImageDecodeError as error:
                self._drop('decode', str(error))
                return
            shape = (self.camera.height, self.camera.width)
            if image.shape != shape:
                self._drop('size', f'image is {image.shape[1]}x{image.shape[0]}, the '
                           f'database camera {shape[1]}x{shape[0]}')
                return
            odom = self._odometry_at(stamp)
            self.last_stamp = stamp
            with self.localizer_lock:
                if restarted:
                    self.localizer.reset_motion()
                estimate = self.localizer.step(Frame(stamp, image, odom))
            self.estimate = estimate
            self.stats.processed += 1
            self._publish(estimate, odom)
            self.stats.add_latency(time.perf_counter() - start)

        def _odometry_at(self, stamp: int) -> np.ndarray | None:
            def arrived() -> bool:
                latest = self.odometry.latest_stamp
                return latest is None or latest >= stamp

            with self.odom_arrived:
                latest = self.odometry.latest_stamp
                if latest is not None and 0 < stamp - latest <= \
                        ODOM_MAX_EXTRAPOLATION_S * 1e9:
                    self.odom_arrived.wait_for(arrived, timeout=ODOM_WAIT_S)
                return self.odometry.at(stamp)

        def _publish(self, estimate: Any, odom: np.ndarray | None) -> None:
            self.region_pub.publish(Int32(data=int(estimate.region)))
            messages = conversions.pose_messages(estimate, self.settings.global_frame_id)
            if messages is None:
                return
            self.pose_pub.publish(messages[0])
            self.pose_cov_pub.publish(messages[1])
            self.stats.poses += 1
            if odom is None or self.tf is None:
                return
            s = self.settings
            stamp = estimate.stamp_ns
            x, y, yaw = (float(v) for v in estimate.pose)
            map_to_base = StampedTransform.planar(stamp, s.global_frame_id, s.base_frame_id,
                                                  x, y, yaw)
            odom_to_base = StampedTransform.planar(stamp, s.odom_frame_id, s.base_frame_id,
                                                   *(float(v) for v in odom))
            transform = correction(map_to_base, odom_to_base,
                                   stamp + int(s.transform_tolerance * 1e9))
            with self.lock:
                self.transform = transform
            self.tf.send(transform)

        # -- periodic --------------------------------------------------------------------
        def _republish_transform(self) -> None:
            with self.lock:
                transform, latest = self.transform, self.odometry.latest_stamp
            if transform is None or latest is None:
                return
            stamp = max(transform.stamp_ns,
                        latest + int(self.settings.transform_tolerance * 1e9))
            self.tf.send(StampedTransform(stamp, transform.parent, transform.child,
                                          transform.translation, transform.rotation))

        def _publish_diagnostics(self) -> None:
            loc = self.localizer
            state = loc.state
            estimate = self.estimate
            with self.lock:
                problem = self.camera_problem
                odometry = 'yes' if len(self.odometry) else 'no'
            values: dict[str, Any] = {
                'state': state,
                'region': loc.region if state == TRACKING else -1,
                'tracked': estimate.tracked if estimate is not None else 0,
                'frames_received': self.stats.received,
                'frames_processed': self.stats.processed,
                'poses_published': self.stats.poses,
                **self.stats.latency_ms(),
                'predicted_switches': loc.stats.predicted_switches,
                'switches_after_loss': loc.stats.lost_switches,
                'falls_to_lost': loc.stats.falls_to_lost,
                'votes': loc.stats.votes,
                'resets': loc.stats.resets,
                'odometry': odometry,
                'camera_info': problem or ('matches' if self.camera_key else 'none'),
                'frames_dropped': sum(self.stats.dropped_counts().values()),
            }
            dropped = self.stats.dropped_counts()
            values.update({f'dropped_{k}': v for k, v in sorted(dropped.items())})
            level = DiagnosticStatus.OK if state == TRACKING and not problem else \
                DiagnosticStatus.WARN
            message = f'TRACKING region {loc.region}' if state == TRACKING else 'LOST'
            if problem:
                message += '; CameraInfo does not match the database'
            self.diag_pub.publish(conversions.diagnostic_array(
                self.get_clock().now().to_msg(), 'localizer', self.settings.db, level,
                message, values))

    return LocalizerNode()


if __name__ == '__main__':
    sys.exit(main())
