from __future__ import annotations

import json
import math
from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.transforms import StampedTransform, compose, correction, inverse


def test_planar_compose_by_hand() -> None:
    # odom -> base_link: 1 m ahead along x, turned 90 degrees; base -> camera: 0.5 m ahead.
    odom_base = StampedTransform.planar(1, 'odom', 'base_link', 1.0, 0.0, math.pi / 2)
    base_cam = StampedTransform.planar(1, 'base_link', 'camera', 0.5, 0.0, 0.0)
    odom_cam = compose(odom_base, base_cam)
    assert (odom_cam.parent, odom_cam.child) == ('odom', 'camera')
    np.testing.assert_allclose(odom_cam.translation, [1.0, 0.5, 0.0], atol=1e-12)
    assert odom_cam.yaw == pytest.approx(math.pi / 2)


def test_inverse_by_hand() -> None:
    a = StampedTransform.planar(3, 'map', 'odom', 2.0, 0.0, math.pi / 2)
    b = inverse(a)
    assert (b.parent, b.child, b.stamp_ns) == ('odom', 'map', 3)
    np.testing.assert_allclose(b.translation, [0.0, 2.0, 0.0], atol=1e-12)
    assert b.yaw == pytest.approx(-math.pi / 2)


def test_correction_by_hand() -> None:
    # Odometry drifted: it believes base_link is at (1, 0), the truth is (1, 1).
    map_base = StampedTransform.planar(10, 'map', 'base_link', 1.0, 1.0, 0.0)
    odom_base = StampedTransform.planar(9, 'odom', 'base_link', 1.0, 0.0, 0.0)
    map_odom = correction(map_base, odom_base, stamp_ns=12)
    assert (map_odom.parent, map_odom.child, map_odom.stamp_ns) == ('map', 'odom', 12)
    np.testing.assert_allclose(map_odom.translation, [0.0, 1.0, 0.0], atol=1e-12)


poses = st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-math.pi, math.pi))


@given(poses, poses)
@settings(max_examples=200, deadline=None)
def test_correction_restores_the_estimate(map_base: tuple, odom_base: tuple) -> None:
    est = StampedTransform.planar(1, 'map', 'base_link', *map_base)
    odo = StampedTransform.planar(1, 'odom', 'base_link', *odom_base)
    chained = compose(correction(est, odo), odo)
    np.testing.assert_allclose(chained.translation, est.translation, atol=1e-9)
    assert math.remainder(chained.yaw - est.yaw, 2 * math.pi) == pytest.approx(0, abs=1e-9)


def test_bad_transforms_are_refused() -> None:
    with pytest.raises(VbnCommonError, match='two different frame ids'):
        StampedTransform.planar(0, 'map', 'map', 0, 0, 0)
    with pytest.raises(VbnCommonError, match='not finite'):
        StampedTransform.planar(0, 'map', 'odom', float('nan'), 0, 0)
    with pytest.raises(VbnCommonError, match='cannot chain'):
        compose(StampedTransform.planar(0, 'map', 'odom', 0, 0, 0),
                StampedTransform.planar(0, 'base_link', 'camera', 0, 0, 0))


def test_workspace_tf2_msgs_has_the_jazzy_type_hash() -> None:
    # The hash a full ROS 2 Jazzy install computes (rosbags' Jazzy store derives it from
    # the upstream definitions) equals the one rosidl generated for our tf2_msgs.
    from ament_index_python.packages import get_package_share_directory
    from rosbags.typesys import Stores, get_typestore
    from tf2_msgs.msg import TFMessage  # noqa: F401 - importable from the workspace

    share = Path(get_package_share_directory('tf2_msgs'))
    store = get_typestore(Stores.ROS2_JAZZY)
    for name in ('TFMessage', 'TF2Error'):
        description = json.loads((share / 'msg' / f'{name}.json').read_text())
        generated = {h['type_name']: h['hash_string'] for h in description['type_hashes']}
        assert generated[f'tf2_msgs/msg/{name}'] == store.hash_rihs01(f'tf2_msgs/msg/{name}')
