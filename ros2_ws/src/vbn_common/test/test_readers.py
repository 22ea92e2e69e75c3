"""Three independent readers agree on our bags: rosbags, mcap + mcap-ros2-support, and evo.

Run on a small synthetic bag written here and on every sample bag in ``bags/`` (a bag
directory with a ``.mcap``): the same topics, message counts, order and content from
rosbags' ``AnyReader`` and from the ``mcap`` reader's ``mcap_ros2`` decoding, every
message compared field by field; and ``evo_traj bag2 BAG /ground_truth/pose
--save_as_tum`` gives the same trajectory.
"""
from __future__ import annotations

from collections import Counter
from pathlib import Path
import shutil
import subprocess
from typing import Any

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
from paths import REPO
import pytest
from rosbags.highlevel import AnyReader

from vbn_common.bags import TYPESTORE, BagWriter, bag_paths, default_qos, open_bag

pytestmark = pytest.mark.integration

T = TYPESTORE.types
REPO = REPO
SAMPLE_BAGS = bag_paths(REPO / 'bags')  # every sample bag that exists


def header(stamp_ns: int, frame: str) -> object:
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
        frame_id=frame)


def write_small_bag(path: Path) -> None:
    """Images, camera info, poses, odometry and /tf over 2 s, like a short run bag."""
    rng = np.random.default_rng(11)
    t0 = 1_763_769_600 * 10**9
    with BagWriter(path) as bag:
        image = bag.add_topic('/camera/image_raw', 'sensor_msgs/msg/Image', [default_qos()])
        info = bag.add_topic('/camera/camera_info', 'sensor_msgs/msg/CameraInfo')
        pose = bag.add_topic('/ground_truth/pose', 'geometry_msgs/msg/PoseStamped')
        odom = bag.add_topic('/odom', 'nav_msgs/msg/Odometry')
        tf = bag.add_topic('/tf', 'tf2_msgs/msg/TFMessage')
        for i in range(100):  # odometry at 50 Hz, the rest at 10 Hz
            stamp = t0 + i * 20_000_000
            yaw = 0.03 * i
            quat = T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=np.sin(yaw / 2),
                                                     w=np.cos(yaw / 2))
            point = T['geometry_msgs/msg/Point'](x=0.01 * i, y=0.02 * np.sin(i / 7), z=0.0)
            p = T['geometry_msgs/msg/Pose'](position=point, orientation=quat)
            cov = rng.normal(size=36)
            bag.write(odom, stamp, T['nav_msgs/msg/Odometry'](
                header=header(stamp, 'odom'), child_frame_id='base_link',
                pose=T['geometry_msgs/msg/PoseWithCovariance'](pose=p, covariance=cov),
                twist=T['geometry_msgs/msg/TwistWithCovariance'](
                    twist=T['geometry_msgs/msg/Twist'](
                        linear=T['geometry_msgs/msg/Vector3'](x=0.5, y=0.0, z=0.0),
                        angular=T['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=1.5)),
                    covariance=cov)))
            if i % 5:
                continue
            bag.write(pose, stamp, T['geometry_msgs/msg/PoseStamped'](
                header=header(stamp, 'map'), pose=p))
            bag.write(image, stamp, T['sensor_msgs/msg/Image'](
                header=header(stamp, 'camera'), height=32, width=128, encoding='mono8',
                is_bigendian=0, step=128, data=rng.integers(0, 256, 32 * 128, dtype=np.uint8)))
            bag.write(info, stamp, T['sensor_msgs/msg/CameraInfo'](
                header=header(stamp, 'camera'), height=32, width=128,
                distortion_model='cylindrical', d=np.zeros(0),
                k=np.array([20.4, 0, 64, 0, 20.4, 16, 0, 0, 1.0]), r=np.eye(3).ravel(),
                p=np.zeros(12), binning_x=0, binning_y=0,
                roi=T['sensor_msgs/msg/RegionOfInterest'](
                    x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)))
            transform = T['geometry_msgs/msg/TransformStamped'](
                header=header(stamp, 'map'), child_frame_id='base_link',
                transform=T['geometry_msgs/msg/Transform'](
                    translation=T['geometry_msgs/msg/Vector3'](x=point.x, y=point.y, z=0.0),
                    rotation=quat))
            bag.write(tf, stamp, T['tf2_msgs/msg/TFMessage'](transforms=[transform]))


@pytest.fixture(scope='module')
def synthetic_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('readers') / 'small_run'
    write_small_bag(path)
    return path


@pytest.fixture(params=['synthetic', *[p.name for p in SAMPLE_BAGS]])
def bag_dir(request: pytest.FixtureRequest, synthetic_bag: Path) -> Path:
    return synthetic_bag if request.param == 'synthetic' else REPO / 'bags' / request.param


def plain(value: Any) -> Any:
    """A rosbags or an mcap_ros2 message as nested plain values (bytes for uint8 arrays)."""
    if isinstance(value, np.ndarray):
        return value.tobytes() if value.dtype == np.uint8 else tuple(value.tolist())
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    if isinstance(value, (list, tuple)):
        return tuple(plain(v) for v in value)
    if hasattr(value, '__dataclass_fields__'):  # rosbags
        return {k: plain(getattr(value, k)) for k in value.__dataclass_fields__
                if k != '__msgtype__'}
    if hasattr(value, '__slots__') and hasattr(value, '__dict__'):  # mcap_ros2 dynamic
        return {k: plain(getattr(value, k)) for k in value.__slots__}
    if isinstance(value, np.generic):
        return value.item()
    return value


def read_rosbags(bag: Path) -> list[tuple[str, int, Any]]:
    with AnyReader([bag], default_typestore=TYPESTORE) as reader:
        return [(conn.topic, stamp, plain(reader.deserialize(raw, conn.msgtype)))
                for conn, stamp, raw in reader.messages()]


def read_mcap(bag: Path) -> list[tuple[str, int, Any]]:
    out = []
    for file in sorted(bag.glob('*.mcap')):
        with file.open('rb') as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            out.extend((channel.topic, message.log_time, plain(decoded))
                       for _, channel, message, decoded in reader.iter_decoded_messages())
    return out


def test_rosbags_and_mcap_readers_agree(bag_dir: Path) -> None:
    by_rosbags = read_rosbags(bag_dir)
    by_mcap = read_mcap(bag_dir)
    assert by_rosbags, f'{bag_dir} has no messages'
    with open_bag(bag_dir) as ours:
        counts = {name: info.count for name, info in ours.topics.items()}
        assert not ours.warnings
    assert Counter(t for t, _, _ in by_rosbags) == Counter(t for t, _, _ in by_mcap) == \
        Counter({k: v for k, v in counts.items() if v})
    # Same messages in the same time order (ties between topics may interleave).
    key = lambda m: (m[1], m[0])  # noqa: E731
    assert len(by_rosbags) == len(by_mcap)
    for a, b in zip(sorted(by_rosbags, key=key), sorted(by_mcap, key=key)):
        assert a[:2] == b[:2]
        assert a[2] == b[2], f'{a[0]} at {a[1]} differs'


def test_evo_reads_the_ground_truth_trajectory(bag_dir: Path, tmp_path: Path) -> None:
    evo_traj = shutil.which('evo_traj')
    if evo_traj is None:
        pytest.skip('evo is not installed (it is in requirements.txt: run make setup)')
    with open_bag(bag_dir) as ours:
        if '/ground_truth/pose' not in ours.topics:
            pytest.skip(f'{bag_dir.name} has no /ground_truth/pose')
        poses = [ours.deserialize(raw, msgtype) for _, msgtype, _, raw in
                 ours.messages(topics=['/ground_truth/pose'])]
    result = subprocess.run(
        [evo_traj, 'bag2', str(bag_dir), '/ground_truth/pose', '--save_as_tum'],
        cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    tum = np.loadtxt(tmp_path / 'ground_truth_pose.tum', ndmin=2)
    assert tum.shape == (len(poses), 8)
    expected = np.array([
        [p.header.stamp.sec + p.header.stamp.nanosec * 1e-9,
         p.pose.position.x, p.pose.position.y, p.pose.position.z,
         p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z,
         p.pose.orientation.w] for p in poses])
    np.testing.assert_allclose(tum[:, 0], expected[:, 0], rtol=0, atol=1e-6)
    np.testing.assert_allclose(tum[:, 1:], expected[:, 1:], rtol=0, atol=1e-9)
