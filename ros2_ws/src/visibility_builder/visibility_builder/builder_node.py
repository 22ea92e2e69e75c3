"""The builder as a ROS 2 node: ``ros2 run visibility_builder builder --ros-args -p db:=DB``.

Two modes, one pipeline (:func:`visibility_builder.build.build`):

- **file mode** (``-p bag:=BAGDIR``): reads the bag directly, like ``vbn build``, as soon
  as the node starts;
- **live mode** (no ``bag``): records what it hears on the image, camera-info, pose and
  transform topics (``/camera/image_raw``, ``/camera/image_raw/compressed``,
  ``/camera/camera_info``, ``/ground_truth/pose``, ``/tf``, ``/tf_static``) into a
  temporary bag, exactly as ``vbn record`` does, while the user plays an exploration
  (``vbn play``, or ``ros2 bag play`` on a full install); it builds from that bag when
  the ``~/build`` service (``std_srvs/srv/Trigger``) is called or after
  ``idle_timeout`` seconds without a new image. Building from what was heard through
  the same reader is what makes live and file mode give the same database.

Both publish progress on ``/builder/progress`` (``diagnostic_msgs/DiagnosticArray``, one
status named ``builder``: the step, images received, counts) and the finished regions
on ``/builder/regions`` (``visualization_msgs/MarkerArray``, transient-local, for RViz).
Every build setting is a parameter named as in ``config/builder.yaml`` (for example
``decomposition.k``, ``classes.gamma``), declared with its description; the node stays
up after a build so that RViz keeps its markers (``shutdown_after_build`` ends it).
"""
from __future__ import annotations

from pathlib import Path
import shutil
import sys
import tempfile
import threading
import time
from typing import Any

from vbn_common.errors import VbnCommonError
from vbn_common.ros_tools.node_main import run_node
from visibility_builder.errors import VisibilityBuilderError

__all__ = ['LIVE_TOPICS', 'main']

#: What live mode records.
LIVE_TOPICS = ('/camera/image_raw', '/camera/image_raw/compressed', '/camera/camera_info',
               '/ground_truth/pose', '/tf', '/tf_static')
_IMAGE_TOPICS = ('/camera/image_raw', '/camera/image_raw/compressed')


def main(args: list[str] | None = None) -> int:
    """Run the builder node until Ctrl-C (or the end of a build with shutdown_after_build).

    Three executor threads: ``~/build`` waits for the build while the recorder's
    subscriptions and the progress timer go on.
    """
    return run_node('builder', _make_node, args, threads=3, start=lambda node: node.start(),
                    close=lambda node: node.close())


