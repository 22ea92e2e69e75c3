"""The localizer as nav2 drives it: lifecycle services, namespaces, live parameters (DDS).

The node runs as the ``localizer`` executable in a subprocess; the test's own node calls
the standard ``lifecycle_msgs`` and ``rcl_interfaces`` services as a nav2 lifecycle
manager and ``ros2 param set`` do, feeds frames of ``bags/room_run`` and listens.
"""
from __future__ import annotations

import shutil
import time

from localizer_nodes import WAIT, Listener, Publisher, read_run, rss_kib, start_localizer
import pytest

from landmark_db.database import open_database

pytestmark = pytest.mark.integration

UNCONFIGURED, INACTIVE, ACTIVE, FINALIZED = 1, 2, 3, 4   # lifecycle_msgs/msg/State ids


@pytest.fixture(scope='module')
def run() -> dict:
    return read_run('room_run')


class Lifecycle:
    """The lifecycle services of one node, called from the test's node."""

    def __init__(self, ros_node, node: str = '/localizer') -> None:
        from lifecycle_msgs.srv import ChangeState, GetState

        self.ros = ros_node
        self.get = ros_node.node.create_client(GetState, f'{node}/get_state')
        self.change = ros_node.node.create_client(ChangeState, f'{node}/change_state')
        assert ros_node.spin_until(lambda: self.get.service_is_ready() and
                                   self.change.service_is_ready(), timeout=WAIT)

    def _call(self, client, request):
        future = client.call_async(request)
        assert self.ros.spin_until(future.done, timeout=WAIT)
        return future.result()

    def state(self) -> int:
        from lifecycle_msgs.srv import GetState
        return self._call(self.get, GetState.Request()).current_state.id

    def transition(self, label: str) -> bool:
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState

        ids = {'configure': Transition.TRANSITION_CONFIGURE,
               'activate': Transition.TRANSITION_ACTIVATE,
               'deactivate': Transition.TRANSITION_DEACTIVATE,
               'cleanup': Transition.TRANSITION_CLEANUP,
               'shutdown_unconfigured': Transition.TRANSITION_UNCONFIGURED_SHUTDOWN}
        request = ChangeState.Request()
        request.transition.id = ids[label]
        return self._call(self.change, request).success


class Parameters:
    """The rcl_interfaces parameter services of one node (what ros2 param uses)."""

    def __init__(self, ros_node, node: str = '/localizer') -> None:
        from rcl_interfaces.srv import GetParameters, SetParameters

        self.ros = ros_node
        self.setter = ros_node.node.create_client(SetParameters, f'{node}/set_parameters')
        self.getter = ros_node.node.create_client(GetParameters, f'{node}/get_parameters')
        assert ros_node.spin_until(lambda: self.setter.service_is_ready() and
                                   self.getter.service_is_ready(), timeout=WAIT)

    def set(self, name: str, value) -> tuple[bool, str]:
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        request = SetParameters.Request(parameters=[Parameter(name, value=value)
                                                    .to_parameter_msg()])
        future = self.setter.call_async(request)
        assert self.ros.spin_until(future.done, timeout=WAIT)
        result = future.result().results[0]
        return result.successful, result.reason

    def get(self, name: str):
        from rcl_interfaces.srv import GetParameters
        from rclpy.parameter import parameter_value_to_python

        future = self.getter.call_async(GetParameters.Request(names=[name]))
        assert self.ros.spin_until(future.done, timeout=WAIT)
        return parameter_value_to_python(future.result().values[0])


def stream(ros_node, publisher: Publisher, start: int, count: int, until=None,
           rate_hz: float = 10.0) -> int:
    """Publish ``count`` frames of the run at ``rate_hz`` (or until ``until()``).

    Returns:
        The index of the next frame.
    """
    stamp0 = 1_700_000_000_000_000_000
    period = 1.0 / rate_hz
    next_time = time.perf_counter()
    index = start
    while index < start + count:
        publisher.compressed.publish(publisher.frame(index, stamp0 + index * 100_000_000))
        index += 1
        next_time += period
        while time.perf_counter() < next_time:
            ros_node.executor.spin_once(timeout_sec=max(0.0, next_time - time.perf_counter()))
        if until is not None and until():
            break
    return index


