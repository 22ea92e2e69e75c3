"""Read and write rosbag2 MCAP bags with rosbags (no rclpy).

A bag is a rosbag2 directory: ``metadata.yaml`` plus one ``.mcap`` file whose
chunks are zstd-compressed, with ROS 2 Jazzy message definitions embedded as
MCAP schemas. ``ros2 bag`` on a full ROS 2 install, rosbags, the ``mcap``
reader with ``mcap-ros2-support`` and evo all read these bags.

Writing (:class:`BagWriter`) uses rosbags' rosbag2 writer with the MCAP storage
plugin in ``CompressionMode.STORAGE``: rosbags then compresses every MCAP chunk
with zstd (what ``ros2 bag record --storage-preset-profile zstd_fast`` does);
the file and message compression modes of ``metadata.yaml`` stay empty, as
rosbag2 writes them for chunk compression. The zstd frames carry their content
checksum, so a corrupted chunk is detected on reading instead of decoding into
garbage (rosbags leaves the MCAP chunk CRC at zero). The metadata is rosbag2
version 8, the version ROS 2 Jazzy writes.

A finished bag appears atomically: the writer works in a hidden temporary
sibling directory and renames it into place on a clean close, and removes it
when the block raises. ``vbn record`` instead writes in place
(``atomic=False``) and closes the bag on any exit, Ctrl-C included, so that
what was recorded stays readable.

Reading (:class:`BagReader`, :func:`open_bag`) accepts a bag directory, a bag
directory without ``metadata.yaml`` (its ``.mcap`` files are read alone, with a
warning: the MCAP file holds schemas, channels and QoS by itself) or a bare
``.mcap`` file. Bad input becomes a one-line :class:`VisibilityBuilderError`
(non-existent path, nothing to read, empty or non-MCAP file) or a warning plus
the readable part: a truncated ``.mcap`` (cut mid-chunk, no summary) is read by
a sequential recovery scan that keeps every intact record and chunk and skips
corrupted chunks; a chunk that fails to decode while reading an indexed file
ends the stream with a warning. A bag without messages opens with a warning.
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
import io
import logging
import os
from pathlib import Path
import shutil
import struct
import sys
import tempfile
from types import TracebackType
from typing import Any

from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag2,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, ReaderError, Writer
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from ruamel.yaml import YAML

from visibility_builder.errors import VisibilityBuilderError

if sys.version_info >= (3, 14):  # pragma: no cover
    from compression import zstd
else:
    from backports import zstd

__all__ = [
    'TYPESTORE',
    'BagReader',
    'BagWriter',
    'TopicInfo',
    'default_qos',
    'deserialize',
    'dump_qos_yaml',
    'open_bag',
    'parse_qos_profiles',
    'serialize',
]

_LOG = logging.getLogger(__name__)

#: The ROS 2 Jazzy message definitions shipped with rosbags.
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)

#: rosbag2 metadata version written by ROS 2 Jazzy.
ROSBAG2_VERSION = 8

_MCAP_MAGIC = b'\x89MCAP0\r\n'
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_DATA_END = 0x0F
_OP_LAST = 0x10  # highest opcode of MCAP v0 (0x80 and above: user records)


class BagWriter:
    """Write a rosbag2 MCAP bag directory; use it as a context manager.

    Example::

        with BagWriter('bags/demo') as bag:
            conn = bag.add_topic('/ground_truth/pose', 'geometry_msgs/msg/PoseStamped')
            bag.write(conn, stamp_ns, pose_msg)

    Args:
        path: The bag directory to create.
        compression: ``'zstd'`` (zstd-compressed MCAP chunks) or ``'none'``.
        atomic: Write into a temporary sibling directory and rename it into
            place on a clean close (default). With ``False`` the bag is written
            in place and closed, valid, on any exit (used by ``vbn record``).
        overwrite: Replace an existing bag at ``path`` on a clean close.

    Raises:
        VisibilityBuilderError: ``path`` exists (without ``overwrite``) or the
            compression is unknown.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        compression: str = 'zstd',
        atomic: bool = True,
        overwrite: bool = False,
    ) -> None:
        self.path = Path(path)
        if compression not in ('zstd', 'none'):
            raise VisibilityBuilderError(
                f'unknown bag compression {compression!r} (expected zstd or none)')
        if self.path.exists() and not (overwrite and atomic):
            raise VisibilityBuilderError(f'{self.path} exists already, not overwriting')
        self.compression = compression
        self.atomic = atomic
        self.overwrite = overwrite
        self._tmp_parent: Path | None = None
        self._writer: Writer | None = None
        self._closed = False
        self.message_count = 0

    # -- lifecycle -----------------------------------------------------------------
    def open(self) -> BagWriter:
        """Create the bag directory (or its temporary sibling) and open the MCAP file."""
        if self._writer is not None:
            raise VisibilityBuilderError(f'bag {self.path} is already open')
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.atomic:
            self._tmp_parent = Path(tempfile.mkdtemp(
                prefix=f'.{self.path.name}.tmp-', dir=self.path.parent))
            target = self._tmp_parent / self.path.name
        else:
            target = self.path
        writer = Writer(target, version=ROSBAG2_VERSION, storage_plugin=StoragePlugin.MCAP)
        if self.compression == 'zstd':
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        try:
            writer.open()
        except Exception as error:
            self._cleanup_tmp()
            raise VisibilityBuilderError(f'cannot create bag {self.path}: {error}') from error
        storage = writer.storage
        if self.compression == 'zstd' and hasattr(storage, 'compressor'):
            # Standard zstd frames with their content checksum: readers detect a
            # corrupted chunk (rosbags writes no MCAP chunk CRC).
            storage.compressor = _zstd_compress_checked
        self._writer = writer
        return self

    def close(self) -> None:
        """Finish the bag: write the MCAP summary and ``metadata.yaml``, rename into place.

        Safe to call twice.
        """
        if self._closed or self._writer is None:
            return
        self._closed = True
        writer, self._writer = self._writer, None
        try:
            writer.close()
        except BaseException:
            if self.atomic:
                self.abort_writer(writer)
            raise
        if self.atomic:
            assert self._tmp_parent is not None
            built = self._tmp_parent / self.path.name
            if self.path.exists():
                if not self.overwrite:  # appeared while writing
                    self._cleanup_tmp()
                    raise VisibilityBuilderError(f'{self.path} exists already, not overwriting')
                old = self._tmp_parent / (self.path.name + '.old')
                self.path.rename(old)
            built.rename(self.path)
            self._cleanup_tmp()

    def abort(self) -> None:
        """Discard the bag being written (atomic mode leaves nothing behind)."""
        if self._closed:
            return
        self._closed = True
        writer, self._writer = self._writer, None
        if writer is not None:
            self.abort_writer(writer)

    def abort_writer(self, writer: Writer) -> None:
        """Abort ``writer`` and remove the temporary directory."""
        try:
            writer.abort()
        except Exception:  # noqa: BLE001 - best effort while already failing
            pass
        self._cleanup_tmp()

    def _cleanup_tmp(self) -> None:
        if self._tmp_parent is not None:
            shutil.rmtree(self._tmp_parent, ignore_errors=True)
            self._tmp_parent = None

    def __enter__(self) -> BagWriter:
        """Open the bag."""
        return self.open()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Close the bag, or discard it when the block raised (atomic mode only)."""
        if exc_type is None or not self.atomic:
            self.close()
        else:
            self.abort()

    # -- content -------------------------------------------------------------------
    def add_topic(
        self,
        topic: str,
        msgtype: str,
        qos_profiles: str | Sequence[Qos | dict[str, Any]] | None = None,
        *,
        msgdef: str | None = None,
        rihs01: str | None = None,
    ) -> Connection:
        """Add a topic (an MCAP channel) and return its connection.

        Args:
            topic: Topic name, e.g. ``/camera/image_raw``.
            msgtype: ROS 2 type name, ``pkg/msg/Type`` (``pkg/Type`` is accepted).
            qos_profiles: The publisher's offered QoS: rosbag2's YAML string, or a
                list of rosbags ``Qos`` (see :func:`default_qos`) or QoS dicts.
                Recorded in the metadata so that ``play`` offers the same QoS.
            msgdef: The ``ros2msg`` definition text for a type unknown to the Jazzy
                typestore (``vbn record`` of a custom type).
            rihs01: The type hash for ``msgdef``; computed from it when omitted.

        Returns:
            The connection to pass to :meth:`write` or :meth:`write_raw`.

        Raises:
            VisibilityBuilderError: The bag is not open, the topic exists already
                or the message type is unknown and no ``msgdef`` is given.
        """
        writer = self._require_open()
        msgtype = normalize_msgtype(msgtype)
        if any(conn.topic == topic for conn in writer.connections):
            raise VisibilityBuilderError(f'topic {topic} was added twice to bag {self.path}')
        qos = parse_qos_profiles(qos_profiles)
        if msgdef is None:
            if msgtype not in TYPESTORE.fielddefs:
                raise VisibilityBuilderError(
                    f'unknown message type {msgtype!r} for topic {topic}: not a ROS 2 Jazzy '
                    'type known to rosbags; pass its msgdef')
            return writer.add_connection(
                topic, msgtype, typestore=TYPESTORE, offered_qos_profiles=qos)
        if not rihs01:
            rihs01 = _hash_msgdef(msgdef, msgtype)
        return writer.add_connection(
            topic, msgtype, msgdef=msgdef, rihs01=rihs01, offered_qos_profiles=qos)

    def write(self, connection: Connection, timestamp_ns: int, message: object) -> None:
        """Serialize a rosbags message object to CDR and write it.

        Args:
            connection: From :meth:`add_topic`.
            timestamp_ns: The receive (log) time in nanoseconds since the epoch.
            message: A message object of ``TYPESTORE.types[connection.msgtype]``.
        """
        self.write_raw(connection, timestamp_ns, serialize(message, connection.msgtype))

    def write_raw(self, connection: Connection, timestamp_ns: int, cdr_bytes: bytes) -> None:
        """Write an already serialized CDR message.

        Args:
            connection: From :meth:`add_topic`.
            timestamp_ns: The receive (log) time in nanoseconds since the epoch.
            cdr_bytes: The message in CDR, encapsulation header included.
        """
        writer = self._require_open()
        if timestamp_ns < 0:
            raise VisibilityBuilderError(f'negative timestamp {timestamp_ns} ns')
        writer.write(connection, int(timestamp_ns), bytes(cdr_bytes))
        self.message_count += 1

    def _require_open(self) -> Writer:
        if self._writer is None:
            raise VisibilityBuilderError(f'bag {self.path} is not open for writing')
        return self._writer


def _hash_msgdef(msgdef: str, msgtype: str) -> str:
    """Compute the RIHS01 type hash of a ``ros2msg`` definition (dependencies included)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    try:
        store.register(get_types_from_msg(msgdef, msgtype))
        return store.hash_rihs01(msgtype)
    except Exception as error:  # noqa: BLE001 - parser errors of many kinds
        raise VisibilityBuilderError(
            f'cannot parse the definition of {msgtype!r}: {_one_line(error)}') from None


