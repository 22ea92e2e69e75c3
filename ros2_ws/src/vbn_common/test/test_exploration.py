"""Tests of vbn_common.exploration: the sample bags, pose sources and bad input."""
from __future__ import annotations

import logging
import math
from pathlib import Path

from exploration_samples import (
    IMAGE,
    INFO,
    OPTICAL,
    POSE,
    T0,
    TF,
    H,
    T,
    W,
    exploration_messages,
    header,
    image,
    info,
    planar,
    pose,
    transform,
    write_bag,
)
import numpy as np
from paths import REPO
import pytest

from vbn_common.bags import BagWriter, open_bag
from vbn_common.errors import VbnCommonError
from vbn_common.exploration import ReadConfig, read_exploration
from vbn_common.images import decode_image

ROOT = REPO
ROOM = ROOT / 'bags' / 'room_exploration'


# -- the committed sample --------------------------------------------------------------
@pytest.fixture(scope='module')
def room() -> object:
    return read_exploration(ROOM)


def ground_truth(path: Path) -> dict[int, tuple[float, float, float]]:
    out = {}
    with open_bag(path) as bag:
        for _, msgtype, _, raw in bag.messages(topics=['/ground_truth/pose']):
            msg = bag.deserialize(raw, msgtype)
            q = msg.pose.orientation
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            out[stamp] = (msg.pose.position.x, msg.pose.position.y,
                          2 * math.atan2(q.z, q.w))
    return out


def test_room_sample_has_200_frames_with_ground_truth_poses(room) -> None:
    assert len(room.frames) == 200
    assert room.pose_source == 'ground_truth'
    assert room.skipped == {'bad_image': 0, 'no_pose': 0, 'invalid_pose': 0}
    assert room.topics == {'image': '/camera/image_raw/compressed',
                           'camera_info': '/camera/camera_info', 'pose': '/ground_truth/pose'}
    assert room.frame_ids == {'map': 'map', 'base': 'base_link', 'camera': 'camera'}
    assert not room.warnings
    info = room.camera_info
    assert (info.width, info.height, info.distortion_model, info.d) == (1024, 256,
                                                                        'cylindrical', ())
    assert info.k[2] == 512.0 and info.k[5] == 128.0 and info.frame_id == 'camera'
    truth = ground_truth(ROOM)
    expected = np.array([truth[f.stamp_ns] for f in room.frames])
    assert np.array_equal(room.base_poses(), expected)
    # The camera sits above base_link looking along its x axis: same planar pose.
    assert np.allclose(room.camera_poses(), expected, atol=1e-12)
    assert all(f.topic == '/camera/image_raw/compressed' and f.image.compressed
               for f in room.frames)
    assert decode_image(room.frames[0].image).shape == (256, 1024)
    assert np.all(np.diff(room.stamps_ns()) == 10**9)


def test_room_sample_without_ground_truth_uses_tf(room, tmp_path: Path) -> None:
    stripped = tmp_path / 'no_truth'
    with open_bag(ROOM) as src, BagWriter(stripped) as dst:
        connections = {}
        for topic, msgtype, stamp, raw in src.messages():
            if topic == '/ground_truth/pose':
                continue
            if topic not in connections:
                connections[topic] = dst.add_topic(topic, msgtype,
                                                   src.topics[topic].qos_profiles)
            dst.write_raw(connections[topic], stamp, raw)
    with open_bag(stripped) as bag:
        assert '/ground_truth/pose' not in bag.topics
    from_tf = read_exploration(stripped)
    assert from_tf.pose_source == 'tf' and from_tf.topics['pose'] == '/tf'
    assert len(from_tf.frames) == 200
    assert np.array_equal(from_tf.stamps_ns(), room.stamps_ns())
    assert np.abs(from_tf.camera_poses() - room.camera_poses()).max() <= 1e-9
    assert np.abs(from_tf.base_poses() - room.base_poses()).max() <= 1e-9
    assert [f.image for f in from_tf.frames] == [f.image for f in room.frames]


