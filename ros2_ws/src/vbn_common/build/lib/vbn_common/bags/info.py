"""Summarize a bag like ``ros2 bag info``: files, size, storage, times, topics and counts.

``summarize_bag`` gathers the facts (optionally reading every message to verify
the counts), ``format_bag_info`` lays them out as ``ros2 bag info`` does, with an
extra compression line.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
import os
from pathlib import Path

from vbn_common.bags.reader import BagReader, open_bag

__all__ = [
    'BagSummary',
    'TopicSummary',
    'bag_paths',
    'format_bag_info',
    'format_size',
    'summarize_bag',
]


@dataclass(frozen=True)
class TopicSummary:
    """One topic line of the summary."""

    name: str
    msgtype: str
    count: int
    serialization_format: str = 'cdr'
    qos: str = ''  # e.g. 'reliable/volatile/keep_last 10'; '' when not recorded


@dataclass(frozen=True)
class BagSummary:
    """What ``vbn bag-info`` prints.

    Times are nanoseconds since the epoch; ``start_ns``/``end_ns`` are None for
    an empty bag. ``verified_count`` is the number of messages actually read when
    verification was asked for, else None.
    """

    path: str
    files: list[str]
    size_bytes: int
    storage: str
    compression: str
    has_metadata: bool
    recovered: bool
    message_count: int
    start_ns: int | None
    end_ns: int | None
    topics: list[TopicSummary]
    warnings: list[str] = field(default_factory=list)
    verified_count: int | None = None

    @property
    def duration_ns(self) -> int:
        """Time from the first to the last message."""
        if self.start_ns is None or self.end_ns is None:
            return 0
        return self.end_ns - self.start_ns

    def to_dict(self) -> dict[str, object]:
        """Return a JSON-ready dict (duration included)."""
        out = asdict(self)
        out['duration_ns'] = self.duration_ns
        return out


def _qos_text(reader: BagReader, topic: str) -> str:
    profiles = reader.topics[topic].qos_profiles
    if not profiles:
        return ''
    qos = profiles[0]
    return (f'{qos.reliability.name.lower()}/{qos.durability.name.lower()}/'
            f'{qos.history.name.lower()} {qos.depth}')


def summarize_bag(path: str | os.PathLike[str], *, verify: bool = False) -> BagSummary:
    """Summarize the bag at ``path``.

    Args:
        path: A bag directory or ``.mcap`` file.
        verify: Read every message and report the counts actually readable
            (finds corrupted chunks that the index alone does not show).

    Raises:
        VbnCommonError: The path holds no readable bag.
    """
    with open_bag(path) as reader:
        counts = {name: info.count for name, info in reader.topics.items()}
        verified = None
        start, end = reader.start_ns, reader.end_ns
        if verify:
            seen: Counter[str] = Counter()
            stamps = []
            for topic, _msgtype, stamp, _raw in reader.messages():
                seen[topic] += 1
                stamps.append(stamp)
            verified = sum(seen.values())
            counts = {name: seen.get(name, 0) for name in reader.topics}
            if stamps:
                start, end = min(stamps), max(stamps)
        topics = [TopicSummary(name, info.msgtype, counts[name], 'cdr', _qos_text(reader, name))
                  for name, info in reader.topics.items()]
        return BagSummary(
            path=str(reader.path), files=[f.name for f in reader.files],
            size_bytes=reader.size_bytes, storage=reader.storage,
            compression=reader.compression, has_metadata=reader.has_metadata,
            recovered=reader.recovered, message_count=reader.message_count,
            start_ns=start, end_ns=end, topics=topics,
            warnings=list(reader.warnings), verified_count=verified)


def format_size(size: float) -> str:
    """Bytes as ``ros2 bag info`` shows them (``12.3 MiB``)."""
    for unit in ('B', 'KiB', 'MiB', 'GiB'):
        if size < 1024 or unit == 'GiB':
            return f'{size:.0f} {unit}' if unit == 'B' else f'{size:.1f} {unit}'
        size /= 1024
    raise AssertionError('unreachable')


def _format_time(stamp_ns: int) -> str:
    when = datetime.fromtimestamp(stamp_ns / 1e9, tz=UTC)
    return (f'{when:%b %d %Y %H:%M:%S}.{stamp_ns % 10**9 // 10**6:03d} UTC '
            f'({stamp_ns // 10**9}.{stamp_ns % 10**9:09d})')


def format_bag_info(summary: BagSummary) -> str:
    """Lay out a summary like ``ros2 bag info``, one fact per line."""
    label = '{:<19}'.format
    lines = [
        label('Files:') + ', '.join(summary.files),
        label('Bag size:') + format_size(summary.size_bytes),
        label('Storage id:') + summary.storage,
        label('Compression:') + summary.compression,
        label('Metadata:') + ('metadata.yaml' if summary.has_metadata
                              else 'none (read from the .mcap file)'),
        label('Duration:') + f'{summary.duration_ns / 1e9:.3f}s',
    ]
    if summary.start_ns is not None and summary.end_ns is not None:
        lines.append(label('Start:') + _format_time(summary.start_ns))
        lines.append(label('End:') + _format_time(summary.end_ns))
    lines.append(label('Messages:') + str(summary.message_count))
    if summary.verified_count is not None:
        lines.append(label('Readable:') + f'{summary.verified_count} (every message read)')
    if summary.recovered:
        lines.append(label('Damaged:') + 'yes; counts are of the readable part')
    width = max((len(t.name) for t in summary.topics), default=0)
    type_width = max((len(t.msgtype) for t in summary.topics), default=0)
    for i, topic in enumerate(summary.topics):
        head = label('Topic information:') if i == 0 else label('')
        qos = f' | QoS: {topic.qos}' if topic.qos else ''
        lines.append(
            f'{head}Topic: {topic.name:<{width}} | Type: {topic.msgtype:<{type_width}} | '
            f'Count: {topic.count} | Serialization Format: {topic.serialization_format}{qos}')
    if not summary.topics:
        lines.append(label('Topic information:'))
    return '\n'.join(lines)


def bag_paths(pattern_dir: str | os.PathLike[str]) -> list[Path]:
    """List the bag directories directly inside ``pattern_dir`` (those with a .mcap)."""
    root = Path(pattern_dir)
    if not root.is_dir():
        return []
    return sorted(p for p in root.iterdir() if p.is_dir() and any(p.glob('*.mcap')))
