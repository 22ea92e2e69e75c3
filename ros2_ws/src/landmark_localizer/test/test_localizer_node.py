"""The localizer node over real DDS: the sample runs, the kidnapped run and bad input.

The room database is built once per session from ``bags/room_exploration``. The node
runs as ``localizer`` (the executable ``ros2 run`` starts) in a subprocess on this test
run's domain; the test process listens (and publishes bad input) with an in-process
rclpy node. Accuracy is checked against the ground truth recorded in the bags.
"""
from __future__ import annotations

import math
import subprocess
import sys
import time

from database_samples import edited_copy
from localizer_nodes import (
    BAGS,
    WAIT,
    Listener,
    Publisher,
    read_run,
    rss_kib,
    stamp_ns,
    start_localizer,
)
import numpy as np
import pytest

from landmark_db.database import SCHEMA_VERSION, open_database
from vbn_common.geometry.frames import quaternion_yaw
from vbn_common.images import decode_image

pytestmark = pytest.mark.integration











def play(start_process, ros_node, bag: str, *options: str):
    # The listener subscribes to every recorded topic, so --wait-for-subscribers starts the
    # playback only once the localizer and the listener are both connected. The listener
    # spins meanwhile, so that it hears everything.
    proc = start_process(['vbn', 'play', str(BAGS / bag), '--wait-for-subscribers',
                          '--wait-timeout', str(WAIT), *options], name='play')
    assert ros_node.spin_until(lambda: proc.popen.poll() is not None, timeout=3 * WAIT)
    assert proc.wait() == 0, proc.output
    return proc


def listen_to_bag_topics(ros_node) -> None:
    """Subscribe to the bag topics the localizer does not use (for --wait-for-subscribers)."""
    from geometry_msgs.msg import PoseStamped
    from tf2_msgs.msg import TFMessage

    from vbn_common.ros_tools.tf_broadcast import STATIC_QOS
    ros_node.node.create_subscription(PoseStamped, '/ground_truth/pose', lambda m: None, 10)
    ros_node.node.create_subscription(TFMessage, '/tf_static', lambda m: None, STATIC_QOS)


