"""Message conversions of the localizer node, and its once-per-kind warnings."""
from __future__ import annotations

import math
import os
import subprocess
import sys
import threading

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo

from landmark_localizer import conversions
from landmark_localizer.camera_check import camera_mismatch
from landmark_localizer.errors import LocalizerError
from landmark_localizer.localizer import Estimate
from landmark_localizer.node_support import FrameStats, Mailbox, Warnings, reason_kind
from vbn_common.geometry.camera import PanoramicCamera, PinholeCamera


def estimate(pose=(1.0, 2.0, 0.5), cov=None) -> Estimate:
    cov = np.diag([0.01, 0.04, 0.0025]) if cov is None else cov
    return Estimate(1_735_689_600_100_000_000, 'TRACKING', 3,
                    None if pose is None else np.array(pose), cov, None, 20, '', 0.01)


def test_stamps_round_trip() -> None:
    ns = 1_735_689_600_123_456_789
    stamp = conversions.ns_to_stamp(ns)
    assert (stamp.sec, stamp.nanosec) == (1_735_689_600, 123_456_789)
    assert conversions.stamp_to_ns(stamp) == ns


def test_pose_messages_carry_stamp_frame_yaw_and_covariance() -> None:
    pose, with_cov = conversions.pose_messages(estimate(), 'map')
    assert pose.header.frame_id == 'map' and with_cov.header.frame_id == 'map'
    assert conversions.stamp_to_ns(pose.header.stamp) == 1_735_689_600_100_000_000
    q = pose.pose.orientation
    assert 2 * math.atan2(q.z, q.w) == pytest.approx(0.5)
    assert (pose.pose.position.x, pose.pose.position.y) == (1.0, 2.0)
    cov = np.array(with_cov.pose.covariance).reshape(6, 6)
    assert (cov[0, 0], cov[1, 1], cov[5, 5]) == (0.01, 0.04, 0.0025)
    assert cov[2, 2] == cov[3, 3] == cov[4, 4] == 0.0


def test_covariance_keeps_cross_terms() -> None:
    cov3 = np.array([[1.0, 0.2, 0.3], [0.2, 2.0, 0.4], [0.3, 0.4, 3.0]])
    cov = np.array(conversions.covariance_6x6(cov3)).reshape(6, 6)
    np.testing.assert_array_equal(cov[np.ix_([0, 1, 5], [0, 1, 5])], cov3)
    np.testing.assert_array_equal(cov, cov.T)


@pytest.mark.parametrize('bad', [
    {'pose': None},
    {'pose': (np.nan, 0.0, 0.0)},
    {'cov': np.full((3, 3), np.inf)},
])
def test_no_pose_message_with_nan(bad) -> None:
    assert conversions.pose_messages(estimate(**bad), 'map') is None


def test_odometry_pose() -> None:
    msg = Odometry()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 5, 20_000_000
    msg.pose.pose.position.x, msg.pose.pose.position.y = 0.5, -0.25
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(0.3), math.cos(0.3)
    stamp, pose = conversions.odometry_pose(msg)
    assert stamp == 5_020_000_000
    np.testing.assert_allclose(pose, [0.5, -0.25, 0.6])
    msg.pose.pose.position.x = float('nan')
    with pytest.raises(LocalizerError, match='pose is not finite'):
        conversions.odometry_pose(msg)
    msg.pose.pose.position.x = 0.0
    msg.pose.pose.orientation.z = msg.pose.pose.orientation.w = 0.0
    with pytest.raises(LocalizerError, match='zero quaternion'):
        conversions.odometry_pose(msg)


def test_initial_pose_hint() -> None:
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = 'map'
    msg.pose.pose.position.x, msg.pose.pose.position.y = 1.5, 2.5
    assert conversions.initial_pose_hint(msg, 'map', 1.5) == (1.5, 2.5, 1.5)
    cov = np.zeros(36)
    cov[0] = cov[7] = 1.0  # 1 m standard deviation: 3 m radius
    msg.pose.covariance = cov.tolist()
    assert conversions.initial_pose_hint(msg, 'map', 1.5)[2] == pytest.approx(3.0)
    msg.header.frame_id = 'odom'
    with pytest.raises(LocalizerError, match="initial pose is in frame 'odom'"):
        conversions.initial_pose_hint(msg, 'map', 1.5)
    msg.header.frame_id = ''
    msg.pose.pose.position.y = float('inf')
    with pytest.raises(LocalizerError, match='not finite'):
        conversions.initial_pose_hint(msg, 'map', 1.5)


def camera_info(camera) -> CameraInfo:
    fields = camera.camera_info()
    return CameraInfo(width=fields.width, height=fields.height,
                      distortion_model=fields.distortion_model, d=list(fields.d),
                      k=list(fields.k), r=list(fields.r), p=list(fields.p))


