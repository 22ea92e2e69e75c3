"""vbn play / record / echo / bag-info as subprocesses over real DDS, and their bad input.

Every test waits for matched endpoints or printed lines (``play --wait-for-subscribers``,
``record``'s "recording"/"first message" lines), never a fixed sleep; every process is
stopped by the ``start_process`` fixture; pytest-timeout bounds a hung node.
"""
from __future__ import annotations

from pathlib import Path
import re
import signal

import numpy as np
from paths import REPO
import pytest
import yaml

from vbn_common.bags import TYPESTORE, BagWriter, default_qos, open_bag

pytestmark = pytest.mark.integration

T = TYPESTORE.types
VBN = 'vbn'
WAIT = 120.0  # generous bound for discovery on a loaded 2-core machine
TOPICS = ['/camera/image_raw', '/ground_truth/pose', '/odom', '/chatter', '/tf']


def header(stamp_ns: int, frame: str) -> object:
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
        frame_id=frame)


def write_synthetic_bag(path: Path, n: int = 15, rate_hz: float = 30.0,
                        with_tf: bool = True) -> dict[str, list[bytes]]:
    """Images (bgr8), poses, odometry, a latched string and /tf; return raw CDR per topic."""
    rng = np.random.default_rng(7)
    raw: dict[str, list[bytes]] = {}
    t0 = 1_763_769_600 * 10**9
    with BagWriter(path) as bag:
        conns = {
            '/camera/image_raw': bag.add_topic('/camera/image_raw', 'sensor_msgs/msg/Image',
                                               [default_qos(depth=10)]),
            '/ground_truth/pose': bag.add_topic('/ground_truth/pose',
                                                'geometry_msgs/msg/PoseStamped',
                                                [default_qos(depth=10)]),
            '/odom': bag.add_topic('/odom', 'nav_msgs/msg/Odometry', [default_qos(depth=50)]),
            '/chatter': bag.add_topic('/chatter', 'std_msgs/msg/String',
                                      [default_qos(durability='transient_local', depth=5)]),
        }
        if with_tf:
            conns['/tf'] = bag.add_topic('/tf', 'tf2_msgs/msg/TFMessage', [default_qos()])
        for i in range(n):
            stamp = t0 + int(i * 1e9 / rate_hz)
            point = T['geometry_msgs/msg/Point'](x=0.1 * i, y=-0.2 * i, z=0.0)
            quat = T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=np.sin(i / 10),
                                                     w=np.cos(i / 10))
            pose = T['geometry_msgs/msg/Pose'](position=point, orientation=quat)
            image = T['sensor_msgs/msg/Image'](
                header=header(stamp, 'camera'), height=24, width=32, encoding='bgr8',
                is_bigendian=0, step=96, data=rng.integers(0, 256, 24 * 96, dtype=np.uint8))
            cov = rng.normal(size=36)
            odom = T['nav_msgs/msg/Odometry'](
                header=header(stamp, 'odom'), child_frame_id='base_link',
                pose=T['geometry_msgs/msg/PoseWithCovariance'](pose=pose, covariance=cov),
                twist=T['geometry_msgs/msg/TwistWithCovariance'](
                    twist=T['geometry_msgs/msg/Twist'](
                        linear=T['geometry_msgs/msg/Vector3'](x=0.5, y=0.0, z=0.0),
                        angular=T['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.1)),
                    covariance=cov))
            msgs = {
                '/camera/image_raw': image,
                '/ground_truth/pose': T['geometry_msgs/msg/PoseStamped'](
                    header=header(stamp, 'map'), pose=pose),
                '/odom': odom,
            }
            if i < 3:
                msgs['/chatter'] = T['std_msgs/msg/String'](data=f'hello {i} ✓' + '!' * i)
            if with_tf:
                msgs['/tf'] = T['tf2_msgs/msg/TFMessage'](transforms=[])
            for k, (topic, msg) in enumerate(msgs.items()):
                bag.write(conns[topic], stamp + k, msg)  # distinct times: a fixed order
    with open_bag(path) as reader:  # what play will publish
        for topic, _msgtype, _stamp, data in reader.messages():
            raw.setdefault(topic, []).append(data)
    return raw


def recorded_raw(path: Path) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    with open_bag(path) as reader:
        assert not reader.warnings, reader.warnings
        for topic, _msgtype, _stamp, raw in reader.messages():
            out.setdefault(topic, []).append(raw)
    return out


def test_play_to_record_round_trip_is_byte_exact(tmp_path: Path, start_process) -> None:
    source = write_synthetic_bag(tmp_path / 'source')
    out = tmp_path / 'recorded'
    record = start_process([VBN, 'record', '--topics', *TOPICS, '--out', str(out)],
                           name='record')
    record.wait_for_output('recording into', timeout=WAIT)
    play = start_process([VBN, 'play', str(tmp_path / 'source'), '--wait-for-subscribers',
                          '--wait-timeout', str(WAIT)], name='play')
    assert play.wait(timeout=2 * WAIT) == 0, play.output
    assert f'done: published {15 * 4 + 3} messages' in play.output
    assert 'skipping' not in play.output  # /tf plays: tf2_msgs is built in the workspace
    for topic in TOPICS:
        record.wait_for_output(f'first message on {re.escape(topic)}', timeout=WAIT)
    assert record.stop() == 0, record.output
    assert 'wrote 63 messages' in record.output, record.output
    got = recorded_raw(out)
    assert set(got) == set(TOPICS)
    for topic in TOPICS:
        assert got[topic] == source[topic], topic  # every message, byte for byte, in order
    with open_bag(out) as reader:
        qos = reader.topics['/chatter'].qos_profiles
        assert qos and qos[0].durability.name == 'TRANSIENT_LOCAL'  # the offered QoS
        assert reader.topics['/camera/image_raw'].msgtype == 'sensor_msgs/msg/Image'


SAMPLE = REPO / 'bags' / 'floor_exploration'


@pytest.mark.skipif(not SAMPLE.is_dir(), reason='sample bag bags/floor_exploration missing')
def test_sample_bag_round_trip_is_byte_exact(tmp_path: Path, start_process) -> None:
    # A committed sample, played eight times faster: every message comes back byte for
    # byte and in order, /tf and the transient-local /tf_static included.
    topics = ['/camera/image_raw/compressed', '/camera/camera_info', '/ground_truth/pose',
              '/tf', '/tf_static']
    out = tmp_path / 'recorded'
    record = start_process([VBN, 'record', '--topics', *topics, '--out', str(out)],
                           name='record')
    record.wait_for_output('recording into', timeout=WAIT)
    play = start_process([VBN, 'play', str(SAMPLE), '--rate', '8', '--topics', *topics,
                          '--wait-for-subscribers', '--wait-timeout', str(WAIT)], name='play')
    assert play.wait(timeout=2 * WAIT) == 0, play.output
    assert record.stop() == 0, record.output
    original = recorded_raw(SAMPLE)
    got = recorded_raw(out)
    assert set(got) == set(topics)
    for topic in topics:
        assert len(got[topic]) == len(original[topic]) == (1 if topic == '/tf_static' else 84)
        assert got[topic] == original[topic], topic
    with open_bag(out) as reader:  # recorded with the QoS it was offered: latched
        assert reader.topics['/tf_static'].qos_profiles[0].durability.name == 'TRANSIENT_LOCAL'


def test_record_killed_with_sigint_leaves_a_valid_bag(tmp_path: Path, start_process) -> None:
    source = write_synthetic_bag(tmp_path / 'source', n=30, with_tf=False)
    out = tmp_path / 'recorded'
    record = start_process([VBN, 'record', '--topics', '/ground_truth/pose', '/odom',
                            '--out', str(out)], name='record')
    record.wait_for_output('recording into', timeout=WAIT)
    start_process([VBN, 'play', str(tmp_path / 'source'), '--loop', '--rate', '4',
                   '--topics', '/ground_truth/pose', '/odom', '--wait-for-subscribers'],
                  name='play')
    record.wait_for_output('first message on /ground_truth/pose', timeout=WAIT)
    record.wait_for_output('first message on /odom', timeout=WAIT)
    record.popen.send_signal(signal.SIGINT)  # while messages are still flowing
    assert record.wait(timeout=60) == 0, record.output
    written = int(re.search(r'wrote (\d+) messages', record.output).group(1))
    assert written > 0
    with open_bag(out) as reader:
        assert not reader.warnings and not reader.recovered
        assert reader.message_count == written
        got = [(topic, raw) for topic, _, _, raw in reader.messages()]
    assert len(got) == written
    loop = {topic: set(raws) for topic, raws in source.items()}
    assert all(raw in loop[topic] for topic, raw in got)  # every message intact


def test_echo_prints_the_published_fields(tmp_path: Path, start_process) -> None:
    source = write_synthetic_bag(tmp_path / 'source', with_tf=False)
    echo = start_process([VBN, 'echo', '/ground_truth/pose', '--count', '2',
                          '--timeout', str(2 * WAIT)], name='echo')
    play = start_process([VBN, 'play', str(tmp_path / 'source'), '--topics',
                          '/ground_truth/pose', '--wait-for-subscribers'], name='play')
    assert echo.wait(timeout=2 * WAIT) == 0, echo.output
    assert play.wait(timeout=WAIT) == 0, play.output
    docs = [d for d in echo.output.split('---\n') if d.strip()]
    assert len(docs) == 2
    expected = [TYPESTORE.deserialize_cdr(raw, 'geometry_msgs/msg/PoseStamped')
                for raw in source['/ground_truth/pose'][:2]]
    for doc, msg in zip(docs, expected):
        data = yaml.safe_load(doc)
        assert data['header']['frame_id'] == 'map'
        assert data['header']['stamp'] == {'sec': msg.header.stamp.sec,
                                           'nanosec': msg.header.stamp.nanosec}
        assert data['pose']['position']['x'] == pytest.approx(msg.pose.position.x)
        assert data['pose']['position']['y'] == pytest.approx(msg.pose.position.y)
        assert data['pose']['orientation']['z'] == pytest.approx(msg.pose.orientation.z)


def test_echo_abbreviates_image_data(tmp_path: Path, start_process) -> None:
    write_synthetic_bag(tmp_path / 'source', with_tf=False)
    echo = start_process([VBN, 'echo', '/camera/image_raw', '--once',
                          '--timeout', str(2 * WAIT)], name='echo')
    start_process([VBN, 'play', str(tmp_path / 'source'), '--topics', '/camera/image_raw',
                   '--wait-for-subscribers'], name='play')
    assert echo.wait(timeout=2 * WAIT) == 0, echo.output
    data = yaml.safe_load(echo.output.split('---\n')[0])
    assert (data['width'], data['height'], data['encoding']) == (32, 24, 'bgr8')
    assert len(data['data']) == 129 and data['data'][-1] == '...'


# -- bad input: one line, exit code 2, no traceback -----------------------------------
def run_vbn(start_process, *args: str) -> tuple[int, str]:
    proc = start_process([VBN, *args], name=args[0])
    code = proc.wait(timeout=WAIT)
    return code, proc.output


def assert_one_line_error(code: int, output: str, command: str, pattern: str) -> None:
    assert code == 2, output
    assert 'Traceback' not in output
    errors = [line for line in output.splitlines() if line.startswith(f'vbn {command}: error:')]
    assert len(errors) == 1 and re.search(pattern, errors[0]), output


@pytest.mark.parametrize('command', ['bag-info', 'play'])
def test_nonexistent_bag(tmp_path: Path, start_process, command: str) -> None:
    code, output = run_vbn(start_process, command, str(tmp_path / 'missing'))
    assert_one_line_error(code, output, command, 'does not exist')


def test_random_bytes_and_empty_file(tmp_path: Path, start_process) -> None:
    (tmp_path / 'random').mkdir()
    (tmp_path / 'random' / 'random.mcap').write_bytes(np.random.default_rng(3).bytes(4096))
    code, output = run_vbn(start_process, 'play', str(tmp_path / 'random'))
    assert_one_line_error(code, output, 'play', 'not an MCAP file')
    (tmp_path / 'empty.mcap').write_bytes(b'')
    code, output = run_vbn(start_process, 'bag-info', str(tmp_path / 'empty.mcap'))
    assert_one_line_error(code, output, 'bag-info', r'is empty \(0 bytes\)')


def test_truncated_and_metadata_less_bags_give_warnings_and_the_readable_part(
        tmp_path: Path, start_process) -> None:
    write_synthetic_bag(tmp_path / 'cut', n=200, with_tf=False)
    mcap = tmp_path / 'cut' / 'cut.mcap'
    size = mcap.stat().st_size
    with mcap.open('r+b') as stream:
        stream.truncate(size * 2 // 3)
    (tmp_path / 'cut' / 'metadata.yaml').unlink()
    code, output = run_vbn(start_process, 'bag-info', str(tmp_path / 'cut'))
    assert code == 0, output
    assert 'Traceback' not in output
    assert re.search(r'WARNING .*has no metadata.yaml', output)
    assert re.search(r'WARNING .*is damaged', output)
    count = int(re.search(r'Messages:\s+(\d+)', output).group(1))
    assert 0 < count < 200 * 3 + 3
    assert 'Damaged:           yes' in output


def test_empty_bag_and_unplayable_types(tmp_path: Path, start_process) -> None:
    with BagWriter(tmp_path / 'empty') as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
    code, output = run_vbn(start_process, 'bag-info', str(tmp_path / 'empty'))
    assert code == 0 and re.search(r'WARNING .*contains no messages', output), output
    with BagWriter(tmp_path / 'unplayable') as bag:
        custom = bag.add_topic('/custom', 'my_msgs/msg/Thing', msgdef='int32 value\n')
        bag.write_raw(custom, 2, bytes([0, 1, 0, 0, 42, 0, 0, 0]))
    code, output = run_vbn(start_process, 'bag-info', str(tmp_path / 'unplayable'))
    assert code == 0 and 'Type: my_msgs/msg/Thing' in output, output
    code, output = run_vbn(start_process, 'play', str(tmp_path / 'unplayable'))
    assert_one_line_error(code, output, 'play', 'nothing to play')
    assert output.count('skipping /custom: message type my_msgs/msg/Thing') == 1


def test_echo_without_publisher_times_out_cleanly(start_process) -> None:
    code, output = run_vbn(start_process, 'echo', '/nobody/publishes/this', '--timeout', '2')
    assert_one_line_error(code, output, 'echo', 'no publisher of /nobody/publishes/this')


def test_bad_options(tmp_path: Path, start_process) -> None:
    write_synthetic_bag(tmp_path / 'bag', n=2, with_tf=False)
    code, output = run_vbn(start_process, 'play', str(tmp_path / 'bag'), '--rate', '0')
    assert_one_line_error(code, output, 'play', 'rate must be positive')
    code, output = run_vbn(start_process, 'record', '--topics', '/x', '--out',
                           str(tmp_path / 'bag'))
    assert_one_line_error(code, output, 'record', 'exists already')
    code, output = run_vbn(start_process, 'play', str(tmp_path / 'bag'), '--topics', '/odom',
                           '--wait-for-subscribers', '--wait-timeout', '1')
    assert_one_line_error(code, output, 'play', 'no subscriber on /odom within 1 s')


# -- play options, in process ----------------------------------------------------------
def test_player_start_offset_topics_and_rate(tmp_path: Path, ros_node) -> None:
    from vbn_common.ros_tools.play import Player, PlayOptions
    write_synthetic_bag(tmp_path / 'bag', n=30, with_tf=True)  # 1 s at 30 Hz
    with open_bag(tmp_path / 'bag') as reader:
        player = Player(ros_node.node, reader, PlayOptions(
            rate=5.0, start_offset_s=0.5, topics=('/odom', '/tf')))
        assert list(player.publishers) == ['/odom', '/tf']
        assert player.stats.skipped_topics == []
        stats = player.play()
    # /odom and /tf messages at i/30 s + a few ns: those at or after 0.5 s are i = 15..29.
    assert stats.published == 30
    assert stats.clock_published == 0


def test_play_publishes_clock_at_bag_time(tmp_path: Path, start_process) -> None:
    write_synthetic_bag(tmp_path / 'bag', n=30, with_tf=False)
    echo = start_process([VBN, 'echo', '/clock', '--once', '--timeout', str(2 * WAIT)],
                         name='echo')
    start_process([VBN, 'play', str(tmp_path / 'bag'), '--loop', '--clock', '100',
                   '--topics', '/ground_truth/pose'], name='play')
    assert echo.wait(timeout=2 * WAIT) == 0, echo.output
    clock = yaml.safe_load(echo.output.split('---\n')[0])['clock']
    stamp = clock['sec'] + clock['nanosec'] * 1e-9
    assert 1_763_769_600 <= stamp <= 1_763_769_601  # inside the bag's 1 s, not wall time


def test_record_stops_after_its_duration_with_a_valid_bag(tmp_path: Path, start_process) -> None:
    code, output = run_vbn(start_process, 'record', '--topics', '/nobody/publishes/this',
                           '--out', str(tmp_path / 'short'), '--duration', '1')
    assert code == 0, output
    assert 'wrote 0 messages' in output
    with open_bag(tmp_path / 'short') as reader:
        assert reader.message_count == 0 and not reader.recovered
        assert reader.warnings == [f'bag {tmp_path / "short"} contains no messages']
