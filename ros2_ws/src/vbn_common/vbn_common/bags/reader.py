"""Read rosbag2 MCAP bags with rosbags (no rclpy).

:class:`BagReader` (or :func:`open_bag`) accepts a bag directory, a bag directory
without ``metadata.yaml`` (its ``.mcap`` files are read alone, with a warning: the
MCAP file holds schemas, channels and QoS by itself) or a bare ``.mcap`` file. An
intact bag is read through rosbags' indexed reader. Bad input becomes a one-line
:class:`VbnCommonError` (non-existent path, nothing to read, empty or
non-MCAP file) or a warning plus the readable part: a truncated ``.mcap`` (cut
mid-chunk, no summary) is read by the recovery scan of
:mod:`vbn_common.bags.recovery`, which keeps every intact record and chunk
and skips corrupted chunks; a chunk that fails to decode while reading an indexed
file makes the reader warn and go on with that scan after the last message read.
A bag without messages opens with a warning.
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
import logging
import os
from pathlib import Path
import struct
import sys
from typing import Any

from mcap.exceptions import McapError
from rosbags.interfaces import ConnectionExtRosbag2, Qos
from rosbags.rosbag2 import Reader, ReaderError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from ruamel.yaml import YAML

from vbn_common.bags.recovery import (
    MCAP_MAGIC,
    McapChannel,
    ScanResult,
    Want,
    chunk_compressions,
    scan_mcap,
    summary_channels,
    top_level_channels,
)
from vbn_common.bags.serialization import (
    TYPESTORE,
    deserialize,
    first_line,
    normalize_msgtype,
)
from vbn_common.errors import VbnCommonError

if sys.version_info >= (3, 14):  # pragma: no cover
    from compression import zstd
else:
    from backports import zstd

__all__ = ['BagReader', 'TopicInfo', 'open_bag']

_LOG = logging.getLogger(__name__)

# What reading a damaged MCAP file can raise in rosbags (a garbage length field can
# make a reader try to allocate or index far beyond the file).
_READ_ERRORS = (ReaderError, zstd.ZstdError, struct.error, ValueError, EOFError, OSError,
                IndexError, TypeError, KeyError, OverflowError, MemoryError, UnicodeDecodeError)


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag.

    Attributes:
        name: Topic name.
        msgtype: ROS 2 type name, ``pkg/msg/Type``.
        count: Number of messages (the readable ones in a recovered bag).
        qos_profiles: The offered QoS recorded with the topic (may be empty).
        msgdef: The embedded ``ros2msg``/``ros2idl`` definition text ('' if none).
    """

    name: str
    msgtype: str
    count: int
    qos_profiles: list[Qos] = field(default_factory=list)
    msgdef: str = ''


