"""Tests of vbn_common.bags: writing and reading rosbag2 MCAP bags, bad input."""
from __future__ import annotations

import os
from pathlib import Path
import shutil

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from ruamel.yaml import YAML

from vbn_common.bags import (
    TYPESTORE,
    BagWriter,
    default_qos,
    deserialize,
    open_bag,
    parse_qos_profiles,
    serialize,
)
from vbn_common.errors import VbnCommonError

T = TYPESTORE.types
POSE = 'geometry_msgs/msg/PoseStamped'
IMAGE = 'sensor_msgs/msg/Image'
ODOM = 'nav_msgs/msg/Odometry'


def header(stamp_ns: int, frame: str) -> object:
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
        frame_id=frame)


def pose_msg(i: int, stamp_ns: int) -> object:
    return T[POSE](header=header(stamp_ns, 'map'), pose=T['geometry_msgs/msg/Pose'](
        position=T['geometry_msgs/msg/Point'](x=float(i), y=-0.5 * i, z=0.0),
        orientation=T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0)))


def image_msg(i: int, stamp_ns: int, width: int = 256, height: int = 64) -> object:
    # Random pixels do not compress: a few images fill several 1 MiB chunks.
    data = np.random.default_rng(i).integers(0, 256, width * height, dtype=np.uint8)
    return T[IMAGE](header=header(stamp_ns, 'camera'), height=height, width=width,
                    encoding='mono8', is_bigendian=0, step=width, data=data)


