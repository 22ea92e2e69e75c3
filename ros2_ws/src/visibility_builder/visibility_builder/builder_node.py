"""The builder as a ROS 2 node: ``ros2 run visibility_builder builder --ros-args -p db:=DB``.

Two modes, one pipeline (:func:`visibility_builder.build.build`):

- **file mode** (``-p bag:=BAGDIR``): reads the bag directly, like ``vbn build``, as soon
  as the node starts;
- **live mode** (no ``bag``): records what it hears on the image, camera-info, pose and
  transform topics (``camera/image_raw``, ``camera/image_raw/compressed``,
  ``camera/camera_info``, ``ground_truth/pose``, ``tf``, ``tf_static``, relative to the
  node's namespace) into a temporary bag, exactly as ``vbn record`` does, while the user
  plays an exploration (``vbn play``, or ``ros2 bag play`` on a full install); it builds
  from that bag when the ``~/build`` service (``std_srvs/srv/Trigger``) is called or
  after ``idle_timeout`` seconds without a new image. Building from what was heard
  through the same reader is what makes live and file mode give the same database.

Both publish progress on ``builder/progress`` (``diagnostic_msgs/DiagnosticArray``, one
status named ``builder``: the step, images received, counts) and the finished regions
on ``builder/regions`` (``visualization_msgs/MarkerArray``, transient-local, for RViz).
Every build setting is a parameter named as in ``config/builder.yaml`` (for example
``decomposition.k``, ``classes.gamma``), declared with its description. The build
settings, ``db`` and ``report`` take effect at the next build (``~/build`` builds again
once a build has finished), ``idle_timeout`` and ``shutdown_after_build`` at once; ``bag``
(the mode) is read-only. A value the build would refuse is refused when it is set. The
node stays up after a build so that RViz keeps its markers (``shutdown_after_build``
ends it).
"""
from __future__ import annotations

from pathlib import Path
import shutil
import sys
import tempfile
import threading
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from vbn_common import names
from vbn_common.bags import BagWriter
from vbn_common.errors import VbnError
from vbn_common.names import relative
from vbn_common.parameters import unknown_parameters
from vbn_common.ros_tools.markers import LATCHED_QOS, region_markers
from vbn_common.ros_tools.record import Recorder
from visibility_builder.build import (
    BuildConfig,
    build,
    config_from_flat,
    flat_config,
    setting_descriptions,
)
from visibility_builder.errors import VisibilityBuilderError

__all__ = ['LIVE_TOPICS', 'BuilderNode']

#: What live mode records (root names; the node subscribes them in its namespace).
LIVE_TOPICS = (*names.IMAGE_TOPICS, names.CAMERA_INFO, names.GROUND_TRUTH_POSE, names.TF,
               names.TF_STATIC)
#: The node's own parameters: default and description (the build settings follow).
NODE_PARAMETERS = {
    'db': ('', 'database file to write (required)'),
    'bag': ('', 'exploration bag to read (file mode); empty: live mode'),
    'idle_timeout': (10.0, 'live mode: build after this many seconds without a new image '
                           '(once images have arrived; 0 disables)'),
    'report': ('', 'write the report figures and summary.json into this folder'),
    'shutdown_after_build': (False, 'end the node after one build (markers are latched '
                                    'until then)'),
}
#: How long closing the node waits for a build to stop.
CLOSE_WAIT_S = 30.0
#: Read-only: the mode is chosen at start-up.
READ_ONLY = frozenset({'bag'})


