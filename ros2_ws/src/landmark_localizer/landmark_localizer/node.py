"""The localizer as a ROS 2 lifecycle node (``ros2 run landmark_localizer localizer``).

Thin glue over :class:`~landmark_localizer.localizer.Localizer`: each camera image is
decoded, checked and given to ``Localizer.step`` with the odometry at its stamp, and
the estimate is published. A lifecycle node, as nav2's localization is:

- **configure** reads the parameters, opens and checks the database and creates the
  publishers, subscriptions and the service;
- **activate** starts processing images and publishing (the region markers first);
- **deactivate** stops processing and publishing, keeps the database;
- **cleanup** releases the database and every interface;
- **shutdown** releases everything and ends the process.

With ``autostart`` (the default) the node configures and activates itself, so that
``localizer --ros-args -p db:=DB`` alone localizes; with ``-p autostart:=false`` it waits
for the standard ``lifecycle_msgs`` services (``~/change_state``, ``~/get_state``), as a
nav2 lifecycle manager drives them (``bond_timeout: 0.0``: there is no bond here).

Names are relative to the node's namespace (:mod:`vbn_common.names`): at the root they
are the contract's names, and ``-r __ns:=/robot1`` moves them all.

Subscribes:
    ``camera/image_raw`` (``sensor_msgs/Image``) and ``camera/image_raw/compressed``
    (``sensor_msgs/CompressedImage``), sensor-data QoS with depth 1: frames that arrive
    while one is processed replace each other, never queue (``image_reliable`` makes
    them reliable, for raw images over 0.5 MB); ``camera/camera_info``
    (checked against the database's camera); ``odom`` (``nav_msgs/Odometry``,
    optional); ``initialpose`` (``geometry_msgs/PoseWithCovarianceStamped``, as nav2's
    AMCL: voting is restricted to regions near it).
Publishes:
    ``localizer/pose`` (``geometry_msgs/PoseStamped``) and
    ``localizer/pose_with_covariance`` (``PoseWithCovarianceStamped``) in ``map`` with
    the image's stamp; ``localizer/region`` (``std_msgs/Int32``, -1 when LOST);
    ``diagnostics`` (state, region, features tracked, latency, switches, drops, and the
    pose's ``quality``: ``good`` OK, ``odometry`` WARN, ``lost`` ERROR, with its
    ``position_std_m``, and the ``stale_regions`` whose landmark the world no longer
    shows, :mod:`landmark_localizer.health`; 1 Hz);
    ``localizer/regions`` (``visualization_msgs/MarkerArray``, transient-local);
    ``map -> odom`` on ``tf`` whenever odometry is present (REP 105, stamped
    ``transform_tolerance`` ahead as AMCL does, and republished every
    ``transform_publish_period`` so that tf users never time out).
Service:
    ``~/reinitialize_global_localization`` (``std_srvs/srv/Empty``, AMCL's name):
    forget the region and vote globally.

Parameters (:mod:`landmark_localizer.parameters`) take effect when set at run time, or
are read-only; a bad value is refused with the reason.

Bad input never ends the node: an image that cannot be decoded or does not fit the
camera, a mismatched or changing CameraInfo, non-finite or jumping odometry and stamps
that go back are each logged once (then at most every 10 s with a count) and the frame
or message is dropped; a stamp more than a second back (a bag that loops) resets the
state.

One thread spins a single-threaded executor and only files messages: odometry and
CameraInfo into their buffers, each image into a one-slot mailbox (a newer image
replaces one not yet taken: counted as dropped, ``overrun``). A worker thread, running
while the node is active, takes the newest image, waits briefly for the odometry of its
stamp and runs the localizer. The executor thus never holds a long callback: rclpy's
multi-threaded executor, given a callback group busy with a frame, re-polled its wait
set in Python without pause and took a whole core and most of the GIL from the frame it
waited for (48 s of CPU over a 49 s replay of ``bags/room_run``, 65 of 439 frames).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import math
import threading
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Int32
from std_srvs.srv import Empty
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from landmark_db.database import LandmarkDatabase, open_database
from landmark_localizer import conversions
from landmark_localizer.config import LocalizerConfig
from landmark_localizer.errors import LocalizerError
from landmark_localizer.frame_worker import FrameWorker
from landmark_localizer.frames import pose_quality
from landmark_localizer.index import DatabaseIndex
from landmark_localizer.localizer import TRACKING, Localizer
from landmark_localizer.node_frames import ODOM_MAX_EXTRAPOLATION_S, FrameHandling
from landmark_localizer.node_support import FrameStats, Warnings, reason_kind
from landmark_localizer.odometry import OdometryBuffer
from landmark_localizer.parameters import (
    NodeSettings,
    parameter_specs,
    settings_from_values,
    unknown_parameters,
)
from vbn_common import names
from vbn_common.errors import VbnError
from vbn_common.geometry.transforms import StampedTransform
from vbn_common.names import relative
from vbn_common.ros_tools.markers import LATCHED_QOS, region_markers
from vbn_common.ros_tools.tf_broadcast import TransformBroadcaster

__all__ = ['IMAGE_TOPICS', 'LoadedDatabase', 'LocalizerNode', 'load_database']

#: The image topics at the root namespace (fixed by the design, as the builder's).
IMAGE_TOPICS = names.IMAGE_TOPICS
_SUCCESS, _FAILURE = TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE


@dataclass(frozen=True)
class LoadedDatabase:
    """What a database gives the node: the file, its index and a localizer over it."""

    path: str
    database: LandmarkDatabase
    index: DatabaseIndex
    localizer: Localizer

    def describe(self) -> str:
        """One line: regions, k, classes and camera."""
        camera = self.index.camera
        return (f'{self.path}: {self.database.n_regions} regions, k={self.index.k}, '
                f'{self.index.n_classes} classes, camera {camera.width}x{camera.height} '
                f'{camera.kind}')


def load_database(path: str, config: LocalizerConfig) -> LoadedDatabase:
    """Open, check and index a database; a localizer over it.

    Raises:
        VbnError: the file is missing, of a newer version or damaged.
    """
    database = open_database(path)
    index = DatabaseIndex(database)
    return LoadedDatabase(path, database, index, Localizer(index, config))


class LocalizerNode(FrameHandling, LifecycleNode):
    """Declares the parameters; configured, opens the database; active, localizes.

    Args:
        **kwargs: passed to :class:`rclpy.lifecycle.LifecycleNode` (a test's context).

    Raises:
        LocalizerError: a parameter of the wrong type or an unknown one; with
            ``autostart``, a configuration that fails (its reason).
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('localizer', **kwargs)
        self.log = self.get_logger()
        self.exit_code = 0
        self.warnings = Warnings(self.log.warning)
        self.stats = FrameStats()
        self.lock = threading.Lock()  # odometry, camera info, transform
        self.odom_arrived = threading.Condition(self.lock)
        self.localizer_lock = threading.Lock()  # stepped by the worker, reset by callbacks
        self._declare_parameters()
        self.settings: NodeSettings | None = None
        self.loaded: LoadedDatabase | None = None
        self.active = False
        self.failure = ''
        self._endpoints: list[Any] = []   # subscriptions, services (configure)
        self._own_timers: list[Any] = []      # diagnostics, tf republishing (activate)
        self.tf: TransformBroadcaster | None = None
        self.worker: FrameWorker | None = None
        self.pose_pub = self.pose_cov_pub = self.region_pub = None
        self.diag_pub = self.markers_pub = None
        self._reset_inputs()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._guard_change_state()
        # With autostart a failure is the executable's one line; under a lifecycle
        # manager the node logs it and stays unconfigured.
        self._autostarting = bool(self.get_parameter('autostart').value)
        if self._autostarting:
            if self.trigger_configure() != _SUCCESS:
                raise LocalizerError(self.failure or 'configuration failed')
            if self.trigger_activate() != _SUCCESS:
                raise LocalizerError(self.failure or 'activation failed')
            self._autostarting = False

    # -- parameters ----------------------------------------------------------------------
    def _declare_parameters(self) -> None:
        specs = parameter_specs()
        for spec in specs:
            try:
                self.declare_parameter(spec.name, spec.default, ParameterDescriptor(
                    description=spec.description, read_only=spec.read_only))
            except ParameterException as error:
                raise LocalizerError(f'parameter {spec.name}: {error}'.splitlines()[0]) \
                    from error
        # rclpy keeps this node's -p and --params-file values here; an undeclared one
        # would otherwise be ignored without a word.
        given = getattr(self, '_parameter_overrides', {})
        unknown = unknown_parameters(set(given), {s.name for s in specs})
        if unknown:
            raise LocalizerError(unknown)

    def _values(self, changes: dict[str, Any] | None = None) -> dict[str, Any]:
        values = {s.name: self.get_parameter(s.name).value for s in parameter_specs()}
        values.update(changes or {})
        return values

    def _on_set_parameters(self, parameters: list[Any]) -> SetParametersResult:
        """Check a change and apply it (from the next frame), or refuse it with a reason."""
        changes = {p.name: p.value for p in parameters}
        configured = self.loaded is not None
        try:
            settings, config = settings_from_values(self._values(changes),
                                                    require_db=configured)
        except LocalizerError as error:
            return SetParametersResult(successful=False, reason=str(error))
        if not configured:
            return SetParametersResult(successful=True)   # used at the next configure
        loaded = self.loaded
        if 'db' in changes:     # even the same path: the file may have been rebuilt
            try:
                loaded = load_database(settings.db, config)
            except VbnError as error:
                return SetParametersResult(successful=False, reason=(
                    f'db {settings.db!r} cannot be used ({error}); still using '
                    f'{self.loaded.path}'))
            self.log.info(f'database reloaded: {loaded.describe()}')
        self._apply(settings, config, loaded)
        return SetParametersResult(successful=True)

    def _apply(self, settings: NodeSettings, config: LocalizerConfig,
               loaded: LoadedDatabase) -> None:
        """Use new settings (and maybe a new database) from the next frame on."""
        old = self.settings
        new_database = loaded is not self.loaded
        frames = (settings.global_frame_id, settings.odom_frame_id, settings.base_frame_id)
        if new_database or frames != (old.global_frame_id, old.odom_frame_id,
                                      old.base_frame_id):
            with self.lock:
                self.transform = None   # of the old map or frames: not republished
        with self.localizer_lock:
            if new_database:
                self.loaded = loaded
                self.camera_key, self.camera_problem = None, ''  # re-check the CameraInfo
            loaded.localizer.set_config(config)
        self._warn_unavailable(loaded)
        with self.lock:
            self.odometry.max_jump_m = settings.odom_max_jump_m
        self.settings = settings
        if settings.tf_broadcast and self.tf is None:
            self.tf = TransformBroadcaster(self, topic=relative(names.TF))
        # Switched off, the broadcaster stays (the worker may be sending with it) and
        # is silent: every send checks settings.tf_broadcast.
        if self.active and (old.transform_publish_period != settings.transform_publish_period
                            or old.tf_broadcast != settings.tf_broadcast):
            self._restart_timers()
        if self.active and (new_database or old.global_frame_id != settings.global_frame_id):
            self._publish_markers()

    # -- lifecycle -------------------------------------------------------------------------
    def _guard_change_state(self) -> None:
        """Answer a transition that the current state does not have with ``success=False``.

        This rclpy (Jazzy's wheel) raises ``RCLError: Transition is not registered`` out of
        the ``~/change_state`` service callback, which ends the node (ros2/rclpy#1209,
        fixed upstream by rclpy pull request 1319): a lifecycle manager asking for a
        transition at the wrong time must not take the localizer down.
        """
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        service = self._service_change_state
        original = service.callback

        def change_state(request: Any, response: Any) -> Any:
            try:
                return original(request, response)
            except _rclpy.RCLError:
                label = self._state_machine.current_state[1]
                self.log.warning(f'transition {request.transition.id} '
                                 f'{request.transition.label!r} refused: not possible from '
                                 f'the {label} state')
                response.success = False
                return response

        service.callback = change_state

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Read the parameters, open the database, create the interfaces."""
        try:
            settings, config = settings_from_values(self._values())
            loaded = load_database(settings.db, config)
        except Exception as error:  # noqa: BLE001 - rclpy would swallow it without a word
            self.failure = str(error) if isinstance(error, VbnError) else \
                f'{type(error).__name__}: {error}'.splitlines()[0]
            if not self._autostarting:
                self.log.error(f'configure failed: {error}')
            return _FAILURE
        self.settings, self.loaded = settings, loaded
        self._reset_inputs()
        self._create_interfaces()
        self.log.info(f'localizer configured: {loaded.describe()}')
        self._warn_unavailable(loaded)
        return _SUCCESS

    def _warn_unavailable(self, loaded: LoadedDatabase) -> None:
        """Log what the settings ask of the database that it cannot give (scene points)."""
        if loaded.localizer.tracker.scene.unavailable:
            self.log.warning(f'{loaded.path}: {loaded.localizer.tracker.scene.unavailable}')

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start processing images and publishing."""
        result = super().on_activate(state)
        if result != _SUCCESS:
            return result
        self.worker = FrameWorker(self._process, self._on_worker_error)
        self.active = True
        self._restart_timers()
        self._publish_markers()
        self.log.info(f'localizer ready: {self.loaded.describe()}; listening on '
                      f'{", ".join(self.resolve_topic_name(relative(t)) for t in IMAGE_TOPICS)}')
        return _SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop processing and publishing; the database stays open."""
        self._stop_processing()
        self.log.info('localizer deactivated: images are ignored')
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release the database and every interface."""
        self._release()
        self.log.info('localizer cleaned up: database released')
        return _SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything and end the process once the transition is answered."""
        self._stop_processing()
        self._release()
        self.log.info('localizer shut down')
        self.create_timer(0.05, self._end_process)
        return _SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything after a transition that raised (back to unconfigured)."""
        self.log.error('a lifecycle transition failed: resources released')
        self._stop_processing()
        self._release()
        return _SUCCESS

    def destroy_node(self) -> None:
        """Stop the worker before the node goes."""
        self._stop_processing()
        super().destroy_node()

    def _end_process(self) -> None:
        from rclpy.utilities import try_shutdown
        try_shutdown(context=self.context)

    def _reset_inputs(self) -> None:
        with self.lock:
            jump = self.settings.odom_max_jump_m if self.settings else \
                NodeSettings().odom_max_jump_m
            self.odometry = OdometryBuffer(max_jump_m=jump,
                                           max_extrapolation_s=ODOM_MAX_EXTRAPOLATION_S)
            self.odom_restarted = False
            self.camera_info_seen = False
            self.camera_problem = ''
            self.camera_key: tuple | None = None
            self.mount_tilt = None
            self.transform = None
        self.first_image: float | None = None
        self.last_stamp: int | None = None
        self.last_received: int | None = None
        self.estimate = None

    def _create_interfaces(self) -> None:
        s = self.settings
        frame_qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=1, durability=DurabilityPolicy.VOLATILE,
            reliability=ReliabilityPolicy.RELIABLE if s.image_reliable else
            ReliabilityPolicy.BEST_EFFORT)
        # Best effort matches reliable and best-effort publishers alike (drivers use
        # both); a lost odometry or camera-info message only widens a gap.
        sensor_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=50,
                                reliability=ReliabilityPolicy.BEST_EFFORT)
        publisher = self.create_lifecycle_publisher
        self.pose_pub = publisher(PoseStamped, relative(names.LOCALIZER_POSE), 10)
        self.pose_cov_pub = publisher(PoseWithCovarianceStamped,
                                      relative(names.LOCALIZER_POSE_WITH_COVARIANCE), 10)
        self.region_pub = publisher(Int32, relative(names.LOCALIZER_REGION), 10)
        self.diag_pub = publisher(DiagnosticArray, relative(names.DIAGNOSTICS), 10)
        self.markers_pub = publisher(MarkerArray, relative(names.LOCALIZER_REGIONS),
                                     LATCHED_QOS)
        self.tf = TransformBroadcaster(self, topic=relative(names.TF)) if s.tf_broadcast \
            else None
        sub = self.create_subscription
        self._endpoints = [
            sub(Odometry, relative(names.ODOM), self._guarded(names.ODOM, self._on_odom),
                sensor_qos),
            sub(CameraInfo, relative(names.CAMERA_INFO),
                self._guarded(names.CAMERA_INFO, self._on_camera_info), sensor_qos),
            # The robot's own camera mount (a second robot sharing the database).
            sub(TFMessage, relative(names.TF_STATIC),
                self._guarded(names.TF_STATIC, self._on_tf_static), LATCHED_QOS),
            sub(Image, relative(names.IMAGE_RAW), self._on_image, frame_qos),
            sub(CompressedImage, relative(names.IMAGE_COMPRESSED), self._on_image, frame_qos),
            sub(PoseWithCovarianceStamped, relative(names.INITIAL_POSE),
                self._guarded(names.INITIAL_POSE, self._on_initial_pose), 10),
            self.create_service(Empty, '~/reinitialize_global_localization',
                                self._on_reinitialize),
        ]

    def _restart_timers(self) -> None:
        for timer in list(self._own_timers):
            self.destroy_timer(timer)
        timers = [self.create_timer(1.0, self._publish_diagnostics)]
        period = self.settings.transform_publish_period
        if self.tf is not None and period > 0:
            timers.append(self.create_timer(period, self._republish_transform))
        self._own_timers = timers

    def _stop_processing(self) -> None:
        self.active = False
        for timer in list(self._own_timers):
            self.destroy_timer(timer)
        self._own_timers = []
        if self.worker is not None:
            self.worker.close()
            self.worker = None

    def _release(self) -> None:
        for endpoint in self._endpoints:
            if hasattr(endpoint, 'srv_type'):
                self.destroy_service(endpoint)
            else:
                self.destroy_subscription(endpoint)
        self._endpoints = []
        for name in ('pose_pub', 'pose_cov_pub', 'region_pub', 'diag_pub', 'markers_pub'):
            pub = getattr(self, name, None)
            if pub is not None:
                self.destroy_lifecycle_publisher(pub)
                setattr(self, name, None)
        if self.tf is not None:
            self.tf.destroy()
            self.tf = None
        with self.localizer_lock:
            self.loaded = None
        self._reset_inputs()

    def _publish_markers(self) -> None:
        if self.markers_pub is not None and self.loaded is not None:
            self.markers_pub.publish(region_markers(
                self.loaded.database, frame_id=self.settings.global_frame_id,
                stamp=self.get_clock().now().to_msg()))

    # -- inputs (executor thread) ------------------------------------------------------------
    def topic(self, name: str) -> str:
        """Return a contract topic as this node resolves it (its namespace, remaps)."""
        return self.resolve_topic_name(relative(name))

    def _guarded(self, topic: str, callback: Callable[[Any], None]) -> Callable[[Any], None]:
        """Return ``callback`` that logs what it raises instead of ending the node."""
        def guarded(msg: Any) -> None:
            try:
                callback(msg)
            except Exception as error:  # noqa: BLE001 - a node reports, it does not die
                if self.context.ok():
                    text = f'{type(error).__name__}: {error}'.splitlines()[0]
                    self.warnings.warn(f'{topic}:{reason_kind(text)}',
                                       f'{self.topic(topic)}: message ignored: '
                                       f'{text}')
        return guarded

    def _on_initial_pose(self, msg: Any) -> None:
        loaded = self.loaded
        if loaded is None:
            return
        try:
            x, y, radius = conversions.initial_pose_hint(
                msg, self.settings.global_frame_id, loaded.localizer.config.hint_radius_m)
        except LocalizerError as error:
            self.warnings.warn('initialpose:' + reason_kind(str(error)),
                               f'{self.topic(names.INITIAL_POSE)}: {error}: ignored')
            return
        with self.localizer_lock:
            loaded.localizer.set_hint(x, y, radius)
        self.log.info(f'{self.topic(names.INITIAL_POSE)} ({x:.2f}, {y:.2f}): voting among '
                      f'the regions within {radius:.2f} m')

    def _on_reinitialize(self, _request: Any, response: Any) -> Any:
        with self.localizer_lock:
            if self.loaded is not None:
                self.loaded.localizer.reset()
        self.log.info('reinitialize_global_localization: region forgotten, voting globally')
        return response

    def _on_image(self, msg: Any) -> None:
        """File the image for the worker (the executor never waits for a frame)."""
        worker = self.worker
        if not self.active or worker is None:
            return
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
        if worker.put((msg, start)):
            self.stats.drop('overrun')  # a newer frame came before it was taken

    # -- one frame (worker thread) -----------------------------------------------------------
    def _drop(self, reason: str, text: str) -> None:
        self.stats.drop(reason)
        self.warnings.warn(f'{reason}:{reason_kind(text)}', f'frame dropped: {text}')

    def _on_worker_error(self, error: Exception) -> None:
        if self.context.ok() and self.active:
            self._drop('error', f'{type(error).__name__}: {error}'.splitlines()[0])

    def _process(self, item: tuple[Any, float]) -> None:
        self._process_frame(*item)

    # -- periodic ------------------------------------------------------------------------
    def _republish_transform(self) -> None:
        with self.lock:
            transform, latest = self.transform, self.odometry.latest_stamp
        if transform is None or latest is None or self.tf is None or \
                not self.settings.tf_broadcast:
            return
        stamp = max(transform.stamp_ns,
                    latest + int(self.settings.transform_tolerance * 1e9))
        self.tf.send(StampedTransform(stamp, transform.parent, transform.child,
                                      transform.translation, transform.rotation))

    def _publish_diagnostics(self) -> None:
        loaded = self.loaded
        if loaded is None or self.diag_pub is None:
            return
        loc = loaded.localizer
        state = loc.state
        estimate = self.estimate
        with self.lock:
            problem = self.camera_problem
            odometry = 'yes' if len(self.odometry) else 'no'
            camera_key = self.camera_key
        dropped = self.stats.dropped_counts()
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
            'camera_info': problem or ('matches' if camera_key else 'none'),
            'frames_dropped': sum(dropped.values()),
        }
        values.update({f'dropped_{k}': v for k, v in sorted(dropped.items())})
        quality = pose_quality(estimate)
        cov = estimate.covariance if estimate is not None else None
        values.update(quality=quality, bridged=loc.stats.bridged, position_std_m=(
            f'{math.sqrt(max(cov[0, 0], cov[1, 1])):.4f}' if cov is not None else 'nan'))
        stale = loc.health.stale_regions()
        values['stale_regions'] = ','.join(map(str, stale)) if stale else 'none'
        level = {'good': DiagnosticStatus.OK, 'odometry': DiagnosticStatus.WARN,
                 'lost': DiagnosticStatus.ERROR}[quality]
        if problem and level == DiagnosticStatus.OK:
            level = DiagnosticStatus.WARN
        message = f'TRACKING region {loc.region}' if state == TRACKING else 'LOST'
        message += f' (pose: {quality})'
        if problem:
            message += '; CameraInfo does not match the database'
        if stale:
            message += f'; {len(stale)} stale region(s): re-explore them (vbn db-update)'
        self.diag_pub.publish(conversions.diagnostic_array(
            self.get_clock().now().to_msg(), 'localizer', loaded.path, level, message,
            values))