def odom_msg(i: int, stamp_ns: int) -> object:
    pose = pose_msg(i, stamp_ns).pose
    cov = np.arange(36, dtype=np.float64) * 0.01
    twist = T['geometry_msgs/msg/Twist'](
        linear=T['geometry_msgs/msg/Vector3'](x=0.3, y=0.0, z=0.0),
        angular=T['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.1 * i))
    return T[ODOM](
        header=header(stamp_ns, 'odom'), child_frame_id='base_link',
        pose=T['geometry_msgs/msg/PoseWithCovariance'](pose=pose, covariance=cov),
        twist=T['geometry_msgs/msg/TwistWithCovariance'](twist=twist, covariance=cov))


def write_sample(path: Path, n_images: int = 12) -> list[tuple[str, str, int, bytes]]:
    """Write images, poses and odometry; return the messages in time order."""
    written = []
    with BagWriter(path) as bag:
        c_img = bag.add_topic('/camera/image_raw', IMAGE)
        c_pose = bag.add_topic('/ground_truth/pose', POSE, [default_qos()])
        c_odom = bag.add_topic('/odom', ODOM, [default_qos(reliability='best_effort', depth=5)])
        for i in range(n_images):
            t = 1_700_000_000 * 10**9 + i * 100_000_000
            for conn, msgtype, msg, stamp in (
                    (c_img, IMAGE, image_msg(i, t), t),
                    (c_pose, POSE, pose_msg(i, t), t + 1),
                    (c_odom, ODOM, odom_msg(i, t), t + 2)):
                bag.write(conn, stamp, msg)
                written.append((conn.topic, msgtype, stamp, serialize(msg, msgtype)))
    return written


@pytest.fixture(scope='module')
def sample(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:
    path = tmp_path_factory.mktemp('bags') / 'sample'
    return path, write_sample(path, n_images=200)  # ~3.3 MB of images: several chunks


def copy_bag(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def mcap_file(bag: Path) -> Path:
    (file,) = bag.glob('*.mcap')
    return file


# -- writing and reading back ----------------------------------------------------------
def test_round_trip_reproduces_every_message(sample: tuple[Path, list]) -> None:
    path, written = sample
    with open_bag(path) as bag:
        read = list(bag.messages())
        assert read == written
        assert bag.message_count == len(written) == 600
        assert {name: t.count for name, t in bag.topics.items()} == {
            '/camera/image_raw': 200, '/ground_truth/pose': 200, '/odom': 200}
        assert bag.topics['/odom'].msgtype == ODOM
        assert bag.start_ns == written[0][2]
        assert bag.end_ns == written[-1][2]
        assert bag.duration_ns == written[-1][2] - written[0][2]
        assert bag.compression == 'zstd (chunks)'
        assert bag.storage == 'mcap'
        assert not bag.warnings and not bag.recovered
        msg = bag.deserialize(read[1][3], read[1][1])
        assert msg.pose.position.x == 0.0 and msg.header.frame_id == 'map'
        image = bag.deserialize(read[-3][3], IMAGE)
        assert image.width == 256 and image.encoding == 'mono8'
        assert np.array_equal(image.data, image_msg(199, 0).data)


def test_metadata_is_jazzy_rosbag2_with_chunk_compression(sample: tuple[Path, list]) -> None:
    path, _ = sample
    meta = YAML(typ='safe').load((path / 'metadata.yaml').read_text())
    info = meta['rosbag2_bagfile_information']
    assert info['version'] == 8
    assert info['storage_identifier'] == 'mcap'
    assert info['compression_mode'] == '' and info['compression_format'] == ''
    assert info['message_count'] == 600
    assert info['relative_file_paths'] == ['sample.mcap']
    with mcap_file(path).open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert len(summary.chunk_indexes) >= 3
    assert {c.compression for c in summary.chunk_indexes} == {'zstd'}
    assert summary.statistics.message_count == 600


def test_qos_is_recorded_and_read_back(sample: tuple[Path, list]) -> None:
    path, _ = sample
    with open_bag(path) as bag:
        (qos,) = bag.topics['/odom'].qos_profiles
        assert qos.reliability.name == 'BEST_EFFORT' and qos.depth == 5
        assert qos.durability.name == 'VOLATILE' and qos.history.name == 'KEEP_LAST'
        assert bag.topics['/camera/image_raw'].qos_profiles == []


def test_mcap_reader_decodes_the_same_messages(sample: tuple[Path, list]) -> None:
    path, written = sample
    with mcap_file(path).open('rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = [(c.topic, m.log_time, d) for _, c, m, d in reader.iter_decoded_messages()]
    assert [(t, s) for t, s, _ in decoded] == [(t, s) for t, _, s, _ in written]
    assert decoded[1][2].pose.position.y == 0.0
    assert decoded[4][2].pose.position.y == -0.5
    assert bytes(decoded[-3][2].data) == bytes(image_msg(199, 0).data)


def test_filters_by_topic_type_and_time(sample: tuple[Path, list]) -> None:
    path, written = sample
    with open_bag(path) as bag:
        poses = list(bag.messages(topics=['/ground_truth/pose']))
        assert poses == [w for w in written if w[0] == '/ground_truth/pose']
        odom = list(bag.messages(msgtypes=['nav_msgs/Odometry']))
        assert odom == [w for w in written if w[1] == ODOM]
        t0, t1 = written[30][2], written[60][2]
        window = list(bag.messages(start_ns=t0, stop_ns=t1))
        assert window == written[30:60]
        assert list(bag.messages(topics=['/nope'])) == []
        assert any('/nope' in w for w in bag.warnings)


def test_bare_mcap_file_and_metadata_path_are_accepted(sample: tuple[Path, list]) -> None:
    path, written = sample
    with open_bag(mcap_file(path)) as bag:
        assert list(bag.messages()) == written
        assert not bag.has_metadata
    with open_bag(path / 'metadata.yaml') as bag:
        assert bag.message_count == len(written)


def test_uncompressed_bag(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'plain', compression='none') as bag:
        conn = bag.add_topic('/chatter', 'std_msgs/String')
        bag.write(conn, 5, T['std_msgs/msg/String'](data='hello'))
    with open_bag(tmp_path / 'plain') as bag:
        ((topic, msgtype, stamp, raw),) = list(bag.messages())
        assert (topic, msgtype, stamp) == ('/chatter', 'std_msgs/msg/String', 5)
        assert deserialize(raw, msgtype).data == 'hello'
        assert bag.compression == 'none'


# -- atomic writing --------------------------------------------------------------------
def test_writer_leaves_nothing_when_the_block_raises(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError), BagWriter(tmp_path / 'bag') as bag:
        conn = bag.add_topic('/chatter', 'std_msgs/msg/String')
        bag.write(conn, 1, T['std_msgs/msg/String'](data='x'))
        assert not (tmp_path / 'bag').exists()  # still in the temporary sibling
        raise RuntimeError('boom')
    assert list(tmp_path.iterdir()) == []


def test_writer_renames_into_place_without_leftovers(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
    assert [p.name for p in tmp_path.iterdir()] == ['bag']
    assert sorted(p.name for p in (tmp_path / 'bag').iterdir()) == ['bag.mcap', 'metadata.yaml']


def test_writer_refuses_to_overwrite_unless_asked(tmp_path: Path) -> None:
    write_sample(tmp_path / 'bag', n_images=1)
    with pytest.raises(VbnCommonError, match='exists already'):
        BagWriter(tmp_path / 'bag')
    with BagWriter(tmp_path / 'bag', overwrite=True) as bag:
        conn = bag.add_topic('/chatter', 'std_msgs/msg/String')
        bag.write(conn, 1, T['std_msgs/msg/String'](data='new'))
    with open_bag(tmp_path / 'bag') as bag:
        assert list(bag.topics) == ['/chatter']
    assert [p.name for p in tmp_path.iterdir()] == ['bag']


def test_in_place_writer_keeps_a_valid_bag_when_interrupted(tmp_path: Path) -> None:
    with pytest.raises(KeyboardInterrupt), BagWriter(tmp_path / 'rec', atomic=False) as bag:
        conn = bag.add_topic('/chatter', 'std_msgs/msg/String')
        for i in range(7):
            bag.write(conn, i + 1, T['std_msgs/msg/String'](data=str(i)))
        raise KeyboardInterrupt
    with open_bag(tmp_path / 'rec') as bag:
        assert not bag.warnings
        assert [deserialize(m[3], m[1]).data for m in bag.messages()] == list('0123456')


def test_writer_input_errors(tmp_path: Path) -> None:
    with pytest.raises(VbnCommonError, match='compression'):
        BagWriter(tmp_path / 'x', compression='lz5')
    with BagWriter(tmp_path / 'bag') as bag:
        with pytest.raises(VbnCommonError, match="unknown message type 'my_msgs/msg/Foo'"):
            bag.add_topic('/foo', 'my_msgs/msg/Foo')
        with pytest.raises(VbnCommonError, match='invalid message type name'):
            bag.add_topic('/foo', 'Foo')
        conn = bag.add_topic('/chatter', 'std_msgs/msg/String')
        with pytest.raises(VbnCommonError, match='added twice'):
            bag.add_topic('/chatter', 'std_msgs/msg/String')
        with pytest.raises(VbnCommonError, match='cannot serialize'):
            bag.write(conn, 1, pose_msg(0, 0))


def test_qos_profiles_parse_from_yaml_and_dicts() -> None:
    qos = default_qos(durability='transient_local', depth=1)
    from vbn_common.bags import dump_qos_yaml
    assert parse_qos_profiles(dump_qos_yaml([qos])) == [qos]
    assert parse_qos_profiles(None) == []
    with pytest.raises(VbnCommonError):
        default_qos(reliability='sometimes')


# -- unknown message types -------------------------------------------------------------
CUSTOM_DEF = 'string name\nint32[] values\ngeometry_msgs/Point where\n'


def test_custom_type_with_embedded_definition_is_readable(tmp_path: Path) -> None:
    store = get_typestore(Stores.ROS2_JAZZY)  # a private store: TYPESTORE stays Jazzy-only
    store.register(get_types_from_msg(CUSTOM_DEF, 'my_msgs/msg/Thing'))
    thing = store.types['my_msgs/msg/Thing'](
        name='abc', values=np.array([7, -3], dtype=np.int32),
        where=store.types['geometry_msgs/msg/Point'](x=1.0, y=2.0, z=3.0))
    raw = serialize(thing, 'my_msgs/msg/Thing', store)
    with BagWriter(tmp_path / 'custom') as bag:
        conn = bag.add_topic('/custom', 'my_msgs/msg/Thing', msgdef=CUSTOM_DEF)
        bag.write_raw(conn, 10, raw)
    with open_bag(tmp_path / 'custom') as bag:
        ((_, msgtype, _, data),) = list(bag.messages())
        assert msgtype == 'my_msgs/msg/Thing'
        msg = bag.deserialize(data, msgtype)
        assert msg.name == 'abc' and list(msg.values) == [7, -3] and msg.where.z == 3.0
    with pytest.raises(VbnCommonError, match='unknown message type'):
        deserialize(data, msgtype)  # the Jazzy typestore alone does not know it


def test_unknown_type_without_definition_is_a_clear_error(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
    with open_bag(tmp_path / 'bag') as bag, pytest.raises(
            VbnCommonError, match="unknown message type 'no_msgs/msg/Nothing'"):
        bag.deserialize(b'\x00\x01\x00\x00', 'no_msgs/msg/Nothing')


def test_garbage_data_is_a_clear_error() -> None:
    with pytest.raises(VbnCommonError, match='cannot deserialize'):
        deserialize(b'\x00\x01\x00\x00\xff\xff\xff\x7f', 'std_msgs/msg/String')


# -- bad input -------------------------------------------------------------------------
def test_nonexistent_path(tmp_path: Path) -> None:
    with pytest.raises(VbnCommonError, match='does not exist'):
        open_bag(tmp_path / 'missing')


def test_directory_without_anything(tmp_path: Path) -> None:
    with pytest.raises(VbnCommonError, match='no metadata.yaml and no .mcap'):
        open_bag(tmp_path)


def test_not_a_bag_file(tmp_path: Path) -> None:
    (tmp_path / 'notes.txt').write_text('hi')
    with pytest.raises(VbnCommonError, match='not a bag'):
        open_bag(tmp_path / 'notes.txt')


def test_zero_byte_mcap(tmp_path: Path, sample: tuple[Path, list]) -> None:
    bag = copy_bag(sample[0], tmp_path / 'zero')
    mcap_file(bag).write_bytes(b'')
    with pytest.raises(VbnCommonError, match=r'is empty \(0 bytes\)'):
        open_bag(bag)


def test_random_bytes(tmp_path: Path, sample: tuple[Path, list]) -> None:
    bag = copy_bag(sample[0], tmp_path / 'random')
    mcap_file(bag).write_bytes(np.random.default_rng(1).bytes(5000))
    with pytest.raises(VbnCommonError, match='not an MCAP file'):
        open_bag(bag)


def test_missing_storage_file(tmp_path: Path, sample: tuple[Path, list]) -> None:
    bag = copy_bag(sample[0], tmp_path / 'nofile')
    mcap_file(bag).unlink()
    with pytest.raises(VbnCommonError, match='missing its storage file'):
        open_bag(bag)


def test_broken_metadata(tmp_path: Path, sample: tuple[Path, list]) -> None:
    bag = copy_bag(sample[0], tmp_path / 'badmeta')
    (bag / 'metadata.yaml').write_text('just: [text')
    with pytest.raises(VbnCommonError, match='not rosbag2 metadata'):
        open_bag(bag)


def test_no_metadata_reads_the_mcap_alone_with_a_warning(
        tmp_path: Path, sample: tuple[Path, list]) -> None:
    bag = copy_bag(sample[0], tmp_path / 'nometa')
    (bag / 'metadata.yaml').unlink()
    with open_bag(bag) as reader:
        assert any('no metadata.yaml' in w for w in reader.warnings)
        assert list(reader.messages()) == sample[1]
        assert reader.topics['/odom'].qos_profiles[0].depth == 5  # from the MCAP channel


def test_empty_bag_warns_and_yields_nothing(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'empty') as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
    with open_bag(tmp_path / 'empty') as reader:
        assert reader.message_count == 0 and reader.duration_ns == 0
        assert reader.start_ns is None
        assert list(reader.messages()) == []
        assert any('contains no messages' in w for w in reader.warnings)


def test_truncated_mid_chunk_keeps_the_readable_part(
        tmp_path: Path, sample: tuple[Path, list]) -> None:
    bag = copy_bag(sample[0], tmp_path / 'cut')
    file = mcap_file(bag)
    size = file.stat().st_size
    with file.open('r+b') as stream:
        stream.truncate(size // 2)  # inside the second of four chunks
    with open_bag(bag) as reader:
        assert reader.recovered
        assert any('damaged' in w for w in reader.warnings)
        assert any('cut chunk' in w for w in reader.warnings)
        read = list(reader.messages())
    written = sample[1]
    assert 0 < len(read) < len(written)
    assert read == written[:len(read)]
    assert reader.message_count == len(read)
    # More than the first complete chunk: the cut chunk's complete records count too.
    with mcap_file(sample[0]).open('rb') as stream:
        first_chunk = make_reader(stream).get_summary().chunk_indexes[0]
    assert len(read) > sum(1 for w in written if w[2] <= first_chunk.message_end_time)


def test_corrupted_chunk_is_skipped_with_a_warning(
        tmp_path: Path, sample: tuple[Path, list]) -> None:
    bag = copy_bag(sample[0], tmp_path / 'corrupt')
    file = mcap_file(bag)
    with mcap_file(sample[0]).open('rb') as stream:
        chunks = make_reader(stream).get_summary().chunk_indexes
    second = chunks[1]
    data = bytearray(file.read_bytes())
    middle = second.chunk_start_offset + second.chunk_length // 2
    data[middle:middle + 64] = np.random.default_rng(2).bytes(64)
    file.write_bytes(bytes(data))
    with open_bag(bag) as reader:
        read = list(reader.messages())
        assert any('corrupted' in w for w in reader.warnings)
    written = sample[1]
    lost = [w for w in written if second.message_start_time <= w[2] <= second.message_end_time]
    assert lost
    assert read == [w for w in written if w not in lost]


CUTS = st.integers(min_value=0, max_value=10**9)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cut=CUTS)
def test_any_truncation_gives_a_prefix_or_a_clear_error(
        tmp_path_factory: pytest.TempPathFactory, sample: tuple[Path, list], cut: int) -> None:
    source = mcap_file(sample[0]).read_bytes()
    cut = cut % len(source)
    target = tmp_path_factory.mktemp('cut') / 'bag.mcap'
    target.write_bytes(source[:cut])
    try:
        reader = open_bag(target)
    except VbnCommonError as error:
        assert cut < 8 and str(error)  # only a file without its magic is refused
        return
    with reader:
        read = list(reader.messages())
    assert read == sample[1][:len(read)]


@settings(max_examples=15, deadline=None)
@given(texts=st.lists(st.tuples(st.sampled_from(['/a', '/b', '/c']), st.text(max_size=40)),
                      max_size=30))
def test_string_messages_round_trip(tmp_path_factory: pytest.TempPathFactory,
                                    texts: list[tuple[str, str]]) -> None:
    path = tmp_path_factory.mktemp('h') / 'bag'
    with BagWriter(path) as bag:
        conns = {t: bag.add_topic(t, 'std_msgs/msg/String') for t in ('/a', '/b', '/c')}
        for i, (topic, text) in enumerate(texts):
            bag.write(conns[topic], 1000 + i, T['std_msgs/msg/String'](data=text))
    with open_bag(path) as reader:
        got = [(topic, deserialize(raw, msgtype).data) for topic, msgtype, _, raw in
               reader.messages()]
        assert got == texts
        assert reader.message_count == len(texts)
    assert os.listdir(path.parent) == ['bag']


@settings(max_examples=30, deadline=None)
@given(text=st.text(max_size=50))
def test_serialize_pads_to_a_dds_payload_and_round_trips(text: str) -> None:
    raw = serialize(T['std_msgs/msg/String'](data=text), 'std_msgs/String')
    unpadded = bytes(TYPESTORE.serialize_cdr(T['std_msgs/msg/String'](data=text),
                                             'std_msgs/msg/String'))
    assert len(raw) % 4 == 0 and len(raw) - len(unpadded) < 4
    assert raw == unpadded + bytes(len(raw) - len(unpadded))
    assert deserialize(raw, 'std_msgs/msg/String').data == text


def read_all_or_error(path: Path) -> list | None:
    """Open and read a damaged bag: a list of messages, or None for a one-line error."""
    try:
        reader = open_bag(path)
    except VbnCommonError as error:
        assert '\n' not in str(error)
        return None
    with reader:
        return list(reader.messages())


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(garbage=st.binary(min_size=0, max_size=3000))
def test_garbage_after_the_magic_never_raises_anything_else(
        tmp_path_factory: pytest.TempPathFactory, garbage: bytes) -> None:
    path = tmp_path_factory.mktemp('garbage') / 'bag.mcap'
    path.write_bytes(b'\x89MCAP0\r\n' + garbage)
    assert read_all_or_error(path) in (None, [])


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(hits=st.lists(st.tuples(st.integers(0, 10**9), st.binary(min_size=1, max_size=16)),
                     min_size=1, max_size=4))
def test_random_overwrites_give_a_subset_or_a_clear_error(
        tmp_path_factory: pytest.TempPathFactory, sample: tuple[Path, list],
        hits: list[tuple[int, bytes]]) -> None:
    data = bytearray(mcap_file(sample[0]).read_bytes())
    for position, junk in hits:
        position %= len(data)
        data[position:position + len(junk)] = junk
    path = tmp_path_factory.mktemp('hit') / 'bag.mcap'
    path.write_bytes(bytes(data))
    read = read_all_or_error(path)
    if read is not None:
        # The zstd checksum covers every chunk, so every message read is an original one
        # (time and data; a hit in the unchecked summary may garble a topic name).
        originals = {(stamp, raw) for _, _, stamp, raw in sample[1]}
        assert all((stamp, raw) in originals for _, _, stamp, raw in read)