def test_transitions_through_the_lifecycle_services(room_db, start_process, ros_node,
                                                     run) -> None:
    node = start_process(['localizer', '--ros-args', '-p', f'db:={room_db}', '-p',
                          'autostart:=false'], name='localizer')
    lifecycle = Lifecycle(ros_node)
    assert lifecycle.state() == UNCONFIGURED
    assert 'localizer ready' not in node.output

    assert lifecycle.transition('configure') and lifecycle.state() == INACTIVE
    listener = Listener(ros_node)
    publisher = Publisher(ros_node, run)      # waits until the node subscribes
    assert ros_node.spin_until(lambda: ros_node.node.count_publishers('/localizer/region'),
                               timeout=WAIT)  # the listener hears the node's publisher
    # Inactive: frames are ignored (not even counted) and nothing is published.
    index = stream(ros_node, publisher, 0, 10)
    assert listener.regions == [] and listener.poses == []

    assert lifecycle.transition('activate') and lifecycle.state() == ACTIVE
    activated_at = index
    assert ros_node.spin_until(lambda: listener.markers, timeout=WAIT)   # latched regions
    index = stream(ros_node, publisher, index, 200, until=lambda: len(listener.poses) >= 5)
    assert len(listener.poses) >= 5, node.output
    status = listener.wait_status(lambda s: True)
    assert int(status['frames_received']) <= index - activated_at   # none while inactive

    assert lifecycle.transition('deactivate') and lifecycle.state() == INACTIVE
    stopped = time.monotonic()
    index = stream(ros_node, publisher, index, 15)
    assert not [t for t in listener.region_times if t > stopped + 0.5], node.output
    assert lifecycle.transition('activate')
    count = len(listener.poses)
    index = stream(ros_node, publisher, index, 200,
                   until=lambda: len(listener.poses) >= count + 3)
    assert len(listener.poses) >= count + 3      # the database was kept

    assert lifecycle.transition('deactivate') and lifecycle.transition('cleanup')
    assert lifecycle.state() == UNCONFIGURED
    assert ros_node.spin_until(lambda: publisher.compressed.get_subscription_count() == 0,
                               timeout=WAIT)     # cleanup released the subscriptions
    assert not lifecycle.transition('activate')  # not from unconfigured

    assert lifecycle.transition('shutdown_unconfigured')
    assert node.wait(timeout=WAIT) == 0, node.output
    assert 'Traceback' not in node.output


def test_a_failed_configure_stays_unconfigured(start_process, ros_node, tmp_path) -> None:
    node = start_process(['localizer', '--ros-args', '-p', f'db:={tmp_path / "none.db"}',
                          '-p', 'autostart:=false'], name='localizer')
    lifecycle = Lifecycle(ros_node)
    assert not lifecycle.transition('configure')
    assert lifecycle.state() == UNCONFIGURED
    node.wait_for_output('configure failed: .*none.db: no such file', timeout=WAIT)
    assert node.popen.poll() is None


def test_100_cycles_keep_memory_flat(room_db, start_process, ros_node) -> None:
    node = start_process(['localizer', '--ros-args', '-p', f'db:={room_db}', '-p',
                          'autostart:=false'], name='localizer')
    lifecycle = Lifecycle(ros_node)
    samples = []
    for cycle in range(100):
        for step in ('configure', 'activate', 'deactivate', 'cleanup'):
            assert lifecycle.transition(step), (cycle, step, node.output)
        if cycle in (9, 99):
            samples.append(rss_kib(node.popen.pid))
    print(f'resident memory after 10 and 100 cycles: {samples[0] / 1024:.0f} MiB, '
          f'{samples[1] / 1024:.0f} MiB ({samples[1] / samples[0]:.3f}x)')
    assert samples[1] <= 1.10 * samples[0], samples
    assert lifecycle.state() == UNCONFIGURED and 'Traceback' not in node.output