class BuilderNode(Node):
    """Declares the parameters, records (live mode), builds, publishes.

    Raises:
        VisibilityBuilderError: a parameter of the wrong type, an unknown parameter, a
            bad build setting or no ``db``.
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('builder', **kwargs)
        self.exit_code = 0
        self._declare_parameters()
        self._settings_from(self._values())            # refuse a bad start at once
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.bag = self.get_parameter('bag').value
        self.progress_pub = self.create_publisher(DiagnosticArray,
                                                  relative(names.BUILDER_PROGRESS), 10)
        self.regions_pub = self.create_publisher(MarkerArray, relative(names.BUILDER_REGIONS),
                                                 LATCHED_QOS)
        self.stage, self.detail, self.images_done = 'waiting', '', 0
        self.lock = threading.Lock()
        self.building = False
        self.closing = False
        self.closing_stopped_build = False
        self.built = threading.Event()
        self.result_text = ''
        self.result_ok = False
        self.recorder: Recorder | None = None
        self.writer: BagWriter | None = None
        self.record_dir: Path | None = None
        self.last_image_count, self.last_image_time = 0, time.monotonic()
        self.create_service(Trigger, '~/build', self._on_build,
                            callback_group=ReentrantCallbackGroup())
        self.create_timer(1.0, self._tick, callback_group=MutuallyExclusiveCallbackGroup())

    # -- parameters ------------------------------------------------------------------------
    def _declare_parameters(self) -> None:
        describe = setting_descriptions()
        declared = {name: (default, text) for name, (default, text) in NODE_PARAMETERS.items()}
        declared.update({name: (value, describe.get(name, ''))
                         for name, value in flat_config(BuildConfig()).items()})
        for name, (default, text) in declared.items():
            # A setting whose default is None (automatic) or a list takes any type.
            dynamic = default is None or isinstance(default, (list, tuple, dict))
            try:
                self.declare_parameter(name, default, ParameterDescriptor(
                    description=text, dynamic_typing=dynamic, read_only=name in READ_ONLY))
            except ParameterException as error:
                raise VisibilityBuilderError(
                    f'parameter {name}: {error}'.splitlines()[0]) from error
        unknown = unknown_parameters(set(getattr(self, '_parameter_overrides', {})),
                                     set(declared))
        if unknown:
            raise VisibilityBuilderError(unknown)
        self._names = list(declared)

    def _values(self, changes: dict[str, Any] | None = None) -> dict[str, Any]:
        values = {name: self.get_parameter(name).value for name in self._names}
        values.update(changes or {})
        return values

    @staticmethod
    def _settings_from(values: dict[str, Any]) -> BuildConfig:
        """Check every value; return the build's settings."""
        if not values['db']:
            raise VisibilityBuilderError('parameter db is required (-p db:=FILE)')
        idle = values['idle_timeout']
        if not (isinstance(idle, (int, float)) and idle >= 0 and idle == idle):
            raise VisibilityBuilderError(f'idle_timeout must be a number >= 0, got {idle!r}')
        return config_from_flat({k: v for k, v in values.items() if k not in NODE_PARAMETERS})

    def _on_set_parameters(self, parameters: list[Any]) -> SetParametersResult:
        try:
            self._settings_from(self._values({p.name: p.value for p in parameters}))
        except VbnError as error:
            return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    # -- modes -------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the build (file mode) or the recording (live mode)."""
        if self.bag:
            self.get_logger().info(f'file mode: building {self.bag} into '
                                   f'{self.get_parameter("db").value}')
            self._start_build(Path(self.bag))
            return
        self.record_dir = Path(tempfile.mkdtemp(prefix='vbn_builder_'))
        self.writer = BagWriter(self.record_dir / 'heard', atomic=False).open()
        heard = {self.resolve_topic_name(relative(t)): t for t in LIVE_TOPICS}
        self.recorder = Recorder(self, self.writer, list(heard), bag_names=heard,
                                 announce=lambda line: self.get_logger().info(line))
        self.create_timer(0.1, self.recorder.subscribe_new_topics)
        self.stage = 'recording'
        self.get_logger().info(
            f'live mode: recording {", ".join(heard)}; call ~/build or stay idle '
            f'{self.get_parameter("idle_timeout").value:g} s after the last image to build '
            f'{self.get_parameter("db").value}')

    def images_received(self) -> int:
        """Images recorded so far (live mode)."""
        if self.recorder is None:
            return 0
        return sum(self.recorder.counts.get(self.resolve_topic_name(relative(t)), 0)
                   for t in names.IMAGE_TOPICS)

    def _tick(self) -> None:
        received = self.images_received()
        idle = float(self.get_parameter('idle_timeout').value)
        if received != self.last_image_count:
            self.last_image_count, self.last_image_time = received, time.monotonic()
        elif (self.recorder is not None and received and idle > 0
              and not self.building and not self.built.is_set()
              and time.monotonic() - self.last_image_time > idle):
            self.get_logger().info(f'no image for {idle:g} s: building')
            self._build_recorded()
        self._publish_progress()

    def _on_build(self, _request: Any, response: Any) -> Any:
        if self.built.is_set() and not self.building:
            self.built.clear()          # a finished build: build again, with today's settings
            if self.bag:
                self._start_build(Path(self.bag))
        if not self.bag:
            self._build_recorded()
        self.built.wait()
        response.success, response.message = self.result_ok, self.result_text
        return response

    def _build_recorded(self) -> None:
        with self.lock:
            if self.building or self.built.is_set() or self.record_dir is None:
                return
            if self.writer is not None:
                self.recorder.drain(_NoExecutor())
                # What comes after the build started is not recorded (the bag is closed).
                for subscription in self.recorder.subscriptions.values():
                    self.destroy_subscription(subscription)
                self.recorder.pending.clear()
                self.writer.close()
                self.writer = None
        self.get_logger().info(f'received {self.images_received()} images; building '
                               f'{self.get_parameter("db").value}')
        self._start_build(self.record_dir / 'heard')

    def _start_build(self, bag: Path) -> None:
        with self.lock:
            if self.building:
                return
            self.building = True
        threading.Thread(target=self._build, args=(bag,), daemon=True).start()

    def _build(self, bag: Path) -> None:
        values = self._values()
        db, report = values['db'], values['report']

        def on_stage(name: str, detail: str) -> None:
            self.stage, self.detail = name, detail
            self._publish_progress()

        def on_image(count: int) -> None:
            self.images_done += count

        try:
            # Live mode's bag is temporary: the database names what was recorded.
            source = str(bag) if self.bag else (
                f'live recording by {self.get_fully_qualified_name()} of '
                f'{", ".join(self.recorder.subscriptions)}')
            # A shutdown stops the build at its next step, image or chunk of pose pairs.
            result = build(bag, self._settings_from(values), db_path=db, on_stage=on_stage,
                           on_image=on_image, source=source, check_stop=self._stop_if_closing)
            database = result.database
            self.result_ok = True
            self.result_text = (f'wrote {db}: {len(database.regions)} regions, '
                                f'{database.classes.n_classes} classes, '
                                f'{database.poses.n_poses} poses, from '
                                f'{len(result.sampling.frames_of_pose)} poses of '
                                f'{self.images_received() or "the bag"} images')
            self.stage, self.detail = 'done', self.result_text
            if not self.closing:
                self.regions_pub.publish(region_markers(
                    database, stamp=self.get_clock().now().to_msg()))
            if report:
                from visibility_builder.report import write_report
                write_report(Path(report), result, None)
            self.get_logger().info(self.result_text)
        except Exception as error:  # noqa: BLE001 - a node reports, it does not die
            text = str(error) if isinstance(error, VbnError) else \
                f'{type(error).__name__}: {error}'
            self.result_ok, self.result_text = False, text
            self.stage, self.detail = 'failed', text
            self.exit_code = 1
            if not self.closing:
                self.get_logger().error(f'build failed: {text}')
        finally:
            with self.lock:     # built before building: no second build slips between
                self.built.set()
                self.building = False
            self._publish_progress()
            if self.get_parameter('shutdown_after_build').value and not self.closing:
                from rclpy.utilities import try_shutdown
                try_shutdown(context=self.context)

    def _stop_if_closing(self) -> None:
        if self.closing:
            self.closing_stopped_build = True
            raise VisibilityBuilderError('build stopped: the node is shutting down')

    def _publish_progress(self) -> None:
        if self.closing or not self.context.ok():
            return
        db = self.get_parameter('db').value
        level = {'failed': DiagnosticStatus.ERROR}.get(self.stage, DiagnosticStatus.OK)
        status = DiagnosticStatus(level=level, name='builder', hardware_id=str(db),
                                  message=f'{self.stage}: {self.detail}'.rstrip(': '))
        values = {'stage': self.stage, 'images_received': self.images_received(),
                  'images_processed': self.images_done, 'database': str(db)}
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.progress_pub.publish(msg)

    def close(self) -> None:
        """Stop a build in progress, publishing and the recording (the node is about to go).

        A build stops at its next step or image (the SIFT workers are terminated) and
        writes nothing: the previous database stays as it was.
        """
        self.closing = True
        db = self.get_parameter('db').value
        # rosout is gone with the context: say it on stderr, as a command would.
        if self.building and not self.built.wait(timeout=CLOSE_WAIT_S):
            print(f'builder: the build did not stop within {CLOSE_WAIT_S:g} s of the '
                  f'shutdown (in its {self.stage or "first"} step); {db} is written only '
                  f'if it completes', file=sys.stderr)
            self.exit_code = 130
        elif self.built.is_set() and self.closing_stopped_build:
            print(f'builder: build stopped by the shutdown, {db} left as it was',
                  file=sys.stderr)
            self.exit_code = 130
        if self.writer is not None:
            self.writer.close()
            self.writer = None
        if self.record_dir is not None:
            shutil.rmtree(self.record_dir, ignore_errors=True)


class _NoExecutor:
    """Drain without spinning: the node's own executor delivers the messages."""

    def spin_once(self, timeout_sec: float = 0.0) -> None:
        time.sleep(timeout_sec)