def _zstd_compress_checked(data: bytes) -> bytes:
    return zstd.compress(data, options={zstd.CompressionParameter.checksum_flag: 1})


# -- QoS -------------------------------------------------------------------------------
def default_qos(
    *,
    reliability: str = 'reliable',
    durability: str = 'volatile',
    depth: int = 10,
) -> Qos:
    """Make a rosbags ``Qos`` for an offered profile, keep-last history.

    Args:
        reliability: ``'reliable'`` or ``'best_effort'``.
        durability: ``'volatile'`` or ``'transient_local'``.
        depth: History depth.
    """
    try:
        rel = QosReliability[reliability.upper()]
        dur = QosDurability[durability.upper()]
    except KeyError as error:
        raise VisibilityBuilderError(f'unknown QoS setting {error}') from None
    infinite = QosTime(0x7FFFFFFF, 0xFFFFFFFF)  # rmw's "infinite" as rosbag2 stores it
    return Qos(QosHistory.KEEP_LAST, depth, rel, dur, infinite, infinite,
               QosLiveliness.AUTOMATIC, infinite, False)


def parse_qos_profiles(profiles: str | Sequence[Qos | dict[str, Any]] | None) -> list[Qos]:
    """Normalize offered QoS profiles (YAML string, dicts or ``Qos``) to ``Qos``.

    Raises:
        VisibilityBuilderError: The profiles cannot be parsed.
    """
    if not profiles:
        return []
    if isinstance(profiles, str):
        try:
            return parse_qos(profiles)
        except (ReaderError, KeyError, TypeError) as error:
            raise VisibilityBuilderError(f'invalid offered QoS profiles: {error}') from None
    out: list[Qos] = []
    for item in profiles:
        if isinstance(item, Qos):
            out.append(item)
        else:
            try:
                out.extend(parse_qos([item]))  # type: ignore[list-item]
            except (ReaderError, KeyError, TypeError) as error:
                raise VisibilityBuilderError(f'invalid offered QoS profile: {error}') from None
    return out