# -- pose sources on small bags -----------------------------------------------------------
def test_camera_offset_and_heading_from_tf_static(tmp_path: Path) -> None:
    # Camera 0.1 m ahead of base_link, optical frame: heading = base yaw.
    bag = write_bag(tmp_path / 'b', exploration_messages(3, with_tf=True))
    for source in ('ground_truth', 'tf'):
        out = read_exploration(bag, ReadConfig(pose_source=source))
        assert out.pose_source == source
        for i, frame in enumerate(out.frames):
            yaw = 0.5 * i
            assert frame.base_pose == pytest.approx((i, 2 * i, yaw), abs=1e-12)
            assert frame.camera_pose == pytest.approx(
                (i + 0.1 * math.cos(yaw), 2 * i + 0.1 * math.sin(yaw), yaw), abs=1e-12)


def test_body_convention_camera_frame(tmp_path: Path) -> None:
    # A camera frame turned 90 degrees left of base_link, looking along its own x axis.
    messages = exploration_messages(2, with_static=False)
    messages.insert(0, ('/tf_static', TF, T0, T[TF](transforms=[transform(
        T0, 'base_link', 'camera', (0.0, 0.0, 1.0),
        (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)))])))
    out = read_exploration(write_bag(tmp_path / 'b', messages),
                           ReadConfig(camera_forward_axis='x'))
    assert out.frames[1].camera_pose == pytest.approx((1.0, 2.0, 0.5 + math.pi / 2))


def test_map_odom_base_link_chain(tmp_path: Path) -> None:
    messages = [('/tf_static', TF, T0, T[TF](transforms=[
        transform(T0, 'base_link', 'camera', (0.0, 0.0, 1.0), OPTICAL)]))]
    for i in range(3):
        t = T0 + i * 10**9
        messages += [('/camera/image_raw', IMAGE, t, image(t)),
                     ('/camera/camera_info', INFO, t, info(t)),
                     ('/tf', TF, t + 10**6, T[TF](transforms=[  # 1 ms late: within tolerance
                         planar(t, 'map', 'odom', 1.0, 0.0, math.pi / 2),
                         planar(t, 'odom', 'base_link', float(i), 0.0, 0.0)]))]
    out = read_exploration(write_bag(tmp_path / 'b', messages))
    assert out.pose_source == 'tf'
    assert out.base_poses() == pytest.approx(
        np.array([[1.0, i, math.pi / 2] for i in range(3)]), abs=1e-12)


def test_both_image_topics_prefers_raw(tmp_path: Path) -> None:
    messages = exploration_messages(2)
    messages.append(('/camera/image_raw/compressed', 'sensor_msgs/msg/CompressedImage',
                     T0, T['sensor_msgs/msg/CompressedImage'](
                         header=header(T0, 'camera'), format='jpeg',
                         data=np.zeros(4, np.uint8))))
    out = read_exploration(write_bag(tmp_path / 'b', messages))
    assert out.topics['image'] == '/camera/image_raw' and len(out.frames) == 2


# -- bad input ----------------------------------------------------------------------------
def test_empty_bag(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'empty') as bag:
        bag.add_topic('/camera/image_raw', IMAGE)
    with pytest.raises(VbnCommonError, match=r'^bag .*empty contains no messages$'):
        read_exploration(tmp_path / 'empty')


def test_bag_without_images(tmp_path: Path) -> None:
    messages = [m for m in exploration_messages(2) if m[0] != '/camera/image_raw']
    with pytest.raises(VbnCommonError, match=r'has no images: no messages on '
                       r'/camera/image_raw or '
                       r'/camera/image_raw/compressed$'):
        read_exploration(write_bag(tmp_path / 'b', messages))


def test_bag_without_camera_info(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'b', exploration_messages(2, with_info=False))
    with pytest.raises(VbnCommonError,
                       match=r'has no camera info: no messages on /camera/camera_info$'):
        read_exploration(bag)


def test_bag_without_pose_source(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'b', exploration_messages(2, with_truth=False))
    with pytest.raises(VbnCommonError,
                       match=r'has no pose source: no messages on /ground_truth/pose or /tf$'):
        read_exploration(bag)


def test_tf_without_a_map_to_base_link_chain(tmp_path: Path) -> None:
    messages = exploration_messages(2, with_truth=False)
    messages.append(('/tf', TF, T0, T[TF](transforms=[
        planar(T0, 'odom', 'base_link', 0.0, 0.0, 0.0)])))
    with pytest.raises(VbnCommonError, match='no transform chain map -> base_link'):
        read_exploration(write_bag(tmp_path / 'b', messages))


