"""Tests of vbn_common.bags.info and ``vbn bag-info``."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
import shutil

from mcap.reader import make_reader
import numpy as np
import pytest

from vbn_common.bags import (
    TYPESTORE,
    BagWriter,
    bag_paths,
    default_qos,
    format_bag_info,
    format_size,
    summarize_bag,
)
from vbn_common.cli import bag_info as bag_info_cli
from vbn_common.errors import VbnCommonError

T = TYPESTORE.types


def write_bag(path: Path, n: int = 40, image_bytes: int = 100_000) -> None:
    rng = np.random.default_rng(0)
    with BagWriter(path) as bag:
        strings = bag.add_topic('/chatter', 'std_msgs/msg/String',
                                [default_qos(durability='transient_local', depth=1)])
        blobs = bag.add_topic('/blob', 'std_msgs/msg/UInt8MultiArray')
        for i in range(n):
            stamp = 1_763_769_600 * 10**9 + i * 50_000_000  # 2025-11-22 00:00:00 UTC + i/20 s
            bag.write(strings, stamp, T['std_msgs/msg/String'](data=f'msg {i}'))
            if i % 2 == 0:
                layout = T['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0)
                bag.write(blobs, stamp + 1, T['std_msgs/msg/UInt8MultiArray'](
                    layout=layout, data=rng.integers(0, 256, image_bytes, dtype=np.uint8)))


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('info') / 'demo'
    write_bag(path)
    return path


def test_summary_counts_times_and_qos(bag: Path) -> None:
    summary = summarize_bag(bag)
    assert summary.message_count == 60
    assert [(t.name, t.msgtype, t.count) for t in summary.topics] == [
        ('/blob', 'std_msgs/msg/UInt8MultiArray', 20), ('/chatter', 'std_msgs/msg/String', 40)]
    assert summary.start_ns == 1_763_769_600 * 10**9
    assert summary.end_ns == 1_763_769_600 * 10**9 + 39 * 50_000_000
    assert summary.duration_ns == 39 * 50_000_000
    assert summary.topics[1].qos == 'reliable/transient_local/keep_last 1'
    assert summary.topics[0].qos == ''
    assert summary.compression == 'zstd (chunks)'
    assert summary.files == ['demo.mcap']
    assert summary.size_bytes == sum(p.stat().st_size for p in bag.iterdir())
    assert summary.verified_count is None and not summary.warnings


def test_format_looks_like_ros2_bag_info(bag: Path) -> None:
    text = format_bag_info(summarize_bag(bag))
    lines = text.splitlines()
    assert lines[0] == 'Files:             demo.mcap'
    assert 'Storage id:        mcap' in lines
    assert 'Duration:          1.950s' in lines
    assert 'Start:             Nov 22 2025 00:00:00.000 UTC (1763769600.000000000)' in lines
    assert 'End:               Nov 22 2025 00:00:01.950 UTC (1763769601.950000000)' in lines
    assert 'Messages:          60' in lines
    assert ('Topic information: Topic: /blob    | Type: std_msgs/msg/UInt8MultiArray | '
            'Count: 20 | Serialization Format: cdr') in lines
    assert any(line.strip().startswith('Topic: /chatter ') and 'Count: 40' in line
               for line in lines)


def test_verify_reports_the_readable_count_of_a_corrupted_bag(
        bag: Path, tmp_path: Path) -> None:
    copy = tmp_path / 'corrupt'
    shutil.copytree(bag, copy)
    mcap = copy / 'demo.mcap'
    with mcap.open('rb') as stream:
        chunks = make_reader(stream).get_summary().chunk_indexes
    assert len(chunks) >= 2
    data = bytearray(mcap.read_bytes())
    first = chunks[0]
    data[first.chunk_start_offset + 200:first.chunk_start_offset + 300] = bytes(100)
    mcap.write_bytes(bytes(data))
    summary = summarize_bag(copy, verify=True)
    assert summary.message_count == 60  # the index still says 60
    assert summary.verified_count is not None and 0 < summary.verified_count < 60
    assert sum(t.count for t in summary.topics) == summary.verified_count
    assert any('corrupted' in w for w in summary.warnings)
    assert f'Readable:          {summary.verified_count}' in format_bag_info(summary)


def test_empty_bag_summary(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'empty') as writer:
        writer.add_topic('/chatter', 'std_msgs/msg/String')
    summary = summarize_bag(tmp_path / 'empty')
    assert summary.message_count == 0 and summary.start_ns is None
    text = format_bag_info(summary)
    assert 'Duration:          0.000s' in text and 'Start:' not in text
    assert any('no messages' in w for w in summary.warnings)


def test_format_size() -> None:
    assert format_size(512) == '512 B'
    assert format_size(2048) == '2.0 KiB'
    assert format_size(3.5 * 2**20) == '3.5 MiB'
    assert format_size(5 * 2**30) == '5.0 GiB'


def test_bag_paths(bag: Path, tmp_path: Path) -> None:
    assert bag_paths(bag.parent) == [bag]
    assert bag_paths(tmp_path / 'nothing') == []


def run_cli(*argv: str) -> int:
    parser = argparse.ArgumentParser()
    bag_info_cli.register(parser.add_subparsers())
    args = parser.parse_args(['bag-info', *argv])
    return args.func(args)


def test_cli_prints_text_and_json(bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli(str(bag)) == 0
    assert 'Messages:          60' in capsys.readouterr().out
    assert run_cli(str(bag), '--json') == 0
    data = json.loads(capsys.readouterr().out)
    assert data['message_count'] == 60 and data['duration_ns'] == 39 * 50_000_000
    assert [t['count'] for t in data['topics']] == [20, 40]


def test_cli_bad_path_is_a_vbn_error(tmp_path: Path) -> None:
    with pytest.raises(VbnCommonError, match='does not exist'):
        run_cli(str(tmp_path / 'missing'))