class BagReader:
    """Read a rosbag2 MCAP bag (directory) or a bare ``.mcap`` file.

    Use :func:`open_bag` or the class as a context manager.

    Attributes:
        path: The path given.
        files: The ``.mcap`` files read.
        topics: ``{topic: TopicInfo}`` in name order.
        start_ns: Time of the first message (None if the bag is empty).
        end_ns: Time of the last message (None if the bag is empty).
        message_count: Number of messages (readable ones when recovered).
        storage: Storage identifier (``mcap``).
        compression: Human-readable compression, e.g. ``zstd (chunks)``.
        has_metadata: Whether ``metadata.yaml`` was read.
        recovered: Whether the bag was damaged and read by the recovery scan.
        warnings: The warnings given while opening (also logged).

    Raises:
        VbnCommonError: The path does not exist or holds no readable bag.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.warnings: list[str] = []
        self.has_metadata = False
        self.recovered = False
        self._reader: Reader | None = None
        self._typestore: Any = None
        self._known: dict[Path, dict[int, McapChannel]] = {}
        self.files = self._resolve_files()
        self._open()

    # -- opening -------------------------------------------------------------------
    def _warn(self, message: str) -> None:
        self.warnings.append(message)
        _LOG.warning('%s', message)

    def _resolve_files(self) -> list[Path]:
        path = self.path
        if not path.exists():
            raise VbnCommonError(f'bag {path} does not exist')
        if path.is_file():
            if path.suffix != '.mcap' and path.name != 'metadata.yaml':
                raise VbnCommonError(
                    f'{path} is not a bag: expected a bag directory or a .mcap file')
            if path.name == 'metadata.yaml':
                self.path = path = path.parent
            else:
                return [path]
        if (path / 'metadata.yaml').is_file():
            self.has_metadata = True
            return self._files_from_metadata(path)
        mcaps = sorted(path.glob('*.mcap'))
        if not mcaps:
            raise VbnCommonError(
                f'{path} is not a bag: no metadata.yaml and no .mcap file in it')
        self._warn(
            f'{path} has no metadata.yaml: reading {", ".join(m.name for m in mcaps)} alone '
            '(a full ROS 2 install recreates it with `ros2 bag reindex`)')
        return mcaps

    def _files_from_metadata(self, path: Path) -> list[Path]:
        try:
            meta = YAML(typ='safe').load((path / 'metadata.yaml').read_text())
            info = meta['rosbag2_bagfile_information']
            storage = info.get('storage_identifier', '')
            files = [path / Path(name).name for name in info['relative_file_paths']]
        except Exception as error:  # noqa: BLE001 - malformed YAML fails in many ways
            raise VbnCommonError(
                f'{path}/metadata.yaml is not rosbag2 metadata: {first_line(error)}') from error
        if storage != 'mcap':
            raise VbnCommonError(
                f'bag {path} uses storage {storage!r}; only mcap bags are supported')
        missing = [f.name for f in files if not f.is_file()]
        if missing:
            raise VbnCommonError(
                f'bag {path} is missing its storage file(s) {", ".join(missing)}')
        return files

    def _open(self) -> None:
        for file in self.files:
            size = file.stat().st_size
            if size == 0:
                raise VbnCommonError(f'bag file {file} is empty (0 bytes)')
            with file.open('rb') as stream:
                if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                    raise VbnCommonError(
                        f'{file} is not an MCAP file (bad magic bytes)')
        reader_path = self.path if self.has_metadata else self.files[0]
        reader: Reader | None = None
        if self.has_metadata or len(self.files) == 1:
            try:
                reader = Reader(reader_path)
                reader.open()
            except _READ_ERRORS as error:
                reader = None
                self._recover(error)
        else:
            self._recover(None)
        self._reader = reader
        if reader is not None:
            self._load_from_reader(reader)
        if self.message_count == 0 and not self.recovered:
            self._warn(f'bag {self.path} contains no messages')

    def _recover(self, error: BaseException | None) -> None:
        if error is not None:
            self._warn(
                f'bag {self.path} is damaged ({first_line(error)}); reading its intact part')
        scan = ScanResult()
        self._known = {file: top_level_channels(file) for file in self.files}
        for file in self.files:
            for _ in scan_mcap(file, scan, want=None, known=self._known[file]):
                pass
        for problem in scan.problems:
            self._warn(problem)
        self.recovered = error is not None
        self.topics = _topics_from_channels(scan.channels, scan.counts)
        self.message_count = sum(scan.counts.values())
        self.start_ns = scan.start_ns
        self.end_ns = scan.end_ns
        self.storage = 'mcap'
        self.compression = _describe_compression(scan.chunk_compression, '')
        if self.recovered:
            self._warn(f'bag {self.path}: recovered {self.message_count} messages')

    def _load_from_reader(self, reader: Reader) -> None:
        topics: dict[str, TopicInfo] = {}
        for conn in reader.connections:
            qos = conn.ext.offered_qos_profiles if isinstance(
                conn.ext, ConnectionExtRosbag2) else []
            old = topics.get(conn.topic)
            count = conn.msgcount + (old.count if old else 0)
            topics[conn.topic] = TopicInfo(
                conn.topic, conn.msgtype, count, list(qos), conn.msgdef.data)
        self.topics = dict(sorted(topics.items()))
        self.message_count = reader.message_count
        self.start_ns = reader.start_time if self.message_count else None
        self.end_ns = reader.end_time - 1 if self.message_count else None
        self.storage = 'mcap'
        chunk_kinds: set[str] = set()
        for file in self.files:
            try:
                chunk_kinds |= chunk_compressions(file)
            except (McapError, *_READ_ERRORS):
                pass
        self.compression = _describe_compression(
            chunk_kinds, reader.compression_format or '', reader.compression_mode or '')

    # -- properties ----------------------------------------------------------------
    @property
    def duration_ns(self) -> int:
        """Time from the first to the last message (0 for an empty bag)."""
        if self.start_ns is None or self.end_ns is None:
            return 0
        return self.end_ns - self.start_ns

    @property
    def size_bytes(self) -> int:
        """Total size of the bag's files on disk."""
        total = sum(f.stat().st_size for f in self.files)
        if self.has_metadata:
            total += (self.path / 'metadata.yaml').stat().st_size
        return total

    # -- messages ------------------------------------------------------------------
    def messages(
        self,
        topics: Iterable[str] | None = None,
        msgtypes: Iterable[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[tuple[str, str, int, bytes]]:
        """Yield ``(topic, msgtype, timestamp_ns, rawdata)`` in time order.

        Args:
            topics: Keep only these topics (None: all).
            msgtypes: Keep only these types (``pkg/msg/Type`` or ``pkg/Type``).
            start_ns: Keep messages at or after this time.
            stop_ns: Keep messages before this time.

        Yields:
            One tuple per message kept.

        A chunk that fails to decode while reading an indexed bag makes the reader
        warn and read on with the recovery scan after the last message given; a
        recovered bag skips it with a warning.
        """
        topic_set = set(topics) if topics is not None else None
        type_set = {normalize_msgtype(t) for t in msgtypes} if msgtypes is not None else None
        if topic_set is not None:
            unknown = sorted(topic_set - set(self.topics))
            if unknown:
                self._warn(f'bag {self.path} has no topic(s) {", ".join(unknown)}')

        def keep(topic: str, msgtype: str, stamp: int) -> bool:
            return ((topic_set is None or topic in topic_set)
                    and (type_set is None or msgtype in type_set)
                    and (start_ns is None or stamp >= start_ns)
                    and (stop_ns is None or stamp < stop_ns))

        if self._reader is None:
            yield from self._scan_messages(keep, self._known, warn=False)  # warned at opening
            return
        reader = self._reader
        conns = [c for c in reader.connections
                 if (topic_set is None or c.topic in topic_set)
                 and (type_set is None or c.msgtype in type_set)]
        if not conns:
            return
        done = 0
        last_stamp: int | None = None
        try:
            for conn, stamp, raw in reader.messages(conns, start=start_ns, stop=stop_ns):
                done += 1
                last_stamp = stamp
                yield conn.topic, conn.msgtype, stamp, bytes(raw)
            return
        except _READ_ERRORS as error:
            self._warn(
                f'bag {self.path} is corrupted ({first_line(error)}) after {done} '
                'messages; skipping the damaged chunk(s) and reading on')

        def keep_after(topic: str, msgtype: str, stamp: int) -> bool:
            return (last_stamp is None or stamp > last_stamp) and keep(topic, msgtype, stamp)

        known = {file: summary_channels(file) for file in self.files}
        yield from self._scan_messages(keep_after, known, warn=True)

    def _scan_messages(
        self, want: Want, known: dict[Path, dict[int, McapChannel]], *, warn: bool,
    ) -> Iterator[tuple[str, str, int, bytes]]:
        """Yield the wanted messages of the recovery scan; then warn of its problems."""
        scan = ScanResult()
        for file in self.files:
            for chan, stamp, raw in scan_mcap(file, scan, want=want, known=known.get(file)):
                yield chan.topic, chan.msgtype, stamp, raw
        if warn:
            for problem in scan.problems:
                self._warn(problem)

    def deserialize(self, rawdata: bytes | memoryview, msgtype: str) -> Any:
        """Deserialize a message of this bag; types unknown to Jazzy use the bag's definition.

        Args:
            rawdata: The CDR message.
            msgtype: Its type, ``pkg/msg/Type``.

        Returns:
            The message object.

        Raises:
            VbnCommonError: The type is unknown and the bag has no
                definition for it, or the data does not decode.
        """
        msgtype = normalize_msgtype(msgtype)
        if msgtype in TYPESTORE.fielddefs:
            return deserialize(rawdata, msgtype)
        store = self._typestore_for(msgtype)
        return deserialize(rawdata, msgtype, store)

    def _typestore_for(self, msgtype: str) -> Any:
        if self._typestore is not None and msgtype in self._typestore.fielddefs:
            return self._typestore
        msgdef = next((t.msgdef for t in self.topics.values()
                       if t.msgtype == msgtype and t.msgdef), '')
        if not msgdef:
            raise VbnCommonError(
                f'unknown message type {msgtype!r}: not a ROS 2 Jazzy type and bag '
                f'{self.path} carries no definition for it')
        if msgdef.startswith('=' * 80 + '\nIDL: '):
            raise VbnCommonError(
                f'message type {msgtype!r} has an IDL definition, which is not supported')
        if self._typestore is None:
            self._typestore = get_typestore(Stores.ROS2_JAZZY)
        try:
            self._typestore.register(get_types_from_msg(msgdef, msgtype))
        except Exception as error:  # noqa: BLE001 - parser errors of many kinds
            raise VbnCommonError(
                f'cannot parse the definition of {msgtype!r} in bag {self.path}: '
                f'{first_line(error)}') from error
        return self._typestore

    # -- lifecycle -----------------------------------------------------------------
    def close(self) -> None:
        """Close the underlying files."""
        reader, self._reader = self._reader, None
        if reader is not None:
            try:
                reader.close()
            except Exception:  # noqa: BLE001 - closing a damaged file
                pass

    def __enter__(self) -> BagReader:
        """Return the open reader."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the reader."""
        self.close()


def open_bag(path: str | os.PathLike[str]) -> BagReader:
    """Open a bag directory or ``.mcap`` file for reading (see :class:`BagReader`).

    Raises:
        VbnCommonError: The path does not exist or holds no readable bag.
    """
    return BagReader(path)


def _describe_compression(chunks: set[str], fmt: str, mode: str = '') -> str:
    parts = []
    kinds = sorted(k for k in chunks if k)
    if kinds:
        parts.append(f'{"/".join(kinds)} (chunks)')
    if mode and fmt:
        parts.append(f'{fmt} ({mode})')
    return ', '.join(parts) if parts else 'none'


def _topics_from_channels(
    channels: dict[str, McapChannel], counts: dict[str, int],
) -> dict[str, TopicInfo]:
    topics = {topic: TopicInfo(topic, chan.msgtype, counts.get(topic, 0), chan.qos, chan.msgdef)
              for topic, chan in channels.items()}
    return dict(sorted(topics.items()))