def test_bad_step_size_and_encoding_are_skipped_with_warnings(tmp_path: Path, caplog) -> None:
    t = [T0 + i * 10**9 for i in range(5)]
    images = [image(t[0]), image(t[1], step=5), image(t[2], size=W * H - 1),
              image(t[3], encoding='yuv422'), image(t[4], encoding='bgr8')]
    bag = write_bag(tmp_path / 'b', exploration_messages(5, images=images))
    with caplog.at_level(logging.WARNING):
        out = read_exploration(bag)
    assert [f.stamp_ns for f in out.frames] == [t[0], t[4]]
    assert out.skipped == {'bad_image': 3, 'no_pose': 0, 'invalid_pose': 0}
    text = '\n'.join(out.warnings)
    assert 'image 8x6 mono8 needs step >= 8, got 5' in text
    assert 'image 8x6 mono8 with step 8 needs 48 bytes of data, got 47' in text
    assert "unsupported image encoding 'yuv422'" in text
    assert all(w in caplog.text for w in out.warnings)
    assert decode_image(out.frames[1].image).tolist() == [[7] * W] * H


def test_raw_image_size_must_match_camera_info(tmp_path: Path) -> None:
    odd = T[IMAGE](header=header(T0, 'camera'), height=2, width=3, encoding='mono8',
                   is_bigendian=0, step=3, data=np.zeros(6, np.uint8))
    bag = write_bag(tmp_path / 'b', exploration_messages(2, images=[odd, image(T0 + 10**9)]))
    out = read_exploration(bag)
    assert len(out.frames) == 1 and out.skipped['bad_image'] == 1
    assert 'image 3x2 mono8 does not match the camera info size 8x6' in out.warnings[0]


def test_only_bad_images_is_an_error(tmp_path: Path) -> None:
    images = [image(T0 + i * 10**9, encoding='yuv422') for i in range(2)]
    with pytest.raises(VbnCommonError,
                       match=r"no usable images in bag .*: all 2 on /camera/image_raw are bad "
                             r"\(unsupported image encoding 'yuv422'"):
        read_exploration(write_bag(tmp_path / 'b', exploration_messages(2, images=images)))


def test_nan_pose_is_skipped_with_a_warning(tmp_path: Path) -> None:
    poses = [pose(T0, 0.0, 0.0, 0.0), pose(T0 + 10**9, math.nan, 1.0, 0.0),
             pose(T0 + 2 * 10**9, 2.0, 4.0, 1.0)]
    out = read_exploration(write_bag(tmp_path / 'b', exploration_messages(3, poses=poses)))
    assert [f.stamp_ns for f in out.frames] == [T0, T0 + 2 * 10**9]
    assert out.skipped == {'bad_image': 0, 'no_pose': 0, 'invalid_pose': 1}
    assert out.warnings == (
        'skipped 1 of 3 image(s): their pose from /ground_truth/pose is invalid '
        f'(NaN or infinite values or a zero quaternion; first at stamp {T0 + 10**9})',)


def test_zero_quaternion_and_all_invalid_poses_is_an_error(tmp_path: Path) -> None:
    poses = [pose(T0 + i * 10**9, 0.0, 0.0, 0.0) for i in range(2)]
    for p in poses:
        p.pose.orientation.w = 0.0
    with pytest.raises(VbnCommonError, match=r'none of the 2 on /camera/image_raw has a '
                       r'valid pose .*invalid_pose 2'):
        read_exploration(write_bag(tmp_path / 'b', exploration_messages(2, poses=poses)))


def test_pose_outside_tolerance_is_skipped(tmp_path: Path) -> None:
    late = T0 + 10**9 + 200_000_000  # 0.2 s after the second image
    poses = [pose(T0, 0.0, 0.0, 0.0), pose(late, 1.0, 2.0, 0.5), pose(T0 + 2 * 10**9, 2, 4, 1)]
    bag = write_bag(tmp_path / 'b', exploration_messages(3, poses=poses))
    out = read_exploration(bag)
    assert out.skipped['no_pose'] == 1 and len(out.frames) == 2
    assert 'no pose from /ground_truth/pose within 0.05 s' in out.warnings[0]
    wide = read_exploration(bag, ReadConfig(pose_tolerance_s=0.3))
    assert len(wide.frames) == 3 and wide.frames[1].base_pose == pytest.approx((1, 2, 0.5))