def _make_node() -> Any:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
    from rclpy.node import Node
    from std_srvs.srv import Trigger
    from visualization_msgs.msg import MarkerArray

    from vbn_common.bags import BagWriter
    from vbn_common.ros_tools.markers import LATCHED_QOS, region_markers
    from vbn_common.ros_tools.record import Recorder
    from visibility_builder.build import (
        BuildConfig,
        build,
        config_from_flat,
        flat_config,
        setting_descriptions,
    )

    class BuilderNode(Node):
        """Declares the parameters, records (live mode), builds, publishes."""

        def __init__(self) -> None:
            super().__init__('builder')
            self.exit_code = 0
            describe = setting_descriptions()
            dynamic = ParameterDescriptor(dynamic_typing=True)
            self.declare_parameter('db', '', ParameterDescriptor(
                description='database file to write (required)'))
            self.declare_parameter('bag', '', ParameterDescriptor(
                description='exploration bag to read (file mode); empty: live mode'))
            self.declare_parameter('idle_timeout', 10.0, ParameterDescriptor(
                description='live mode: build after this many seconds without a new image '
                            '(once images have arrived; 0 disables)'))
            self.declare_parameter('report', '', ParameterDescriptor(
                description='write the report figures and summary.json into this folder'))
            self.declare_parameter('shutdown_after_build', False, ParameterDescriptor(
                description='end the node after one build (markers are latched until then)'))
            for name, value in flat_config(BuildConfig()).items():
                descriptor = ParameterDescriptor(description=describe.get(name, ''))
                if value is None or isinstance(value, (list, tuple, dict)):
                    descriptor = ParameterDescriptor(description=describe.get(name, ''),
                                                     dynamic_typing=dynamic.dynamic_typing)
                self.declare_parameter(name, value, descriptor)
            overrides = {name: self.get_parameter(name).value
                         for name in flat_config(BuildConfig())}
            self.config = config_from_flat(overrides)
            self.db = self.get_parameter('db').value
            if not self.db:
                raise VisibilityBuilderError('parameter db is required (-p db:=FILE)')
            self.bag = self.get_parameter('bag').value
            self.idle_timeout = float(self.get_parameter('idle_timeout').value)
            self.report_dir = self.get_parameter('report').value
            self.shutdown_after_build = bool(self.get_parameter('shutdown_after_build').value)
            self.progress_pub = self.create_publisher(DiagnosticArray, '/builder/progress', 10)
            self.regions_pub = self.create_publisher(MarkerArray, '/builder/regions',
                                                     LATCHED_QOS)
            self._msg = (DiagnosticArray, DiagnosticStatus, KeyValue)
            self.stage, self.detail, self.images_done = 'waiting', '', 0
            self.lock = threading.Lock()
            self.building = False
            self.built = threading.Event()
            self.result_text = ''
            self.result_ok = False
            self.recorder = None
            self.writer = None
            self.record_dir: Path | None = None
            self.last_image_count, self.last_image_time = 0, time.monotonic()
            group = ReentrantCallbackGroup()
            self.create_service(Trigger, '~/build', self._on_build, callback_group=group)
            self.create_timer(1.0, self._tick, callback_group=MutuallyExclusiveCallbackGroup())

        # -- modes -----------------------------------------------------------------------
        def start(self) -> None:
            if self.bag:
                self.get_logger().info(f'file mode: building {self.bag} into {self.db}')
                self._start_build(Path(self.bag))
                return
            self.record_dir = Path(tempfile.mkdtemp(prefix='vbn_builder_'))
            bag = self.record_dir / 'heard'
            self.writer = BagWriter(bag, atomic=False).open()
            self.recorder = Recorder(self, self.writer, list(LIVE_TOPICS),
                                     announce=lambda line: self.get_logger().info(line))
            self.create_timer(0.1, self.recorder.subscribe_new_topics)
            self.stage = 'recording'
            self.get_logger().info(
                f'live mode: recording {", ".join(LIVE_TOPICS)}; call ~/build or stay idle '
                f'{self.idle_timeout:g} s after the last image to build {self.db}')

        def images_received(self) -> int:
            if self.recorder is None:
                return 0
            return sum(self.recorder.counts.get(t, 0) for t in _IMAGE_TOPICS)

        def _tick(self) -> None:
            received = self.images_received()
            if received != self.last_image_count:
                self.last_image_count, self.last_image_time = received, time.monotonic()
            elif (self.recorder is not None and received and self.idle_timeout > 0
                  and not self.building and not self.built.is_set()
                  and time.monotonic() - self.last_image_time > self.idle_timeout):
                self.get_logger().info(f'no image for {self.idle_timeout:g} s: building')
                self._build_recorded()
            self._publish_progress()

        def _on_build(self, _request: Any, response: Any) -> Any:
            if self.bag is None or self.bag == '':
                self._build_recorded()
            self.built.wait()
            response.success, response.message = self.result_ok, self.result_text
            return response

        def _build_recorded(self) -> None:
            with self.lock:
                if self.building or self.built.is_set():
                    return
                if self.writer is not None:
                    self.recorder.drain(_NoExecutor())
                    self.writer.close()
                    self.writer = None
            received = self.images_received()
            self.get_logger().info(f'received {received} images; building {self.db}')
            self._start_build(self.record_dir / 'heard')

        def _start_build(self, bag: Path) -> None:
            with self.lock:
                if self.building:
                    return
                self.building = True
            threading.Thread(target=self._build, args=(bag,), daemon=True).start()

        def _build(self, bag: Path) -> None:
            def on_stage(name: str, detail: str) -> None:
                self.stage, self.detail = name, detail
                self._publish_progress()

            def on_image(count: int) -> None:
                self.images_done += count

            try:
                result = build(bag, self.config, db_path=self.db, on_stage=on_stage,
                               on_image=on_image)
                db = result.database
                self.result_ok = True
                self.result_text = (f'wrote {self.db}: {len(db.regions)} regions, '
                                    f'{db.classes.n_classes} classes, {db.poses.n_poses} '
                                    f'poses, from {len(result.sampling.frames_of_pose)} poses '
                                    f'of {self.images_received() or "the bag"} images')
                self.stage, self.detail = 'done', self.result_text
                self.regions_pub.publish(region_markers(db, stamp=self.get_clock().now()
                                                        .to_msg()))
                if self.report_dir:
                    from visibility_builder.report import write_report
                    write_report(Path(self.report_dir), result, None)
                self.get_logger().info(self.result_text)
            except (VisibilityBuilderError, VbnCommonError) as error:
                self.result_ok, self.result_text = False, str(error)
                self.stage, self.detail = 'failed', str(error)
                self.exit_code = 1
                self.get_logger().error(f'build failed: {error}')
            except Exception as error:  # noqa: BLE001 - a node reports, it does not die
                self.result_ok, self.result_text = False, f'{type(error).__name__}: {error}'
                self.stage, self.detail = 'failed', self.result_text
                self.exit_code = 1
                self.get_logger().error(f'build failed: {self.result_text}')
            finally:
                self.building = False
                self.built.set()
                self._publish_progress()
                if self.shutdown_after_build:
                    import rclpy
                    rclpy.try_shutdown()

        def _publish_progress(self) -> None:
            DiagnosticArray, DiagnosticStatus, KeyValue = self._msg
            level = {'failed': DiagnosticStatus.ERROR}.get(self.stage, DiagnosticStatus.OK)
            status = DiagnosticStatus(level=level, name='builder', hardware_id=str(self.db),
                                      message=f'{self.stage}: {self.detail}'.rstrip(': '))
            values = {'stage': self.stage, 'images_received': self.images_received(),
                      'images_processed': self.images_done, 'database': str(self.db)}
            status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
            msg = DiagnosticArray(status=[status])
            msg.header.stamp = self.get_clock().now().to_msg()
            self.progress_pub.publish(msg)

        def close(self) -> None:
            if self.writer is not None:
                self.writer.close()
                self.writer = None
            if self.record_dir is not None:
                shutil.rmtree(self.record_dir, ignore_errors=True)

    return BuilderNode()


class _NoExecutor:
    """Drain without spinning: the node's own executor delivers the messages."""

    def spin_once(self, timeout_sec: float = 0.0) -> None:
        time.sleep(timeout_sec)


if __name__ == '__main__':
    sys.exit(main())