def dump_qos_yaml(profiles: Sequence[Qos]) -> str:
    """Dump offered QoS profiles as rosbag2 (version 8) YAML text."""
    from rosbags.rosbag2.metadata import dump_qos_v8
    return dump_qos_v8(list(profiles))


# -- serialization ---------------------------------------------------------------------
def normalize_msgtype(msgtype: str) -> str:
    """``pkg/Type`` -> ``pkg/msg/Type``; ``pkg/msg/Type`` unchanged."""
    parts = msgtype.strip().split('/')
    if len(parts) == 2 and all(parts):
        return f'{parts[0]}/msg/{parts[1]}'
    if len(parts) == 3 and all(parts):
        return msgtype.strip()
    raise VisibilityBuilderError(f'invalid message type name {msgtype!r} (expected pkg/msg/Type)')


def serialize(message: object, msgtype: str, typestore: Any = None) -> bytes:
    """Serialize a rosbags message object to CDR bytes (little endian).

    The result is padded with zeros to a multiple of 4 bytes, as a DDS serialized
    payload is: Fast DDS pads every message it delivers that way, so a bag of
    padded messages is what ``ros2 bag record`` (or ``vbn record``) writes, and a
    play-to-record round trip reproduces it byte for byte. Every CDR reader
    ignores the trailing padding.

    Raises:
        VisibilityBuilderError: Unknown type or a message that does not fit it.
    """
    store = typestore or TYPESTORE
    msgtype = normalize_msgtype(msgtype)
    if msgtype not in store.fielddefs:
        raise VisibilityBuilderError(f'unknown message type {msgtype!r}')
    try:
        data = bytes(store.serialize_cdr(message, msgtype))
    except Exception as error:  # noqa: BLE001 - rosbags raises many kinds here
        raise VisibilityBuilderError(
            f'cannot serialize {type(message).__name__} as {msgtype}: {error}') from None
    return data + bytes(-len(data) % 4)


