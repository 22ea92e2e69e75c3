"""Tests of vbn_common.bags.recovery: reading the intact part of damaged MCAP files."""
from __future__ import annotations

from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader
import numpy as np
import pytest

from vbn_common.bags import TYPESTORE, BagWriter, serialize
from vbn_common.bags.recovery import (
    MCAP_MAGIC,
    ScanResult,
    chunk_compressions,
    scan_mcap,
    summary_channels,
    top_level_channels,
)

T = TYPESTORE.types
IMAGE = 'sensor_msgs/msg/Image'
STRING = 'std_msgs/msg/String'


def image(i: int) -> object:
    # Random pixels do not compress: 40 images of 64 KiB fill three 1 MiB chunks.
    data = np.random.default_rng(i).integers(0, 256, 256 * 256, dtype=np.uint8)
    stamp = T['builtin_interfaces/msg/Time'](sec=i, nanosec=0)
    return T[IMAGE](header=T['std_msgs/msg/Header'](stamp=stamp, frame_id='camera'),
                    height=256, width=256, encoding='mono8', is_bigendian=0, step=256,
                    data=data)


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[tuple[str, int, bytes]]]:
    """A bag of images and strings; returns its .mcap file and (topic, stamp, cdr) written."""
    path = tmp_path_factory.mktemp('recovery') / 'bag'
    written = []
    with BagWriter(path) as writer:
        images = writer.add_topic('/camera/image_raw', IMAGE)
        notes = writer.add_topic('/notes', STRING)
        for i in range(40):
            for conn, msgtype, msg in ((images, IMAGE, image(i)),
                                       (notes, STRING, T[STRING](data=f'note {i}'))):
                stamp = 10**18 + i * 10**8 + (msgtype == STRING)
                writer.write(conn, stamp, msg)
                written.append((conn.topic, stamp, serialize(msg, msgtype)))
    return path / 'bag.mcap', written


def chunks_of(file: Path) -> list:
    with file.open('rb') as stream:
        return make_reader(stream).get_summary().chunk_indexes


def read(file: Path, **kwargs: object) -> tuple[list[tuple[str, int, bytes]], ScanResult]:
    scan = ScanResult()
    got = [(chan.topic, stamp, raw)
           for chan, stamp, raw in scan_mcap(file, scan, want=lambda *_: True, **kwargs)]
    return got, scan


def damaged_copy(tmp_path: Path, file: Path, data: bytes) -> Path:
    target = tmp_path / file.name
    target.write_bytes(data)
    return target


def test_intact_file_is_read_whole(bag: tuple[Path, list]) -> None:
    file, written = bag
    got, scan = read(file)
    assert got == written
    assert scan.problems == []
    assert scan.counts == {'/camera/image_raw': 40, '/notes': 40}
    assert (scan.start_ns, scan.end_ns) == (written[0][1], written[-1][1])
    assert scan.chunk_compression == {'zstd'}
    assert len(chunks_of(file)) >= 3


def test_cut_chunk_keeps_its_complete_records(tmp_path: Path, bag: tuple[Path, list]) -> None:
    file, written = bag
    second = chunks_of(file)[1]
    cut = damaged_copy(tmp_path, file, file.read_bytes()[
        :second.chunk_start_offset + second.chunk_length // 2])
    got, scan = read(cut)
    in_first = sum(1 for _, stamp, _ in written if stamp <= chunks_of(file)[0].message_end_time)
    assert got == written[:len(got)]
    assert in_first < len(got) < len(written)
    assert len(scan.problems) == 1 and 'messages of the cut chunk' in scan.problems[0]
    assert f'starts at byte {second.chunk_start_offset}' in scan.problems[0]


def test_corrupted_chunk_is_skipped_and_the_scan_goes_on(
        tmp_path: Path, bag: tuple[Path, list]) -> None:
    file, written = bag
    second = chunks_of(file)[1]
    data = bytearray(file.read_bytes())
    middle = second.chunk_start_offset + second.chunk_length // 2
    data[middle:middle + 16] = bytes(16)  # the zstd frame's checksum no longer matches
    got, scan = read(damaged_copy(tmp_path, file, bytes(data)))
    lost = [w for w in written
            if second.message_start_time <= w[1] <= second.message_end_time]
    assert lost and got == [w for w in written if w not in lost]
    assert scan.problems == ['bag.mcap: skipped 1 corrupted chunk(s)']


def test_summary_channels_read_what_follows_a_lost_first_chunk(
        tmp_path: Path, bag: tuple[Path, list]) -> None:
    file, written = bag
    first = chunks_of(file)[0]
    data = bytearray(file.read_bytes())
    middle = first.chunk_start_offset + first.chunk_length // 2
    data[middle:middle + 16] = bytes(16)
    damaged = damaged_copy(tmp_path, file, bytes(data))
    # The first chunk held the only in-data channel records.
    assert read(damaged)[0] == []
    known = summary_channels(damaged)
    assert {c.topic: c.msgtype for c in known.values()} == {
        '/camera/image_raw': IMAGE, '/notes': STRING}
    assert top_level_channels(damaged) == known
    got, _ = read(damaged, known=known)
    assert got == [w for w in written if w[1] > first.message_end_time]


def test_garbage_length_beyond_the_file_ends_the_walk(tmp_path: Path) -> None:
    # Regression: a length pointing past the end made the walk seek beyond any offset.
    file = tmp_path / 'garbage.mcap'
    file.write_bytes(MCAP_MAGIC + b'\x03' + (2**63).to_bytes(8, 'little') + b'\x80')
    assert top_level_channels(file) == {}
    got, scan = read(file)
    assert got == []
    assert scan.problems == ['garbage.mcap is truncated at byte 18, inside a record that '
                             'starts at byte 8']


def test_chunk_compressions_without_a_readable_summary(
        tmp_path: Path, bag: tuple[Path, list]) -> None:
    # Regression: when mcap cannot read the summary, the chunk headers still name it.
    file, _ = bag
    assert chunk_compressions(file) == {'zstd'}
    no_footer = damaged_copy(tmp_path, file, file.read_bytes()[:-40])
    with no_footer.open('rb') as stream, pytest.raises(McapError):
        make_reader(stream).get_summary()
    assert chunk_compressions(no_footer) == {'zstd'}
