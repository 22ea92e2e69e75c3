"""Synthesised bags read back with rosbags (and mcap-ros2): topics, counts, stamps."""
from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from landmark_db.scenes import resolve_scene
from vbn_common.cli.main import main as vbn_main
from vbn_common.geometry.frames import compose_poses
from vbn_worlds.errors import WorldsError
from vbn_worlds.synthesis.bags import START_NS, BagSpec, write_bag
from vbn_worlds.synthesis.grid import exploration_poses

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def _read(path: Path) -> dict[str, list[tuple[int, object]]]:
    out: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([path], default_typestore=TYPESTORE) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, stamp, raw in reader.messages():
            out.setdefault(conn.topic, []).append((stamp, reader.deserialize(raw, conn.msgtype)))
    out['__types__'] = types  # type: ignore[assignment]
    return out


def _stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


@pytest.fixture(scope='module')
def room():
    return resolve_scene('room')


def test_small_panoramic_exploration_bag(tmp_path, room):
    spec = BagSpec(kind='exploration', camera='panoramic', width=256, height=64, spacing=1.0)
    summary = write_bag(room, spec, tmp_path / 'expl')
    poses = exploration_poses(room, 1.0)
    n = len(poses)
    assert summary.images == n
    bag = _read(tmp_path / 'expl')
    assert bag['__types__'] == {
        '/camera/image_raw': 'sensor_msgs/msg/Image',
        '/camera/camera_info': 'sensor_msgs/msg/CameraInfo',
        '/ground_truth/pose': 'geometry_msgs/msg/PoseStamped',
        '/tf': 'tf2_msgs/msg/TFMessage',
        '/tf_static': 'tf2_msgs/msg/TFMessage',
    }
    for topic in ('/camera/image_raw', '/camera/camera_info', '/ground_truth/pose', '/tf'):
        assert len(bag[topic]) == n
        for stamp, msg in bag[topic]:
            header = msg.transforms[0].header if topic == '/tf' else msg.header
            assert _stamp_ns(header) == stamp
    assert len(bag['/tf_static']) == 1
    static = bag['/tf_static'][0][1].transforms[0]
    assert (static.header.frame_id, static.child_frame_id) == ('base_link', 'camera')
    assert static.transform.translation.z == pytest.approx(room.camera_height)
    image = bag['/camera/image_raw'][0][1]
    assert (image.width, image.height, image.encoding, image.step) == (256, 64, 'bgr8', 768)
    assert image.header.frame_id == 'camera'
    info = bag['/camera/camera_info'][0][1]
    assert info.distortion_model == 'cylindrical'
    assert info.k[0] == pytest.approx(256 / (2 * math.pi)) and info.k[5] == pytest.approx(32)
    gt = [m for _, m in bag['/ground_truth/pose']]
    assert gt[0].header.frame_id == 'map'
    xy = np.array([[m.pose.position.x, m.pose.position.y] for m in gt])
    assert xy == pytest.approx(poses)
    assert bag['/camera/image_raw'][0][0] == START_NS


def test_pinhole_exploration_has_four_headings_and_compressed_images(tmp_path, room):
    spec = BagSpec(kind='exploration', camera='pinhole', width=160, height=120, spacing=1.5,
                   compression='jpeg', encoding='mono8')
    write_bag(room, spec, tmp_path / 'pin')
    bag = _read(tmp_path / 'pin')
    n = len(exploration_poses(room, 1.5))
    images = bag['/camera/image_raw/compressed']
    assert len(images) == 4 * n
    assert images[0][1].format == 'mono8; jpeg compressed mono8'
    decoded = cv2.imdecode(np.asarray(images[0][1].data), cv2.IMREAD_UNCHANGED)
    assert decoded.shape == (120, 160)
    yaws = [2 * math.atan2(m.pose.orientation.z, m.pose.orientation.w)
            for _, m in bag['/ground_truth/pose'][:4]]
    assert np.degrees(np.unwrap(yaws)) == pytest.approx([0, 90, 180, 270], abs=1e-6)
    assert bag['/camera/camera_info'][0][1].distortion_model == 'plumb_bob'