def test_a_namespace_and_a_remap_move_the_topics(room_db, start_process, ros_node,
                                                  run) -> None:
    node = start_localizer(start_process, room_db,
                           ros_args=('-r', '__ns:=/robot1', '-r', 'localizer/pose:=estimate'))
    node.wait_for_output('listening on /robot1/camera/image_raw, '
                         '/robot1/camera/image_raw/compressed', timeout=WAIT)
    listener = Listener(ros_node, ns='/robot1')
    from geometry_msgs.msg import PoseStamped
    remapped = []
    ros_node.node.create_subscription(PoseStamped, '/robot1/estimate', remapped.append, 100)
    publisher = Publisher(ros_node, run, ns='/robot1')
    stream(ros_node, publisher, 0, 300, until=lambda: len(remapped) >= 3)
    assert len(remapped) >= 3, node.output
    assert listener.regions and listener.poses_cov and not listener.poses
    assert ros_node.spin_until(lambda: listener.markers, timeout=WAIT)
    names = dict(ros_node.node.get_topic_names_and_types())
    assert '/localizer/pose' not in names and '/localizer/region' not in names
    assert Lifecycle(ros_node, '/robot1/localizer').state() == ACTIVE


def test_parameters_take_effect_or_are_refused(room_db, start_process, ros_node, run,
                                               tmp_path) -> None:
    node = start_localizer(start_process, room_db)
    params = Parameters(ros_node)
    listener = Listener(ros_node)
    publisher = Publisher(ros_node, run)
    index = stream(ros_node, publisher, 0, 300, until=lambda: len(listener.poses) >= 3)
    assert len(listener.poses) >= 3

    ok, reason = params.set('autostart', False)
    assert not ok and 'read-only' in reason
    ok, reason = params.set('image_reliable', True)
    assert not ok and 'read-only' in reason
    ok, reason = params.set('vote_scale', 5.0)
    assert not ok and 'vote_scale must be in' in reason
    ok, reason = params.set('vote_ratio', 'abc')
    assert not ok and reason
    ok, reason = params.set('db', str(tmp_path / 'missing.db'))
    assert not ok and 'missing.db' in reason and 'still using' in reason
    assert params.get('db') == str(room_db)

    # A threshold takes effect from the next frame: no pose passes a zero limit.
    assert params.set('max_position_std_m', 0.0) == (True, '')
    regions, poses = len(listener.regions), len(listener.poses)
    index = stream(ros_node, publisher, index, 100,
                   until=lambda: len(listener.regions) >= regions + 10)
    assert len(listener.regions) >= regions + 10
    assert len(listener.poses) <= poses + 1       # at most the frame in flight
    assert params.set('max_position_std_m', 0.5) == (True, '')

    # db reloads the database (a copy: the same regions).
    copy = tmp_path / 'copy.db'
    shutil.copy(room_db, copy)
    assert ros_node.spin_until(lambda: listener.markers, timeout=WAIT)
    markers = len(listener.markers)
    assert params.set('db', str(copy)) == (True, '')
    regions_in_db = open_database(room_db).n_regions
    node.wait_for_output(rf'database reloaded: .*copy\.db: {regions_in_db} regions',
                         timeout=WAIT)
    poses = len(listener.poses)
    stream(ros_node, publisher, index, 300, until=lambda: len(listener.poses) >= poses + 3)
    assert len(listener.poses) >= poses + 3, node.output
    assert ros_node.spin_until(lambda: len(listener.markers) > markers, timeout=WAIT)
    assert params.get('db') == str(copy)
    # The same path again reloads too (a database rebuilt in place).
    assert params.set('db', str(copy)) == (True, '')
    assert ros_node.spin_until(lambda: node.output.count('database reloaded') == 2,
                               timeout=WAIT)
    assert 'Traceback' not in node.output