def test_tilted_pose_and_changing_camera_info_warn(tmp_path: Path) -> None:
    messages = exploration_messages(2)
    tilted = pose(T0, 0.0, 0.0, 0.0)
    s = math.sin(0.1 / 2)  # roll 0.1 rad = 5.7 degrees
    tilted.pose.orientation = T['geometry_msgs/msg/Quaternion'](x=s, y=0.0, z=0.0,
                                                                w=math.cos(0.05))
    assert messages[3][0] == '/ground_truth/pose' and messages[5][0] == '/camera/camera_info'
    messages[3] = ('/ground_truth/pose', POSE, T0, tilted)
    messages[5] = ('/camera/camera_info', INFO, T0 + 10**9, info(T0 + 10**9, fx=5.0))
    out = read_exploration(write_bag(tmp_path / 'b', messages))
    assert len(out.frames) == 2 and out.camera_info.k[0] == 4.0
    text = '\n'.join(out.warnings)
    assert 'camera info on /camera/camera_info changes in 1 message(s)' in text
    assert '1 of 2 pose(s) are not planar (base_link tilted up to 5.7 deg' in text


def test_a_static_mount_that_changes_mid_bag_is_one_warning(tmp_path: Path) -> None:
    # The camera remounted between the two frames: 0.1 m -> 0.3 m ahead of base_link.
    messages = exploration_messages(2)
    messages.append(('/tf_static', TF, T0 + 10**9 // 2, T[TF](transforms=[
        transform(T0 + 10**9 // 2, 'base_link', 'camera', (0.3, 0.0, 1.2), OPTICAL)])))
    out = read_exploration(write_bag(tmp_path / 'b', sorted(messages, key=lambda m: m[2])))
    changed = [w for w in out.warnings if 'changes during the bag' in w]
    assert changed == ['the static transform base_link -> camera changes during the bag (by '
                       '0.00 deg and 0.200 m): every frame uses its last value (tf2 keeps the '
                       'newest static transform)']
    assert len(out.frames) == 2
    assert out.frames[0].camera_pose == pytest.approx((0.3, 0.0, 0.0), abs=1e-12)
    # The same transform sent twice is no change.
    again = exploration_messages(2) + [('/tf_static', TF, T0 + 10**9 // 2, T[TF](transforms=[
        transform(T0 + 10**9 // 2, 'base_link', 'camera', (0.1, 0.0, 1.2), OPTICAL)]))]
    out = read_exploration(write_bag(tmp_path / 'c', sorted(again, key=lambda m: m[2])))
    assert not [w for w in out.warnings if 'changes during the bag' in w]


def test_missing_camera_transform_assumes_the_base_heading(tmp_path: Path) -> None:
    out = read_exploration(write_bag(tmp_path / 'b', exploration_messages(2, with_static=False)))
    assert 'no transform base_link -> camera' in out.warnings[0]
    assert np.array_equal(out.camera_poses(), out.base_poses())


def test_bad_config_values() -> None:
    with pytest.raises(VbnCommonError, match='pose_source must be one of auto'):
        ReadConfig(pose_source='odom')
    with pytest.raises(VbnCommonError, match='pose_tolerance_s must be a non-negative'):
        ReadConfig(pose_tolerance_s=-1.0)
    with pytest.raises(VbnCommonError, match="camera_forward_axis must be 'x' or 'z'"):
        ReadConfig(camera_forward_axis='y')


def test_missing_bag_is_a_one_line_error(tmp_path: Path) -> None:
    with pytest.raises(VbnCommonError, match='does not exist'):
        read_exploration(tmp_path / 'nothing')


def test_wrong_message_type_on_a_topic(tmp_path: Path) -> None:
    messages = [m for m in exploration_messages(2) if m[0] != '/ground_truth/pose']
    messages.append(('/ground_truth/pose', 'std_msgs/msg/String', T0,
                     T['std_msgs/msg/String'](data='here')))
    with pytest.raises(VbnCommonError,
                       match=r'/ground_truth/pose has type std_msgs/msg/String, expected '
                             r'geometry_msgs/msg/PoseStamped or '):
        read_exploration(write_bag(tmp_path / 'b', messages))