def deserialize(rawdata: bytes | memoryview, msgtype: str, typestore: Any = None) -> Any:
    """Deserialize CDR bytes into a rosbags message object.

    Args:
        rawdata: The CDR message.
        msgtype: Its type, ``pkg/msg/Type``.
        typestore: A rosbags typestore; default the Jazzy :data:`TYPESTORE`.

    Raises:
        VisibilityBuilderError: Unknown type or data that is not such a message.
    """
    store = typestore or TYPESTORE
    msgtype = normalize_msgtype(msgtype)
    if msgtype not in store.fielddefs:
        raise VisibilityBuilderError(
            f'unknown message type {msgtype!r}: not a ROS 2 Jazzy type known to rosbags')
    try:
        return store.deserialize_cdr(rawdata, msgtype)
    except Exception as error:  # noqa: BLE001 - corrupted data fails in many ways
        raise VisibilityBuilderError(
            f'cannot deserialize {len(rawdata)} bytes as {msgtype}: {error}') from None


# -- reading ---------------------------------------------------------------------------
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


@dataclass
class _Channel:
    topic: str
    msgtype: str
    qos: list[Qos]
    msgdef: str


@dataclass
class _ScanResult:
    channels: dict[str, _Channel] = field(default_factory=dict)  # by topic
    counts: dict[str, int] = field(default_factory=dict)  # by topic
    start_ns: int | None = None
    end_ns: int | None = None
    chunk_compression: set[str] = field(default_factory=set)
    problems: list[str] = field(default_factory=list)


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
        VisibilityBuilderError: The path does not exist or holds no readable bag.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.warnings: list[str] = []
        self.has_metadata = False
        self.recovered = False
        self._reader: Reader | None = None
        self._scan: _ScanResult | None = None
        self._typestore: Any = None
        self._known: dict[Path, dict[int, _Channel]] = {}
        self.files = self._resolve_files()
        self._open()

    # -- opening -------------------------------------------------------------------
    def _warn(self, message: str) -> None:
        self.warnings.append(message)
        _LOG.warning('%s', message)

    def _resolve_files(self) -> list[Path]:
        path = self.path
        if not path.exists():
            raise VisibilityBuilderError(f'bag {path} does not exist')
        if path.is_file():
            if path.suffix != '.mcap' and path.name != 'metadata.yaml':
                raise VisibilityBuilderError(
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
            raise VisibilityBuilderError(
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
            raise VisibilityBuilderError(
                f'{path}/metadata.yaml is not rosbag2 metadata: {_one_line(error)}') from None
        if storage != 'mcap':
            raise VisibilityBuilderError(
                f'bag {path} uses storage {storage!r}; only mcap bags are supported')
        missing = [f.name for f in files if not f.is_file()]
        if missing:
            raise VisibilityBuilderError(
                f'bag {path} is missing its storage file(s) {", ".join(missing)}')
        return files

    def _open(self) -> None:
        for file in self.files:
            size = file.stat().st_size
            if size == 0:
                raise VisibilityBuilderError(f'bag file {file} is empty (0 bytes)')
            with file.open('rb') as stream:
                if stream.read(8) != _MCAP_MAGIC:
                    raise VisibilityBuilderError(
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
                f'bag {self.path} is damaged ({_one_line(error)}); reading its intact part')
        scan = _ScanResult()
        self._known = {file: _top_level_channels(file) for file in self.files}
        for file in self.files:
            for _ in _scan_mcap(file, scan, want=None, known=self._known[file]):
                pass
        for problem in scan.problems:
            self._warn(problem)
        self.recovered = error is not None
        self._scan = scan
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
        storages = getattr(reader.storage, 'storages', None) or [reader.storage]
        for storage in storages:
            for chunk in getattr(storage, 'chunks', []):
                chunk_kinds.add(chunk.compression)
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

        A chunk that fails to decode ends the stream with a warning (indexed
        bags) or is skipped with a warning (recovered bags).
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

        if self._reader is not None:
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
                    f'bag {self.path} is corrupted ({_one_line(error)}) after {done} '
                    'messages; skipping the damaged chunk(s) and reading on')

            def keep_after(topic: str, msgtype: str, stamp: int) -> bool:
                return (last_stamp is None or stamp > last_stamp) and keep(topic, msgtype, stamp)

            scan = _ScanResult()
            for file in self.files:
                for chan, stamp, raw in _scan_mcap(file, scan, want=keep_after,
                                                   known=self._indexed_channels(file)):
                    yield chan.topic, chan.msgtype, stamp, raw
            for problem in scan.problems:
                self._warn(problem)
            return
        scan = _ScanResult()
        for file in self.files:
            for chan, stamp, raw in _scan_mcap(file, scan, want=keep,
                                               known=self._known.get(file)):
                yield chan.topic, chan.msgtype, stamp, raw

    def _indexed_channels(self, file: Path) -> dict[int, _Channel]:
        """Return the channels that rosbags read from the summary of ``file``."""
        if self._reader is None:
            return {}
        storage = self._reader.storage
        storages = getattr(storage, 'storages', None) or [storage]
        for mcap in storages:
            if Path(getattr(mcap, 'path', '')).name != file.name:
                continue
            by_id = {c.id: c for c in getattr(mcap, 'connections', [])}
            out = {}
            for cid, conn in by_id.items():
                qos = conn.ext.offered_qos_profiles if isinstance(
                    conn.ext, ConnectionExtRosbag2) else []
                out[cid] = _Channel(conn.topic, conn.msgtype, list(qos), conn.msgdef.data)
            return out
        return {}

    def deserialize(self, rawdata: bytes | memoryview, msgtype: str) -> Any:
        """Deserialize a message of this bag; types unknown to Jazzy use the bag's definition.

        Raises:
            VisibilityBuilderError: The type is unknown and the bag has no
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
            raise VisibilityBuilderError(
                f'unknown message type {msgtype!r}: not a ROS 2 Jazzy type and bag '
                f'{self.path} carries no definition for it')
        if msgdef.startswith('=' * 80 + '\nIDL: '):
            raise VisibilityBuilderError(
                f'message type {msgtype!r} has an IDL definition, which is not supported')
        if self._typestore is None:
            self._typestore = get_typestore(Stores.ROS2_JAZZY)
        try:
            self._typestore.register(get_types_from_msg(msgdef, msgtype))
        except Exception as error:  # noqa: BLE001 - parser errors of many kinds
            raise VisibilityBuilderError(
                f'cannot parse the definition of {msgtype!r} in bag {self.path}: '
                f'{_one_line(error)}') from None
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
    """Open a bag directory or ``.mcap`` file for reading (see :class:`BagReader`)."""
    return BagReader(path)


# -- helpers ---------------------------------------------------------------------------
def _one_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return text[0] if text else type(error).__name__


def _describe_compression(chunks: set[str], fmt: str, mode: str = '') -> str:
    parts = []
    kinds = sorted(k for k in chunks if k)
    if kinds:
        parts.append(f'{"/".join(kinds)} (chunks)')
    if mode and fmt:
        parts.append(f'{fmt} ({mode})')
    return ', '.join(parts) if parts else 'none'


def _topics_from_channels(
    channels: dict[str, _Channel], counts: dict[str, int],
) -> dict[str, TopicInfo]:
    topics = {topic: TopicInfo(topic, chan.msgtype, counts.get(topic, 0), chan.qos, chan.msgdef)
              for topic, chan in channels.items()}
    return dict(sorted(topics.items()))


# What reading a damaged MCAP file can raise, in rosbags or here (a garbage length
# field can make a reader try to allocate or index far beyond the file).
_READ_ERRORS = (ReaderError, zstd.ZstdError, struct.error, ValueError, EOFError, OSError,
                IndexError, TypeError, KeyError, OverflowError, MemoryError, UnicodeDecodeError)


class _TruncatedError(Exception):
    """The MCAP data ends inside a record."""


def _read_exact(stream: io.BufferedIOBase | io.BytesIO, size: int) -> bytes:
    data = stream.read(size)
    if len(data) != size:
        raise _TruncatedError(f'needed {size} bytes, got {len(data)}')
    return data


def _string(buf: bytes, pos: int) -> tuple[str, int]:
    (size,) = struct.unpack_from('<I', buf, pos)
    pos += 4
    if pos + size > len(buf):
        raise ValueError('string exceeds its record')
    return buf[pos:pos + size].decode('utf-8'), pos + size


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    if compression == '':
        raw = data
    elif compression == 'zstd':
        raw = zstd.decompress(data)
    elif compression == 'lz4':
        import lz4.frame
        raw = lz4.frame.decompress(data)
    else:
        raise ValueError(f'unsupported chunk compression {compression!r}')
    if len(raw) != size:
        raise ValueError(f'chunk size mismatch: expected {size} bytes, got {len(raw)}')
    return raw


def _decompress_partial(data: bytes, compression: str) -> bytes:
    """Decompress the readable start of a chunk whose end is cut off."""
    if compression == '':
        return data
    if compression == 'zstd':
        return zstd.ZstdDecompressor().decompress(data)
    if compression == 'lz4':
        import lz4.frame
        return lz4.frame.LZ4FrameDecompressor().decompress(data)
    raise ValueError(f'unsupported chunk compression {compression!r}')


def _parse_schema(body: bytes) -> tuple[int, str, str]:
    """Parse an MCAP schema record: (id, type name, definition text)."""
    (sid,) = struct.unpack_from('<H', body, 0)
    name, pos = _string(body, 2)
    _encoding, pos = _string(body, pos)
    (size,) = struct.unpack_from('<I', body, pos)
    return sid, name, body[pos + 4:pos + 4 + size].decode('utf-8')


def _parse_channel(body: bytes) -> tuple[int, int, str, list[Qos]]:
    """Parse an MCAP channel record: (id, schema id, topic, offered QoS)."""
    cid, sid = struct.unpack_from('<HH', body, 0)
    topic, pos = _string(body, 4)
    _encoding, pos = _string(body, pos)
    qos: list[Qos] = []
    (map_size,) = struct.unpack_from('<I', body, pos)
    pos += 4
    end = pos + map_size
    while pos < end:
        key, pos = _string(body, pos)
        value, pos = _string(body, pos)
        if key == 'offered_qos_profiles':
            try:
                qos = parse_qos(value)
            except Exception:  # noqa: BLE001 - QoS is optional information
                qos = []
    return cid, sid, topic, qos


def _top_level_channels(file: Path) -> dict[int, _Channel]:
    """Collect the schema and channel records outside chunks, the summary's included.

    The first chunk usually holds the only in-data copy of the channel records; when
    it is lost, the copies in the summary section (if readable) still name every
    channel. Records that do not parse are skipped; the walk stops at the footer or
    at a record that is not MCAP.
    """
    size = file.stat().st_size
    schemas: dict[int, tuple[str, str]] = {}
    raw_channels: dict[int, tuple[int, str, list[Qos]]] = {}
    with file.open('rb') as stream:
        offset = 8
        while offset + 9 <= size:
            stream.seek(offset)
            head = stream.read(9)
            op = head[0]
            (length,) = struct.unpack_from('<Q', head, 1)
            if op == _OP_FOOTER or (op > _OP_LAST and op < 0x80) or op == 0:
                break
            if op in (_OP_SCHEMA, _OP_CHANNEL) and length <= size - offset - 9:
                body = stream.read(length)
                try:
                    if op == _OP_SCHEMA:
                        sid, name, msgdef = _parse_schema(body)
                        schemas.setdefault(sid, (name, msgdef))
                    else:
                        cid, sid, topic, qos = _parse_channel(body)
                        raw_channels.setdefault(cid, (sid, topic, qos))
                except (ValueError, struct.error, UnicodeDecodeError, IndexError):
                    pass
            offset += 9 + length
    out = {}
    for cid, (sid, topic, qos) in raw_channels.items():
        name, msgdef = schemas.get(sid, ('', ''))
        if name:
            out[cid] = _Channel(topic, name, qos, msgdef)
    return out


def _scan_mcap(
    file: Path,
    scan: _ScanResult,
    want: Any,
    known: dict[int, _Channel] | None = None,
) -> Iterator[tuple[_Channel, int, bytes]]:
    """Read an MCAP file record by record, keeping what is intact.

    Fills ``scan`` with schemas, channels, counts and times; yields the messages
    ``want(topic, msgtype, stamp)`` accepts (none when ``want`` is None).
    ``known`` gives the channels of an indexed file, which make messages readable
    even when the chunk holding the channel records is lost. A corrupted chunk
    is skipped and noted in ``scan.problems``; the scan ends at the first
    unreadable record outside a chunk, or inside the last one of a truncated
    file (keeping that chunk's complete records).
    """
    schemas: dict[int, tuple[str, str]] = {}
    channels: dict[int, _Channel] = dict(known or {})
    for chan in channels.values():
        scan.channels.setdefault(chan.topic, chan)
        scan.counts.setdefault(chan.topic, 0)
    bad_chunks = 0

    def handle(
        op: int, body: bytes, in_chunk: bool, partial: bool,
    ) -> Iterator[tuple[_Channel, int, bytes]]:
        if op == _OP_SCHEMA:
            sid, name, msgdef = _parse_schema(body)
            schemas[sid] = (name, msgdef)
        elif op == _OP_CHANNEL:
            cid, sid, topic, qos = _parse_channel(body)
            name, msgdef = schemas.get(sid, ('', ''))
            if cid not in channels:
                channels[cid] = _Channel(topic, name, qos, msgdef)
                scan.channels.setdefault(topic, channels[cid])
                scan.counts.setdefault(topic, 0)
        elif op == _OP_MESSAGE:
            cid, _seq, log_time, _pub = struct.unpack_from('<HIQQ', body, 0)
            chan = channels.get(cid)
            if chan is None:
                return
            scan.counts[chan.topic] += 1
            scan.start_ns = log_time if scan.start_ns is None else min(scan.start_ns, log_time)
            scan.end_ns = log_time if scan.end_ns is None else max(scan.end_ns, log_time)
            if want is not None and want(chan.topic, chan.msgtype, log_time):
                yield chan, log_time, body[22:]
        elif op == _OP_CHUNK and not in_chunk:
            _start, _end, size, _crc = struct.unpack_from('<QQQI', body, 0)
            compression, pos = _string(body, 28)
            (csize,) = struct.unpack_from('<Q', body, pos)
            pos += 8
            if partial:
                raw = _decompress_partial(body[pos:pos + csize], compression)
            else:
                if pos + csize > len(body):
                    raise ValueError('chunk data exceeds its record')
                raw = _decompress(body[pos:pos + csize], compression, size)
            scan.chunk_compression.add(compression)
            # Parse the whole chunk first: a corrupted chunk is dropped as a whole,
            # a cut one (partial) keeps its complete records.
            records = []
            inner = io.BytesIO(raw)
            try:
                while inner.tell() < len(raw):
                    (iop,) = _read_exact(inner, 1)
                    (ilen,) = struct.unpack('<Q', _read_exact(inner, 8))
                    records.append((iop, _read_exact(inner, ilen)))
            except _TruncatedError:
                if not partial:
                    raise
            saved = (dict(scan.counts), scan.start_ns, scan.end_ns)
            try:
                out = [m for iop, ibody in records for m in handle(iop, ibody, True, False)]
            except Exception:
                scan.counts, scan.start_ns, scan.end_ns = saved
                raise
            yield from out

    size = file.stat().st_size
    with file.open('rb') as stream:
        stream.read(8)  # magic, checked by the caller
        offset = 8
        while True:
            head = stream.read(9)
            if not head:
                scan.problems.append(f'{file.name} ends without an MCAP footer (truncated)')
                break
            if len(head) < 9:
                scan.problems.append(f'{file.name} is truncated at byte {offset}')
                break
            op = head[0]
            (length,) = struct.unpack_from('<Q', head, 1)
            if op == _OP_FOOTER:
                break
            if not _OP_HEADER <= op <= _OP_LAST and op < 0x80:
                scan.problems.append(
                    f'{file.name}: invalid record (opcode {op:#04x}) at byte {offset}; '
                    'stopped there')
                break
            # A garbage length must not make us allocate it: read what the file has.
            body = stream.read(min(length, size - offset - 9))
            partial = len(body) < length
            before = sum(scan.counts.values())
            try:
                yield from handle(op, body, False, partial)
            except (ValueError, struct.error, _TruncatedError, zstd.ZstdError, UnicodeDecodeError,
                    IndexError, ImportError, OverflowError, MemoryError) as error:
                if op == _OP_CHUNK and not partial:
                    bad_chunks += 1
                elif not partial:
                    scan.problems.append(
                        f'{file.name}: unreadable record at byte {offset} ({error}); '
                        'stopped there')
                    break
            if partial:
                kept = sum(scan.counts.values()) - before
                what = (f'; kept {kept} messages of the cut chunk (unverified: its checksum '
                        'is in the lost part)') if op == _OP_CHUNK else ''
                scan.problems.append(
                    f'{file.name} is truncated at byte {offset + 9 + len(body)}, inside a '
                    f'record that starts at byte {offset}{what}')
                break
            offset += 9 + length
            if op == _OP_DATA_END:
                break
        if bad_chunks:
            scan.problems.append(f'{file.name}: skipped {bad_chunks} corrupted chunk(s)')
