"""The builder on the sample bags: vbn build, the database, /tf poses, a kill, live mode.

The room database is built once per session (``room_build``) and shared; the floor bag
(84 panoramas on a 1.25 m grid) is small enough for the tests that build twice. It needs
looser filters than the defaults, which are tuned for a 25 cm grid (see README).
"""
from __future__ import annotations

import json
import os
from pathlib import Path
import re
import signal
import subprocess
import sys

import numpy as np
from paths import REPO
import pytest

from landmark_db.database import database_summary, open_database
from vbn_common.bags import BagWriter, open_bag

pytestmark = pytest.mark.integration

ROOT = REPO
BAGS = ROOT / 'bags'
WAIT = 240.0
FLOOR_SETTINGS = ['--set', 'filters.min_poses=3', '--set', 'filters.min_block=1',
                  '--set', 'filters.convex_trim=false', '--set', 'sampling.connectivity=8',
                  '--k', '4', '--rho', '0']


def vbn(*args: str, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run(['vbn', *args], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope='session')
def floor_build(tmp_path_factory) -> Path:
    db = tmp_path_factory.mktemp('floor_build') / 'floor.db'
    proc = vbn('build', str(BAGS / 'floor_exploration'), '--db', str(db), '--quiet',
               *FLOOR_SETTINGS)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return db


def region_signature(db_path: Path) -> list[tuple[tuple[int, ...], tuple[int, ...]]]:
    db = open_database(db_path)
    return [(tuple(r.poses.tolist()), tuple(r.landmark.tolist())) for r in db.regions]


def test_room_database_exports_and_validates(room_build, tmp_path: Path) -> None:
    db = open_database(room_build['db'])
    assert db.info.pose_source == 'ground_truth'
    assert db.poses.n_poses == 200 and db.poses.spacing == pytest.approx(0.25, abs=1e-3)
    assert (db.info.k, db.info.rho, db.info.sigma, db.info.algorithm) == (8, 1, 0, 'best')
    assert db.n_regions >= 3 and db.n_classes >= 100
    for region in db.regions:
        assert 2 <= len(region.model_views) <= 3
        views = np.array([[v.x, v.y] for v in region.model_views])
        assert np.linalg.norm(views[0] - views[1]) > 0.2  # two different places
    world, decomp = tmp_path / 'world.json', tmp_path / 'decomp.json'
    proc = vbn('db-export', str(room_build['db']), '--world', str(world), '--decomposition',
               str(decomp))
    assert proc.returncode == 0, proc.stderr
    proc = vbn('validate', str(world), str(decomp))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = json.loads((room_build['report'] / 'summary.json').read_text())
    assert summary['database']['regions'] == db.n_regions
    assert summary['counts']['filter']['min_block_classes'] == db.n_classes
    for name in ('regions.png', 'visibility_sizes.png'):
        assert (room_build['report'] / name).stat().st_size > 10_000
    for step in ('read', 'sample', 'features', 'classes', 'filter', 'decompose',
                 'model_views', 'write'):
        assert re.search(rf'^{step} +\d+\.\d+ s', room_build['output'], re.M), step


def test_database_is_far_smaller_than_every_descriptor(room_build) -> None:
    db = open_database(room_build['db'])
    # The full unpruned feature database: every SIFT descriptor (uint8) of every image.
    features = int(re.search(r'features=(\d+)', room_build['output']).group(1))
    # The regions and their landmarks: 20 times smaller than every descriptor. The scene
    # points (one descriptor each, for poses outside the regions, and a 15 x 15 patch for
    # those seen by 5 or more images, measured in tracked frames) add less than that
    # again: the whole file is 9 times smaller (the schema 5 room: 0.52 MB). About half
    # of the room's points have a patch (1,886 of 3,503), those seen by 3 or 4 not.
    tables = database_summary(room_build['db']).table_bytes
    points = tables.get('scene_points', db.points.n_points * 180)
    assert (room_build['db'].stat().st_size - points) * 20 < features * 128
    assert room_build['db'].stat().st_size * 9 < features * 128
    assert 0 < db.points.patch_mask.sum() < db.points.n_points * 2 // 3
    assert db.points.n_points < features // 20
    assert db.classes.descriptors.shape[0] <= 4 * db.n_classes


def strip_topic(source: Path, out: Path, topic: str) -> None:
    with open_bag(source) as reader, BagWriter(out) as writer:
        connections = {}
        for name, info in reader.topics.items():
            if name != topic:
                connections[name] = writer.add_topic(name, info.msgtype, info.qos_profiles)
        for name, _msgtype, stamp, raw in reader.messages():
            if name != topic:
                writer.write_raw(connections[name], stamp, raw)


def test_tf_poses_give_the_same_database(floor_build, tmp_path: Path) -> None:
    strip_topic(BAGS / 'floor_exploration', tmp_path / 'tf_only', '/ground_truth/pose')
    db = tmp_path / 'tf.db'
    proc = vbn('build', str(tmp_path / 'tf_only'), '--db', str(db), '--quiet',
               *FLOOR_SETTINGS)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    a, b = open_database(floor_build), open_database(db)
    assert (a.info.pose_source, b.info.pose_source) == ('ground_truth', 'tf')
    np.testing.assert_allclose(a.poses.xy, b.poses.xy, atol=1e-9)
    assert region_signature(floor_build) == region_signature(db)
    assert np.array_equal(a.classes.descriptors, b.classes.descriptors)


def test_k_larger_than_any_visibility_writes_nothing(floor_build, tmp_path: Path) -> None:
    db = tmp_path / 'x.db'
    proc = vbn('build', str(BAGS / 'floor_exploration'), '--db', str(db), '--quiet',
               *FLOOR_SETTINGS, '--k', '5000')
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert 'k=5000 is larger than any pose' in proc.stderr and 'Traceback' not in proc.stderr
    assert not db.exists() and list(tmp_path.iterdir()) == []


def test_killed_build_leaves_the_previous_database(floor_build, tmp_path: Path) -> None:
    db = tmp_path / 'floor.db'
    db.write_bytes(floor_build.read_bytes())
    before = db.read_bytes()
    proc = subprocess.Popen(['vbn', 'build', str(BAGS / 'floor_exploration'), '--db', str(db),
                             '--quiet', *FLOOR_SETTINGS],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        for line in proc.stdout:  # kill it in the middle of matching features
            if line.startswith('[classes]'):
                os.kill(proc.pid, signal.SIGKILL)
                break
    finally:
        proc.kill()
        proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    assert db.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ['floor.db']
    assert open_database(db).n_regions == open_database(floor_build).n_regions


def test_live_mode_over_dds_builds_the_same_regions(floor_build, tmp_path: Path,
                                                    start_process, ros_node) -> None:
    from std_srvs.srv import Trigger

    db = tmp_path / 'live.db'
    settings = {'filters.min_poses': '3', 'filters.min_block': '1',
                'filters.convex_trim': 'false', 'sampling.connectivity': '8',
                'decomposition.k': '4', 'decomposition.rho': '0'}
    params = [arg for name, value in settings.items() for arg in ('-p', f'{name}:={value}')]
    node = start_process(['builder', '--ros-args', '-p', f'db:={db}', '-p',
                          'idle_timeout:=0.0', *params], name='builder')
    node.wait_for_output('live mode: recording', timeout=WAIT)
    play = start_process(['vbn', 'play', str(BAGS / 'floor_exploration'), '--rate', '5',
                          '--wait-for-subscribers', '--wait-timeout', str(WAIT)],
                         name='play')
    assert play.wait(timeout=2 * WAIT) == 0, play.output
    client = ros_node.node.create_client(Trigger, '/builder/build')
    assert ros_node.spin_until(client.service_is_ready, timeout=WAIT)
    future = client.call_async(Trigger.Request())
    assert ros_node.spin_until(future.done, timeout=2 * WAIT), node.output
    response = future.result()
    assert response.success, response.message
    assert 'received 84 images' in node.output, node.output
    assert region_signature(db) == region_signature(floor_build)
    assert open_database(db).n_classes == open_database(floor_build).n_classes

    # Latched region markers for RViz, received after the fact; progress says done.
    from diagnostic_msgs.msg import DiagnosticArray
    from visualization_msgs.msg import MarkerArray

    from vbn_common.ros_tools.markers import LATCHED_QOS
    markers: list = []
    progress: list = []
    ros_node.node.create_subscription(MarkerArray, '/builder/regions', markers.append,
                                      LATCHED_QOS)
    ros_node.node.create_subscription(DiagnosticArray, '/builder/progress', progress.append,
                                      10)
    assert ros_node.spin_until(lambda: markers and progress, timeout=WAIT)
    regions = [m for m in markers[0].markers if m.ns == 'regions']
    assert len(regions) == open_database(db).n_regions
    assert sorted(len(m.points) for m in regions) == sorted(
        len(r.poses) for r in open_database(db).regions)
    status = progress[-1].status[0]
    assert status.name == 'builder' and status.message.startswith('done')
    # The recording was temporary: the database names what was recorded instead.
    source = open_database(db).info.source_bag
    assert source.startswith('live recording by /builder of /camera/image_raw')
    assert 'vbn_builder_' not in source

    # Settings take effect at the next build; a bad value and the mode are refused.
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter
    setter = ros_node.node.create_client(SetParameters, '/builder/set_parameters')
    assert ros_node.spin_until(setter.service_is_ready, timeout=WAIT)

    def set_parameter(name, value):
        future = setter.call_async(SetParameters.Request(
            parameters=[Parameter(name, value=value).to_parameter_msg()]))
        assert ros_node.spin_until(future.done, timeout=WAIT)
        return future.result().results[0]

    refused = set_parameter('decomposition.k', 0)
    assert not refused.successful and 'k' in refused.reason
    assert not set_parameter('bag', 'other').successful          # read-only: the mode
    assert set_parameter('decomposition.k', 3).successful
    future = client.call_async(Trigger.Request())
    assert ros_node.spin_until(future.done, timeout=2 * WAIT), node.output
    assert future.result().success, future.result().message
    assert open_database(db).info.k == 3


if __name__ == '__main__':
    sys.exit(pytest.main([__file__, '-q']))