def test_run_bag_has_odometry_and_consistent_tf(tmp_path, room):
    spec = BagSpec(kind='run', width=128, height=32, duration=3.0, seed=1)
    summary = write_bag(room, spec, tmp_path / 'run')
    bag = _read(tmp_path / 'run')
    assert len(bag['/odom']) == 151  # 3 s at 50 Hz, both ends
    assert len(bag['/camera/image_raw']) == 31  # 10 Hz
    assert summary.counts['/ground_truth/pose'] == 31
    odom = bag['/odom'][10][1]
    assert (odom.header.frame_id, odom.child_frame_id) == ('odom', 'base_link')
    assert np.diff([s for s, _ in bag['/odom']]) == pytest.approx(20_000_000)
    # map -> odom -> base_link is the ground truth at every image time
    gt = {s: m for s, m in bag['/ground_truth/pose']}
    for stamp, tf in bag['/tf']:
        frames = {(t.header.frame_id, t.child_frame_id): t.transform for t in tf.transforms}
        if ('map', 'odom') not in frames:
            continue

        def planar(t):
            return np.array([t.translation.x, t.translation.y,
                             2 * math.atan2(t.rotation.z, t.rotation.w)])

        chained = compose_poses(planar(frames[('map', 'odom')]),
                                planar(frames[('odom', 'base_link')]))
        pose = gt[stamp].pose
        assert chained[:2] == pytest.approx([pose.position.x, pose.position.y], abs=1e-9)
    # all messages in time order, header stamps equal to bag time
    for topic in ('/odom', '/camera/image_raw', '/ground_truth/pose'):
        assert all(_stamp_ns(m.header) == s for s, m in bag[topic])


def test_bags_are_deterministic(tmp_path, room):
    spec = BagSpec(kind='run-kidnapped', width=128, height=32, duration=2.0, seed=4,
                   compression='jpeg')
    write_bag(room, spec, tmp_path / 'a')
    write_bag(room, spec, tmp_path / 'b')
    mcap_a = next((tmp_path / 'a').glob('*.mcap')).read_bytes()
    mcap_b = next((tmp_path / 'b').glob('*.mcap')).read_bytes()
    a, b = _read(tmp_path / 'a'), _read(tmp_path / 'b')
    assert len(mcap_a) == len(mcap_b)
    for topic in ('/odom', '/camera/image_raw/compressed'):
        assert [s for s, _ in a[topic]] == [s for s, _ in b[topic]]
    assert all(np.array_equal(x.data, y.data) for (_, x), (_, y) in
               zip(a['/camera/image_raw/compressed'], b['/camera/image_raw/compressed']))


