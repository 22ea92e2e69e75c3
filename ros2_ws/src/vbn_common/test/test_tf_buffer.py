"""The tf buffer of the exploration reader: chains composed at many stamps, by hand."""
from __future__ import annotations

from types import SimpleNamespace as Ns

import numpy as np
import pytest

from vbn_common.tf_buffer import TfBuffer, nearest_stamps, quaternion_matrices


def _tf(parent, child, xyz, quat=(0.0, 0.0, 0.0, 1.0)):
    return Ns(header=Ns(frame_id=parent), child_frame_id=child,
              transform=Ns(translation=Ns(x=xyz[0], y=xyz[1], z=xyz[2]),
                           rotation=Ns(x=quat[0], y=quat[1], z=quat[2], w=quat[3])))


def test_quaternion_matrices_rotate_about_z_and_reject_zero():
    s = np.sqrt(0.5)
    r = quaternion_matrices([[0, 0, s, s], [0, 0, 0, 0]])
    assert np.allclose(r[0] @ [1, 0, 0], [0, 1, 0])
    assert np.isnan(r[1]).all()


def test_nearest_stamps_and_gaps():
    index, gap = nearest_stamps(np.array([0, 10, 20]), np.array([4, 6, 25]))
    assert index.tolist() == [0, 1, 2] and gap.tolist() == [4, 4, 5]


def test_chain_map_odom_base_camera_at_two_stamps():
    s = np.sqrt(0.5)
    tf = TfBuffer()
    tf.add(_tf('map', 'odom', (1.0, 0.0, 0.0), (0, 0, s, s)), 0, static=True)  # yaw 90
    tf.add(_tf('odom', 'base_link', (2.0, 0.0, 0.0)), 100, static=False)
    tf.add(_tf('odom', 'base_link', (3.0, 0.0, 0.0)), 200, static=False)
    tf.add(_tf('base_link', 'camera', (0.0, 0.0, 0.5)), 0, static=True)
    assert tf.chain('map', 'camera') == ['camera', 'base_link', 'odom', 'map']
    rotation, translation, found = tf.lookup('map', 'camera', np.array([110, 190, 500]), 20)
    # map->odom turns odom's x into map's y: base at odom x=2 is at map (1, 2)
    assert np.allclose(translation[0], [1.0, 2.0, 0.5])
    assert np.allclose(translation[1], [1.0, 3.0, 0.5])
    assert found.tolist() == [True, True, False]       # 500 is 300 ns from any sample
    assert np.allclose(rotation[0] @ [1, 0, 0], [0, 1, 0])
    assert tf.lookup('map', 'nowhere', np.array([0]), 10) is None


def test_a_second_parent_is_a_conflict_and_static_replaces():
    tf = TfBuffer()
    tf.add(_tf('base_link', 'camera', (0.0, 0.0, 0.5)), 0, static=True)
    tf.add(_tf('base_link', 'camera', (0.0, 0.0, 0.7)), 5, static=True)
    tf.add(_tf('odom', 'camera', (0.0, 0.0, 0.0)), 6, static=False)
    assert tf.conflicts == {'camera (parents base_link and odom)'}
    _, translation, _ = tf.lookup('base_link', 'camera', np.array([0]), 0)
    assert np.allclose(translation[0], [0, 0, 0.7])


def test_rotation_angles_between_rotations() -> None:
    from vbn_common.tf_buffer import rotation_angles_deg

    def rot_z(deg: float) -> np.ndarray:
        c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    many = np.stack([rot_z(d) for d in (0.0, 30.0, -90.0, 180.0)])
    assert rotation_angles_deg(np.eye(3), many) == pytest.approx([0.0, 30.0, 90.0, 180.0])
    assert float(rotation_angles_deg(rot_z(10.0), rot_z(45.0))) == pytest.approx(35.0)
    assert np.isnan(rotation_angles_deg(np.eye(3), np.full((3, 3), np.nan)))


def test_stamps_that_go_back_are_refused_jitter_is_not():
    """An odometry reset (stamps back by 2 s) would interleave two histories once sorted."""
    from vbn_common.errors import VbnCommonError

    second = 1_000_000_000
    jitter = TfBuffer()
    for stamp in (0, 2 * second, int(1.9 * second), 3 * second):     # 0.1 s out of order
        jitter.add(_tf('odom', 'base_link', (stamp / second, 0.0, 0.0)), stamp, static=False)
    _, translation, found = jitter.lookup('odom', 'base_link', np.array([int(1.9 * second)]),
                                          10)
    assert found.all() and translation[0, 0] == pytest.approx(1.9)
    reset = TfBuffer()
    for stamp in (0, second, 2 * second, int(0.5 * second), second):
        reset.add(_tf('odom', 'base_link', (0.0, 0.0, 0.0)), stamp, static=False)
    with pytest.raises(VbnCommonError, match=r'odom -> base_link: stamps go back by 1\.50 s'):
        reset.lookup('odom', 'base_link', np.array([0]), 10)