def pose_errors(listener: Listener, truth: dict) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, position errors) of the poses received."""
    stamps = np.array([stamp_ns(p.header.stamp) for p in listener.poses])
    errors = np.array([math.hypot(p.pose.position.x - truth[s][0],
                                  p.pose.position.y - truth[s][1])
                       for p, s in zip(listener.poses, stamps, strict=True)])
    return stamps, errors


def planar(transform) -> np.ndarray:
    t, q = transform.transform.translation, transform.transform.rotation
    return np.array([t.x, t.y, float(quaternion_yaw(np.array([q.x, q.y, q.z, q.w])))])


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]])


def spin_for(ros_node, seconds: float) -> None:
    ros_node.spin_until(lambda: False, timeout=seconds)


def test_room_run_poses_regions_tf_markers_diagnostics(room_db, start_process,
                                                       ros_node) -> None:
    run = read_run('room_run')
    node = start_localizer(start_process, room_db)
    listener = Listener(ros_node)
    listen_to_bag_topics(ros_node)
    started = time.monotonic()
    # Half speed: the node takes every frame even on a loaded machine (at full speed a
    # second job on the two cores made it drop 28 of 439 frames, by design: depth-1
    # queue); full-speed latency is the benchmark's, the full-speed run the demo's.
    play(start_process, ros_node, 'room_run', '--rate', '0.5')
    elapsed = time.monotonic() - started
    listener.wait_settled()
    assert node.popen.poll() is None, node.output

    # The targets for room_run, from what arrives on /localizer/pose: a pose for
    # at least 98 % of the frames, in map with the image's stamp, translation median at
    # most 1 cm and 95th percentile at most 5 cm, heading median at most 0.2 degree.
    # (Availability itself is the offline benchmark's: every frame, at its own pace.)
    image_stamps = {s for s, _ in run['images']}
    status = listener.status()
    said = (f'{len(listener.poses)} poses heard of {len(image_stamps)} frames; node '
            f'diagnostics {status}; output {node.output}')
    received, processed, published = (int(status[k]) for k in (
        'frames_received', 'frames_processed', 'poses_published'))
    # Across processes DDS loses a little on a busy machine (a fresh-clone make test: 438
    # of 439 frames reached the node, 431 of its 438 poses reached this listener);
    # the node's own share is judged on what it received.
    assert received >= 0.98 * len(image_stamps), said
    # A frame the node has no time for is dropped by design (depth-1 queue: the newest
    # frame wins); at half speed few are, and none for any other reason.
    dropped = {k for k, v in status.items() if k.startswith('dropped_') and int(v)}
    assert dropped <= {'dropped_overrun'} and processed >= 0.9 * received, said
    assert published >= 0.98 * processed, said
    assert len(listener.poses) >= 0.95 * published, said
    assert {p.header.frame_id for p in listener.poses} == {'map'}
    stamps, errors = pose_errors(listener, run['truth'])
    assert set(stamps) <= image_stamps
    assert np.all(np.diff(stamps) > 0)
    assert np.median(errors) <= 0.01 and np.percentile(errors, 95) <= 0.05, np.percentile(
        errors, [50, 95, 100])
    headings = np.array([abs(wrap(quaternion_yaw(np.array([o.x, o.y, o.z, o.w]))
                                  - run['truth'][s][2]))
                         for p, s in zip(listener.poses, stamps, strict=True)
                         for o in [p.pose.orientation]])
    assert np.degrees(np.median(headings)) <= 0.2, np.degrees(np.median(headings))
    cov = np.array([m.pose.covariance for m in listener.poses_cov])
    assert np.all(np.isfinite(cov)) and np.all(cov[:, [0, 7, 35]] > 0)
    # A region most of the time (-1 only while LOST).
    regions = np.array(listener.regions)
    assert len(regions) >= len(listener.poses) and np.mean(regions >= 0) > 0.9

    # map -> odom on /tf: with the odometry at the image stamp it gives the pose.
    assert listener.tf and {(t.header.frame_id, t.child_frame_id) for t in listener.tf} == \
        {('map', 'odom')}
    # (The transform republished between frames carries the newest odometry's stamp, so
    # a stamp may come twice: one of them is the frame's own correction.)
    by_stamp = {stamp_ns(p.header.stamp): p for p in listener.poses}
    offsets: dict[int, list[float]] = {}
    for transform in listener.tf:
        image_stamp = stamp_ns(transform.header.stamp) - 100_000_000  # transform_tolerance
        if image_stamp in by_stamp and image_stamp in run['odom']:
            base = compose(planar(transform), np.array(run['odom'][image_stamp]))
            p = by_stamp[image_stamp].pose.position
            offsets.setdefault(image_stamp, []).append(math.hypot(base[0] - p.x,
                                                                  base[1] - p.y))
    # Exact where the odometry of the image's stamp had arrived (the node waits 100 ms for
    # it: over 95 % of frames on an idle machine, 88 % measured under a full load);
    # otherwise extrapolated from the newest two messages, at most 0.1 s ahead.
    mins = np.array([min(v) for v in offsets.values()])
    assert np.mean(mins < 1e-6) > 0.8 and mins.max() < 0.15, np.sort(mins)[-5:]
    checked = len(offsets)
    assert checked >= 0.5 * len(listener.poses)

    # Region markers, latched: a subscriber that joins late still gets them.
    assert ros_node.spin_until(lambda: listener.markers, timeout=10)
    regions_markers = [m for m in listener.markers[0].markers if m.ns == 'regions']
    assert len(regions_markers) == open_database(room_db).n_regions
    assert {m.header.frame_id for m in regions_markers} == {'map'}

    status = listener.wait_status(lambda s: True)
    assert status['state'] == 'TRACKING' and int(status['region']) >= 0
    assert status['quality'] == 'good' and 0 < float(status['position_std_m']) < 0.05
    # 'none' or region ids (one landmark of 23 may never be found by a window search even
    # in the room as explored: about one region in twenty, docs/db_update.md).
    stale = status['stale_regions']
    n_regions = open_database(room_db).n_regions
    assert stale == 'none' or all(0 <= int(r) < n_regions for r in stale.split(','))
    assert int(status['frames_processed']) >= len(listener.poses) >= \
        0.9 * int(status['frames_processed'])  # a pose for nearly every frame processed
    assert float(status['latency_p50_ms']) > 0 and float(status['latency_p95_ms']) < 1000
    assert status['odometry'] == 'yes'
    predicted, after_loss = int(status['predicted_switches']), int(status['switches_after_loss'])
    assert predicted > 0 and predicted >= 0.9 * (predicted + after_loss), status
    assert status['camera_info'] == 'matches'
    for key in ('tracked', 'falls_to_lost', 'switches_after_loss', 'frames_dropped'):
        assert key in status
    print(f'room_run at rate 0.5 in {elapsed:.1f} s: {len(listener.poses)} poses of '
          f'{len(image_stamps)} images, p50 {status["latency_p50_ms"]} ms, p95 '
          f'{status["latency_p95_ms"]} ms, error median {np.median(errors):.4f} m, p95 '
          f'{np.percentile(errors, 95):.4f} m, heading median '
          f'{np.degrees(np.median(headings)):.3f} deg, {predicted} predicted and '
          f'{after_loss} after-loss region changes')

    # AMCL's service: forget the region; the diagnostics then say LOST.
    from std_srvs.srv import Empty
    client = ros_node.node.create_client(Empty, '/localizer/reinitialize_global_localization')
    assert ros_node.spin_until(client.service_is_ready, timeout=WAIT)
    future = client.call_async(Empty.Request())
    assert ros_node.spin_until(future.done, timeout=WAIT)
    assert listener.wait_status(lambda s: s['state'] == 'LOST')['region'] == '-1'
    assert 'Traceback' not in node.output


def test_kidnapped_run_with_sim_time(room_db, start_process, ros_node) -> None:
    run = read_run('room_run_kidnapped')
    start_localizer(start_process, room_db, 'use_sim_time:=true')
    listener = Listener(ros_node)
    listen_to_bag_topics(ros_node)
    play(start_process, ros_node, 'room_run_kidnapped', '--rate', '2', '--clock')
    # With sim time the node's timers stop with the bag's clock (no diagnostics to wait
    # on): give the last frames a moment to arrive.
    spin_for(ros_node, 1.5)
    stamps, errors = pose_errors(listener, run['truth'])
    start = min(run['truth'])
    kidnap = start + 21_900_000_000  # where the ground truth jumps by 2.7 m
    before, after = errors[stamps < kidnap], errors[stamps > kidnap + 3_000_000_000]
    assert len(before) > 50 and len(after) > 50
    assert np.median(before) < 0.1 and np.median(after) < 0.1, (np.median(before),
                                                                np.median(after))
    # The map -> odom correction moved by the kidnapping (odometry did not notice).
    tf_stamps = np.array([stamp_ns(t.header.stamp) for t in listener.tf])
    early = planar(listener.tf[int(np.flatnonzero(tf_stamps < kidnap)[-1])])
    late = planar(listener.tf[-1])
    assert math.hypot(*(late[:2] - early[:2])) > 2.0
    # Diagnostics are stamped with the bag's clock (use_sim_time).
    assert ros_node.spin_until(lambda: listener.diagnostics, timeout=10)
    assert abs(stamp_ns(listener.diagnostics[0].header.stamp) - start) < 100e9


def test_looping_bag_with_sim_time_resets_cleanly(room_db, start_process, ros_node) -> None:
    # The last 8 s of the run, looped at twice the speed, with /clock: time goes back at
    # each new pass, and the localizer starts again cleanly each time.
    node = start_localizer(start_process, room_db, 'use_sim_time:=true')
    listener = Listener(ros_node)
    start_process(['vbn', 'play', str(BAGS / 'room_run'), '--loop', '--clock', '--rate', '2',
                   '--start-offset', '36'], name='play')
    listener.wait_status(lambda s: int(s['resets']) >= 2, timeout=WAIT)
    node.wait_for_output(r'time went back by \d\.\d s \(a bag that loops\?\): state reset',
                         timeout=10)
    poses = len(listener.poses)
    # Each pass starts LOST (the reset) and must get back to TRACKING: wait for a status
    # after the third reset that says so (a status right at a reset says LOST).
    listener.wait_status(lambda s: int(s['resets']) >= 3 and s['state'] == 'TRACKING',
                         timeout=WAIT)
    assert len(listener.poses) > poses + 10
    assert node.popen.poll() is None and 'Traceback' not in node.output




def test_bad_input_is_warned_once_and_dropped(room_db, start_process, ros_node) -> None:
    run = read_run('room_run')
    node = start_localizer(start_process, room_db)
    listener = Listener(ros_node)
    pub = Publisher(ros_node, run)
    t0 = run['images'][0][0]
    tick = [t0]

    def stamp(step_ns: int = 100_000_000) -> int:
        tick[0] += step_ns
        return tick[0]

    def send(publisher, msg, pause: float = 0.15) -> None:
        publisher.publish(msg)
        spin_for(ros_node, pause)

    sent: dict[int, int] = {}  # stamp -> bag image

    def good_frames(n: int, start: int = 0) -> None:
        for i in range(n):
            sent[stamp()] = start + i
            send(pub.compressed, pub.frame(start + i, tick[0]), 0.1)

    # No CameraInfo at all: the database's camera is assumed, said once (after 2 s).
    for i in range(300):
        good_frames(1, i % 8)
        if 'no CameraInfo on /camera/camera_info' in node.output and listener.poses:
            break
    assert node.output.count('no CameraInfo') == 1 and listener.poses, node.output

    bad_images = [
        (pub.raw(stamp(), step=1000), 'needs step >= 1024, got 1000'),
        (pub.raw(stamp(), encoding='yuv422', width=64, height=64, step=128,
                 data=bytes(128 * 64)),
         "unsupported image encoding 'yuv422'"),
        (pub.raw(stamp(), data=b''), 'needs 262144 bytes of data, got 0'),
        (pub.raw(stamp(), width=64, height=64), 'image is 64x64, the database camera '
                                                '1024x256'),
    ]
    for msg, text in bad_images:
        for _ in range(3):  # the same problem three times: one warning
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp(), 1_000_000_000)
            send(pub.image, msg)
        node.wait_for_output(text.replace('(', r'\(').replace(')', r'\)'), timeout=20)
        assert node.output.count(text) == 1, (text, node.output)
    good_frames(3, 8)
    # Raw images work too.
    count = len(listener.regions)
    gray = decode_image(run['images'][11][1])
    send(pub.image, pub.raw(stamp(), data=gray.tobytes()), 0.5)
    assert ros_node.spin_until(lambda: len(listener.regions) == count + 1, timeout=10)

    # A CameraInfo at another size: taken as the frames' own camera, so frames of
    # another size than it says are dropped, one warning.
    send(pub.info, pub.camera_info(512, 128))
    node.wait_for_output('CameraInfo 512x128 panoramic differs from the database camera '
                         '1024x256: frames are read with their own calibration', timeout=20)
    count = len(listener.regions)
    good_frames(3, 11)
    node.wait_for_output('frame dropped: image is 1024x256, its CameraInfo 512x128',
                         timeout=20)
    assert len(listener.regions) == count
    garbage = pub.camera_info()
    garbage.k = [float('nan')] * 9
    send(pub.info, garbage)
    send(pub.info, garbage)
    node.wait_for_output(r'CameraInfo changed: CameraInfo cannot be used \(camera info k '
                         r'must hold 9 finite numbers', timeout=20)
    assert node.output.count('CameraInfo cannot be used') == 1
    send(pub.info, pub.camera_info())
    node.wait_for_output('CameraInfo fits the database camera again', timeout=20)
    good_frames(3, 14)
    assert len(listener.regions) > count

    # NaN and jumping odometry: one warning each, no NaN anywhere.
    for i in range(5):
        send(pub.odom, pub.odometry(tick[0] + i * 20_000_000, float('nan')), 0.02)
    node.wait_for_output('/odom: pose is not finite', timeout=20)
    for i in range(5):
        send(pub.odom, pub.odometry(tick[0] + (5 + i) * 20_000_000, 5.0 * (i % 2)), 0.02)
    node.wait_for_output('/odom jumped by more than 1 m', timeout=20)
    assert node.output.count('/odom jumped') == 1

    # Stamps that go back: a little is dropped, a lot (a looping bag) resets the state.
    send(pub.compressed, pub.frame(17, tick[0] - 500_000_000))
    node.wait_for_output('older than the last frame', timeout=20)
    send(pub.compressed, pub.frame(0, t0 - 100_000_000_000))
    node.wait_for_output('time went back by 1\\d\\d.\\d s', timeout=20)
    tick[0] = t0 - 100_000_000_000
    good_frames(5, 1)
    status = listener.wait_status(lambda s: int(s['resets']) >= 1)
    assert int(status['dropped_stamp_went_back']) == 1 and int(status['dropped_decode']) >= 9

    # A burst of 1,000 frames at 200 Hz: the node keeps up by dropping, stays alive and
    # keeps publishing afterwards.
    before = len(listener.regions)
    period = 1 / 200
    next_time = time.perf_counter()
    frames = [pub.frame(20 + (i % 40), 0) for i in range(40)]
    for i in range(1000):
        msg = frames[i % 40]
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp(5_000_000),
                                                                1_000_000_000)
        pub.compressed.publish(msg)
        next_time += period
        while time.perf_counter() < next_time:
            ros_node.executor.spin_once(timeout_sec=max(0.0, next_time - time.perf_counter()))
    listener.wait_settled()
    assert node.popen.poll() is None, node.output
    burst = len(listener.regions) - before
    assert 10 < burst < 1000  # processed some, dropped the rest
    # /initialpose (as RViz sends it): voting restricted to the regions near it.
    from geometry_msgs.msg import PoseWithCovarianceStamped
    x, y = run['truth'][run['images'][60][0]][:2]
    hint = PoseWithCovarianceStamped()
    hint.header.frame_id = 'map'
    hint.pose.pose.position.x, hint.pose.pose.position.y = x, y
    send(pub.initial, hint)
    node.wait_for_output(rf'/initialpose \({x:.2f}, {y:.2f}\): voting among the regions '
                         r'within 1.50 m', timeout=20)
    after, poses = len(listener.regions), len(listener.poses)
    good_frames(10, 60)
    assert ros_node.spin_until(lambda: len(listener.poses) > poses, timeout=10)
    assert len(listener.regions) > after
    last = listener.poses[-1]
    x, y = run['truth'][run['images'][sent[stamp_ns(last.header.stamp)]][0]][:2]
    assert math.hypot(last.pose.position.x - x, last.pose.position.y - y) < 0.3
    assert all(np.all(np.isfinite([p.pose.position.x, p.pose.position.y]))
               for p in listener.poses)
    assert 'Traceback' not in node.output
    print(f'burst of 1000 frames at 200 Hz: {burst} processed')


def test_image_reliable_receives_large_raw_images(room_db, start_process, ros_node) -> None:
    # 786 kB bgr8 frames: Fast DDS drops best-effort samples over its 0.5 MB shared-memory
    # segment between processes, so these need image_reliable (and a reliable publisher).
    run = read_run('room_run')
    start_localizer(start_process, room_db, 'image_reliable:=true')
    listener = Listener(ros_node)
    pub = Publisher(ros_node, run)
    # The first frame votes (up to a second); frames sent meanwhile replace each other.
    for i in range(30):
        gray = decode_image(run['images'][i][1])
        bgr = np.repeat(gray[:, :, None], 3, axis=2)
        pub.image.publish(pub.raw(run['images'][i][0], encoding='bgr8', step=3 * 1024,
                                  data=bgr.tobytes()))
        spin_for(ros_node, 0.2)
        if len(listener.poses) >= 3:
            break
    assert len(listener.poses) >= 3 and len(listener.regions) >= 3




def memory_over(frames: int, room_db, start_process, ros_node, rate_hz: float = 100) -> None:
    """Send ``frames`` images at ``rate_hz``, stamps 10 ms apart: the run at real speed.

    Each bag image is sent ten times with advancing stamps (the images change at the
    bag's 10 Hz), with the bag's odometry at 50 Hz; past the end the run starts again
    (a kidnapping, as far as the localizer can tell). The node processes what it can.
    """
    run = read_run('room_run')
    node = start_localizer(start_process, room_db)
    listener = Listener(ros_node)
    pub = Publisher(ros_node, run)
    info = pub.camera_info()
    t0 = run['images'][0][0]
    odom_stamps = sorted(run['odom'])
    cycle = len(run['images']) * 10
    period = 1 / rate_hz
    warm = max(500, frames // 5)
    samples = []
    next_time = time.perf_counter()
    for i in range(frames):
        stamp = t0 + i * 10_000_000
        pub.compressed.publish(pub.frame((i % cycle) // 10, stamp))
        if i % 2 == 0:
            x, y, yaw = run['odom'][odom_stamps[min((i % cycle) // 2, len(odom_stamps) - 1)]]
            odom = pub.odometry(stamp, x, y)
            odom.pose.pose.orientation.z, odom.pose.pose.orientation.w = \
                math.sin(yaw / 2), math.cos(yaw / 2)
            pub.odom.publish(odom)
        if i % 10 == 0:
            pub.info.publish(info)
        if i >= warm and i % 100 == 0:
            samples.append(rss_kib(node.popen.pid))
        next_time += period
        while time.perf_counter() < next_time:
            ros_node.executor.spin_once(timeout_sec=max(0.0, next_time - time.perf_counter()))
    listener.wait_settled()
    samples.append(rss_kib(node.popen.pid))
    status = listener.wait_status(lambda s: True)
    assert node.popen.poll() is None and 'Traceback' not in node.output
    assert int(status['frames_processed']) > frames / 10 and len(listener.poses) > frames / 20
    growth = samples[-1] / samples[0]
    print(f'{frames} frames at {rate_hz:g} Hz: {status["frames_processed"]} processed, '
          f'{len(listener.poses)} poses, p50 {status["latency_p50_ms"]} ms, RSS '
          f'{samples[0] / 1024:.0f} -> {samples[-1] / 1024:.0f} MiB ({growth:.3f}x)')
    print('RSS MiB every 1000 frames:', [round(v / 1024) for v in samples[::10]])
    assert growth < 1.10, samples


def test_memory_flat_over_10000_frames(room_db, start_process, ros_node) -> None:
    memory_over(10_000, room_db, start_process, ros_node)


@pytest.mark.parametrize('case', ['missing', 'random_bytes', 'newer_schema'])
def test_bad_database_exits_2_with_one_line(case, room_db, ros_env, tmp_path) -> None:
    path = tmp_path / f'{case}.db'
    expected = {'missing': 'no such file', 'random_bytes': 'not a SQLite database',
                'newer_schema': f'has schema version {SCHEMA_VERSION + 1}'}[case]
    if case == 'random_bytes':
        path.write_bytes(np.random.default_rng(0).bytes(50_000))
    elif case == 'newer_schema':
        newer = SCHEMA_VERSION + 1
        edited_copy(room_db, path, f'PRAGMA user_version = {newer}',
                    f"UPDATE meta SET value = '{newer}' WHERE key = 'schema_version'")
    proc = subprocess.run(['localizer', '--ros-args', '-p', f'db:={path}'], env=ros_env,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('localizer: error: '), proc.stderr
    assert expected in lines[0] and str(path) in lines[0]


if __name__ == '__main__':
    sys.exit(pytest.main([__file__, '-q']))