def test_mcap_reader_decodes_the_same_messages(tmp_path, room):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    write_bag(room, BagSpec(width=128, height=32, spacing=1.5), tmp_path / 'm')
    expected = _read(tmp_path / 'm')
    counts: dict[str, int] = {}
    with open(next((tmp_path / 'm').glob('*.mcap')), 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == '/ground_truth/pose':
                assert decoded.header.frame_id == 'map'
                assert message.log_time == (decoded.header.stamp.sec * 1_000_000_000
                                            + decoded.header.stamp.nanosec)
    assert counts == {t: len(v) for t, v in expected.items() if t != '__types__'}


def test_fisheye_exploration_carries_its_lens_to_the_builder(tmp_path, room):
    from vbn_common.exploration import read_exploration
    from vbn_common.geometry.camera import camera_from_info

    spec = BagSpec(kind='exploration', camera='fisheye', width=96, height=72, hfov_deg=190.0,
                   distortion=('equidistant', (0.02, -0.005, 0.001, 0.0)), spacing=1.5,
                   headings=2, compression='jpeg', encoding='mono8')
    write_bag(room, spec, tmp_path / 'fish')
    info = _read(tmp_path / 'fish')['/camera/camera_info'][0][1]
    assert info.distortion_model == 'equidistant'
    assert list(info.d) == pytest.approx([0.02, -0.005, 0.001, 0.0])
    exploration = read_exploration(tmp_path / 'fish')
    assert camera_from_info(exploration.camera_info) == spec.camera_model()
    assert len(exploration.frames) == 2 * len(exploration_poses(room, 1.5))


def test_bad_input_is_one_line_errors(tmp_path, room, capsys):
    (tmp_path / 'exists').mkdir()
    with pytest.raises(WorldsError, match='exists'):
        write_bag(room, BagSpec(), tmp_path / 'exists')
    with pytest.raises(WorldsError, match='kind'):
        write_bag(room, BagSpec(kind='walk'), tmp_path / 'x')
    bad = tmp_path / 'bad.json'
    bad.write_text('{"perimeter": [[0, 0], [1, 0]]}')
    for argv in (['render', '--scene', 'no-such-scene', '--out', str(tmp_path / 'o')],
                 ['render', '--scene', str(bad), '--out', str(tmp_path / 'o')],
                 ['render', '--scene', 'room', '--out', str(tmp_path / 'exists')],
                 ['render', '--scene', 'room', '--spacing', '-1', '--out', str(tmp_path / 'o')],
                 ['render', '--scene', 'room', '--camera', 'fisheye', '--distortion',
                  'equidistant:0.1', '--out', str(tmp_path / 'o')]):
        assert vbn_main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith('vbn render: error:') and '\n' not in err
    with pytest.raises(SystemExit, match='2'):   # argparse's own error
        vbn_main(['render', '--scene', 'room', '--camera', 'pinhole', '--distortion',
                  'plumb_bob:a,b', '--out', str(tmp_path / 'o')])
    assert 'expected MODEL:c1,c2,... with numbers' in capsys.readouterr().err
    assert not (tmp_path / 'o').exists()
    assert not (tmp_path / 'x').exists()


def test_vbn_render_writes_a_bag_and_a_snapshot(tmp_path, capsys):
    out = tmp_path / 'cli_bag'
    argv = ['render', '--scene', 'room', '--kind', 'run', '--width', '64', '--height', '16',
            '--duration', '1', '--compressed', 'png', '--out', str(out)]
    assert vbn_main(argv) == 0
    assert 'wrote' in capsys.readouterr().out
    bag = _read(out)
    assert len(bag['/camera/image_raw/compressed']) == 11
    assert bag['/camera/image_raw/compressed'][0][1].format == 'bgr8; png compressed bgr8'
    png = tmp_path / 'view.png'
    assert vbn_main(['render', '--scene', 'room', '--camera', 'pinhole', '--width', '80',
                     '--height', '60', '--snapshot', '1', '1', '45', '--out', str(png)]) == 0
    assert cv2.imread(str(png)).shape == (60, 80, 3)
    assert vbn_main(['render', '--scene', 'room', '--snapshot', '1.3', '2.3', '0',
                     '--out', str(tmp_path / 'inside_table.png')]) == 2


def test_a_tilted_mount_is_written_to_tf_static_and_read_back(tmp_path, room):
    from vbn_common.exploration import read_exploration
    from vbn_common.geometry.mount import TiltedCamera, tilt_angles

    spec = BagSpec(kind='exploration', camera='pinhole', width=80, height=60, spacing=1.5,
                   headings=1, camera_pitch_deg=2.0, camera_roll_deg=-1.0,
                   camera_height=1.05, compression='jpeg', encoding='mono8')
    write_bag(room, spec, tmp_path / 'tilted')
    static = _read(tmp_path / 'tilted')['/tf_static'][0][1].transforms[0]
    assert static.transform.translation.z == pytest.approx(1.05)
    exploration = read_exploration(tmp_path / 'tilted')
    assert tilt_angles(exploration.camera_tilt) == pytest.approx((2.0, -1.0), abs=1e-9)
    camera = exploration.camera_model()
    assert isinstance(camera, TiltedCamera) and camera.camera == spec.camera_model()
    # The heading of the pitched optical axis is still the base's.
    assert exploration.camera_poses()[:, 2] == pytest.approx(exploration.base_poses()[:, 2],
                                                             abs=1e-9)
    with pytest.raises(WorldsError, match='pitch must be within 45'):
        BagSpec(camera_pitch_deg=60.0).check()


def test_vibration_tilts_each_frame_and_the_ground_truth_says_by_how_much(tmp_path, room):
    from vbn_common.exploration import read_exploration
    from vbn_common.geometry.mount import tilt_angles

    spec = BagSpec(kind='exploration', camera='panoramic', width=128, height=32, spacing=1.5,
                   vibration_deg=0.5, compression='jpeg', encoding='mono8')
    write_bag(room, spec, tmp_path / 'shaky')
    exploration = read_exploration(tmp_path / 'shaky')
    assert exploration.camera_tilt is None          # the mount itself is level
    angles = np.array([tilt_angles(f.camera_tilt) for f in exploration.frames])
    # Each frame's own pitch and roll, drawn as the renderer drew them (seed, frame, 7).
    drawn = np.array([np.clip(np.random.default_rng([0, i, 7]).normal(0.0, 0.5, 2), -2, 2)
                      for i in range(len(exploration.frames))])
    np.testing.assert_allclose(angles, drawn, atol=1e-6)
    assert 0.2 < angles.std() < 0.8
    # The planar pose is untouched: the heading is the base's yaw.
    assert exploration.camera_poses()[:, 2] == pytest.approx(
        exploration.base_poses()[:, 2], abs=0.05)
    with pytest.raises(WorldsError, match='vibration must be 0 to 5 degrees'):
        BagSpec(vibration_deg=-1.0).check()