def test_camera_mismatch() -> None:
    from landmark_localizer.camera_check import frame_camera

    panorama = PanoramicCamera(1024, 256)
    assert camera_mismatch(camera_info(panorama), panorama) == ''
    assert frame_camera(camera_info(panorama), panorama) == (panorama, '')
    # Another resolution or calibration of the same kind: the frames' own camera.
    assert frame_camera(camera_info(PanoramicCamera(512, 128)), panorama) == (
        PanoramicCamera(512, 128), '')
    shifted = PanoramicCamera(1024, 256, y0=100.0)
    assert frame_camera(camera_info(shifted), panorama) == (shifted, '')
    # Another kind of camera: refused, naming both.
    pinhole = PinholeCamera.from_fov(1024, 256, 90.0)
    assert camera_mismatch(camera_info(pinhole), panorama) == (
        'CameraInfo 1024x256 pinhole (fx 512, fy 512, cx 511.5, cy 127.5) is not the kind '
        'of the database camera 1024x256 panoramic (fx 162.975, fy 162.975, cx 512, cy 128)')
    # A lens the database was not built with: named with its coefficients.
    distorted = camera_info(pinhole)
    distorted.d = [0.1, 0.0, 0.0, 0.0, 0.0]
    assert camera_mismatch(distorted, pinhole) == (
        'CameraInfo 1024x256 pinhole (fx 512, fy 512, cx 511.5, cy 127.5, plumb_bob '
        'd=[0.1, 0, 0, 0, 0]) has plumb_bob distortion, the database camera 1024x256 '
        'pinhole (fx 512, fy 512, cx 511.5, cy 127.5) none')
    lens = PinholeCamera(1024, 256, pinhole.fx, pinhole.fy, pinhole.cx, pinhole.cy,
                         distortion_model='plumb_bob', d=(0.1, 0.0, 0.0, 0.0, 0.0))
    assert camera_mismatch(distorted, lens) == ''
    # Another calibration of the same lens model: the run's coefficients are used.
    distorted.d = [0.12, 0.0, 0.0, 0.0, 0.0]
    camera, problem = frame_camera(distorted, lens)
    assert problem == '' and camera.d == (0.12, 0.0, 0.0, 0.0, 0.0)
    # The run's own mount: its rays are levelled with it.
    from vbn_common.geometry.mount import TiltedCamera, tilt_matrix
    camera, problem = frame_camera(camera_info(panorama), panorama, tilt_matrix(2.0, 0.0))
    assert problem == '' and isinstance(camera, TiltedCamera)
    assert camera.tilt == pytest.approx(tilt_matrix(2.0, 0.0))
    assert frame_camera(camera_info(panorama), panorama, np.eye(3)) == (panorama, '')
    distorted.d = [0.1, 0.0, 0.0, 0.0]   # four coefficients for plumb_bob
    assert camera_mismatch(distorted, lens).startswith(
        'CameraInfo cannot be used (plumb_bob distortion takes 5 coefficients, got 4)')


def test_diagnostic_array() -> None:
    msg = conversions.diagnostic_array(conversions.ns_to_stamp(0), 'localizer', 'room.db',
                                       DiagnosticStatus.WARN, 'LOST',
                                       {'region': -1, 'latency_p50_ms': 12.3456,
                                        'latency_p95_ms': float('nan')})
    status = msg.status[0]
    assert (status.name, status.level, status.message) == ('localizer', DiagnosticStatus.WARN,
                                                           'LOST')
    assert {kv.key: kv.value for kv in status.values} == {
        'region': '-1', 'latency_p50_ms': '12.35', 'latency_p95_ms': 'n/a'}


def test_warnings_once_per_kind_then_with_a_count() -> None:
    lines: list[str] = []
    now = [0.0]
    warnings = Warnings(lines.append, repeat_s=10.0, clock=lambda: now[0])
    for i in range(5):
        warnings.warn(reason_kind(f'image 64x{i} bad'), f'image 64x{i} bad')
    warnings.warn('other', 'other problem')
    assert lines == ['image 64x0 bad', 'other problem']
    now[0] = 11.0
    warnings.warn(reason_kind('image 64x9 bad'), 'image 64x9 bad')
    assert lines[-1] == 'image 64x9 bad (4 more since the last warning)'


def test_frame_stats_latency_window() -> None:
    stats = FrameStats(window=10)
    assert math.isnan(stats.latency_ms()['latency_p50_ms'])
    for ms in range(100):
        stats.add_latency(ms / 1e3)
    latency = stats.latency_ms()
    assert latency['latency_max_ms'] == pytest.approx(99.0)
    assert latency['latency_p50_ms'] == pytest.approx(94.5)
    stats.drop('decode')
    stats.drop('decode')
    assert stats.dropped_counts() == {'decode': 2}


def test_mailbox_keeps_only_the_newest_item_and_closes() -> None:
    box = Mailbox()
    assert box.put('a') == (False, None)
    assert box.put('b') == (True, 'a')  # 'a' was never taken: replaced, dropped
    assert box.take(timeout=0) == (True, 'b')
    assert box.take(timeout=0.01) == (False, None)  # empty: nothing after the timeout
    taken: list = []
    worker = threading.Thread(target=lambda: taken.append(box.take()))
    worker.start()
    box.put('c')
    worker.join(timeout=5)
    assert taken == [(True, 'c')]
    box.put('d')
    assert not box.closed
    box.close()
    assert box.take() == (False, None) and box.closed  # the worker stops, even with an item


def test_the_node_runs_opencv_and_openblas_on_one_thread() -> None:
    """main() calls it before the node loads: no thread pools beside the frame worker."""
    code = ('import cv2\n'
            'from landmark_localizer.node_support import one_thread_per_library\n'
            'from vbn_common.blas import _openblas_thread_controls\n'
            'cv2.setNumThreads(2)\n'
            'one_thread_per_library()\n'
            'print(cv2.getNumThreads(), [get() for get, _ in _openblas_thread_controls()])\n')
    env = {k: v for k, v in os.environ.items() if 'NUM_THREADS' not in k}
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         env=env, check=True).stdout.split(maxsplit=1)
    assert out[0] == '1'
    assert set(eval(out[1])) <= {1}   # noqa: S307 - our own printed list
