"""Read what is intact in a damaged MCAP file: the recovery scan behind :class:`BagReader`.

An MCAP file (https://mcap.dev/spec) is a magic, then records framed as an opcode
byte, a little-endian uint64 body length and the body; a chunk record holds a
compressed run of schema, channel and message records. The ``mcap`` library parses
every record body (:mod:`mcap.records`), decompresses and checks chunks
(:func:`mcap.stream_reader.get_chunk_data_stream`) and reads the summary
(:func:`mcap.reader.make_reader`); this module uses those. What the library lacks
for a damaged file, and this module adds, is the walk itself: its
:class:`~mcap.stream_reader.StreamReader` parses each record straight from the
stream, so a garbage length field carries it past the record into the next ones,
a record cut by the end of the file is lost whole, and after the first error the
stream cannot resume. The walk here reads each record's body within its declared
length (bounded by the file size), so that

* a chunk whose zstd frame fails its checksum (or that does not parse) is skipped
  and the walk goes on with the next record;
* a chunk cut off by the end of the file keeps the complete records of its
  readable start (unverified: the frame's checksum is in the lost part);
* the walk stops, with a note saying where, at the first record outside a chunk
  that is not MCAP or does not parse.

Channels known from elsewhere (the summary of an indexed file, or the schema and
channel records outside chunks) make messages readable even when the chunk that
held the channel records is lost.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
import io
from pathlib import Path
import struct
import sys
from typing import BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import get_chunk_data_stream
from rosbags.interfaces import Qos
import zstandard

from vbn_common.bags.qos import qos_from_channel_metadata

if sys.version_info >= (3, 14):  # pragma: no cover
    from compression import zstd
else:
    from backports import zstd

__all__ = [
    'MCAP_MAGIC',
    'McapChannel',
    'ScanResult',
    'Want',
    'chunk_compressions',
    'scan_mcap',
    'summary_channels',
    'top_level_channels',
]

#: The eight bytes every MCAP file starts (and ends) with.
MCAP_MAGIC = b'\x89MCAP0\r\n'

_HEAD = struct.Struct('<BQ')  # a record's opcode and body length
_LAST_OPCODE = 0x10  # highest opcode of MCAP v0 (0x80 and above: user records)
_CHUNK_FIXED = 28  # a chunk record's fields before its compression name

#: What a damaged record can raise while it is parsed or decompressed (a garbage
#: length field can make a parser try to allocate or index far beyond the file).
_RECORD_ERRORS = (ValueError, struct.error, McapError, zstd.ZstdError, zstandard.ZstdError,
                  UnicodeDecodeError, IndexError, ImportError, OverflowError, MemoryError)


@dataclass
class McapChannel:
    """A channel with its schema: what a message record needs to be read."""

    topic: str
    msgtype: str
    qos: list[Qos]
    msgdef: str


@dataclass
class ScanResult:
    """What a scan found, gathered over the files of a bag."""

    channels: dict[str, McapChannel] = field(default_factory=dict)  # by topic
    counts: dict[str, int] = field(default_factory=dict)  # by topic
    start_ns: int | None = None
    end_ns: int | None = None
    chunk_compression: set[str] = field(default_factory=set)
    problems: list[str] = field(default_factory=list)


#: Decides from (topic, msgtype, log time) whether a message is wanted.
Want = Callable[[str, str, int], bool]


# -- framing ---------------------------------------------------------------------------
@dataclass(frozen=True)
class _Head:
    """A record's place and header; ``opcode`` is None when the header is cut off."""

    offset: int
    opcode: int | None
    length: int


class _CutRecordError(Exception):
    """The data ends inside a record."""


def _heads(stream: BinaryIO, size: int, offset: int) -> Iterator[_Head]:
    """Walk the record headers of ``stream`` (``size`` bytes) from ``offset`` to its end.

    After each header the stream stands at the record's body, for the caller to read
    (:func:`_body`) or not: the walk seeks to the next header by the declared length.
    """
    while offset < size:  # a garbage length may point far beyond the data
        stream.seek(offset)
        head = stream.read(_HEAD.size)
        if not head:
            return
        if len(head) < _HEAD.size:
            yield _Head(offset, None, 0)
            return
        opcode, length = _HEAD.unpack(head)
        yield _Head(offset, opcode, length)
        offset += _HEAD.size + length


def _body(stream: BinaryIO, head: _Head, size: int) -> bytes:
    """Read the body of the record at ``head``: what the data holds of it."""
    # A garbage length must not make us allocate it: read what the data has.
    return stream.read(min(head.length, size - head.offset - _HEAD.size))


class _ExactStream(ReadDataStream):
    """mcap's record field reader, but a field that runs past its record is an error.

    mcap's reader returns what there is when a field is longer than the data left;
    inside a record of known length that means the record is damaged.
    """

    def read(self, length: int) -> bytes:
        """Read ``length`` bytes of the record, or raise :class:`EndOfFile`."""
        try:
            data = super().read(length)
        except EndOfFile:
            data = b''
        if len(data) < length:
            raise EndOfFile(f'a field of {length} bytes runs past its record')
        return data


def _fields(body: bytes, *, exact: bool = True) -> ReadDataStream:
    return (_ExactStream if exact else ReadDataStream)(io.BytesIO(body))


def _channel_of(record: Channel, schemas: dict[int, tuple[str, str]]) -> McapChannel:
    name, msgdef = schemas.get(record.schema_id, ('', ''))
    return McapChannel(record.topic, name, qos_from_channel_metadata(record.metadata), msgdef)


def _schema_of(body: bytes) -> tuple[int, str, str]:
    """Parse a schema record: (id, type name, definition text)."""
    # The definition may run past a damaged record: what is there is kept.
    schema = Schema.read(_fields(body, exact=False))
    return schema.id, schema.name, schema.data.decode('utf-8')


# -- chunks ----------------------------------------------------------------------------
def _chunk_data(body: bytes, cut: bool) -> tuple[str, bytes]:
    """Decompress a chunk record: (compression, its records' bytes).

    An intact chunk is decompressed and checked by mcap (a zstd frame checks its
    content checksum); a chunk cut off by the end of the file gives what its
    readable start decompresses to.
    """
    chunk = Chunk.read(_fields(body, exact=not cut))
    if chunk.compression not in ('', 'zstd', 'lz4'):
        raise ValueError(f'unsupported chunk compression {chunk.compression!r}')
    if cut:
        return chunk.compression, _decompress_start(chunk.data, chunk.compression)
    stream, size = get_chunk_data_stream(chunk)
    if size != chunk.uncompressed_size:
        raise ValueError(
            f'chunk size mismatch: expected {chunk.uncompressed_size} bytes, got {size}')
    return chunk.compression, stream.read(size)


def _decompress_start(data: bytes, compression: str) -> bytes:
    """Decompress the readable start of a chunk whose end is cut off."""
    if compression == 'zstd':
        return zstd.ZstdDecompressor().decompress(data)
    if compression == 'lz4':
        import lz4.frame
        return lz4.frame.LZ4FrameDecompressor().decompress(data)
    return data


def _chunk_records(raw: bytes, cut: bool) -> list[tuple[int, bytes]]:
    """Split a chunk's records into (opcode, body); a cut chunk keeps its complete ones.

    Raises:
        _CutRecordError: An intact chunk ends inside a record (the chunk is damaged).
    """
    records = []
    stream = io.BytesIO(raw)
    for head in _heads(stream, len(raw), 0):
        body = b'' if head.opcode is None else _body(stream, head, len(raw))
        if head.opcode is None or len(body) < head.length:
            if cut:
                break
            raise _CutRecordError(f'chunk ends inside a record at byte {head.offset}')
        records.append((head.opcode, body))
    return records


# -- the scan --------------------------------------------------------------------------
class _FileScan:
    """One sequential pass over one MCAP file, adding to a :class:`ScanResult`."""

    def __init__(
        self, file: Path, scan: ScanResult, want: Want | None,
        known: dict[int, McapChannel] | None,
    ) -> None:
        self.file = file
        self.scan = scan
        self.want = want
        self.schemas: dict[int, tuple[str, str]] = {}
        self.channels: dict[int, McapChannel] = dict(known or {})
        for chan in self.channels.values():
            scan.channels.setdefault(chan.topic, chan)
            scan.counts.setdefault(chan.topic, 0)

    def record(self, opcode: int, body: bytes) -> Iterator[tuple[McapChannel, int, bytes]]:
        """Take in a schema, channel or message record; yield a wanted message."""
        scan = self.scan
        if opcode == Opcode.SCHEMA:
            sid, name, msgdef = _schema_of(body)
            self.schemas[sid] = (name, msgdef)
        elif opcode == Opcode.CHANNEL:
            channel = Channel.read(_fields(body))
            if channel.id not in self.channels:
                chan = _channel_of(channel, self.schemas)
                self.channels[channel.id] = chan
                scan.channels.setdefault(chan.topic, chan)
                scan.counts.setdefault(chan.topic, 0)
        elif opcode == Opcode.MESSAGE:
            message = Message.read(_fields(body), len(body))
            chan = self.channels.get(message.channel_id)
            if chan is None:
                return
            stamp = message.log_time
            scan.counts[chan.topic] += 1
            scan.start_ns = stamp if scan.start_ns is None else min(scan.start_ns, stamp)
            scan.end_ns = stamp if scan.end_ns is None else max(scan.end_ns, stamp)
            if self.want is not None and self.want(chan.topic, chan.msgtype, stamp):
                yield chan, stamp, message.data

    def chunk(self, body: bytes, cut: bool) -> list[tuple[McapChannel, int, bytes]]:
        """Take in a chunk as a whole: a damaged one changes nothing and raises."""
        compression, raw = _chunk_data(body, cut)
        self.scan.chunk_compression.add(compression)
        records = _chunk_records(raw, cut)
        scan = self.scan
        saved = (dict(scan.counts), scan.start_ns, scan.end_ns)
        try:
            return [m for opcode, inner in records for m in self.record(opcode, inner)]
        except Exception:
            scan.counts, scan.start_ns, scan.end_ns = saved
            raise

    def run(self) -> Iterator[tuple[McapChannel, int, bytes]]:
        """Walk the file's records (see :func:`scan_mcap`)."""
        file, scan = self.file, self.scan
        size = file.stat().st_size
        bad_chunks = 0
        with file.open('rb') as stream:
            for head in _heads(stream, size, len(MCAP_MAGIC)):
                offset, opcode = head.offset, head.opcode
                if opcode is None:
                    scan.problems.append(f'{file.name} is truncated at byte {offset}')
                    break
                if opcode == Opcode.FOOTER:
                    break
                if not Opcode.HEADER <= opcode <= _LAST_OPCODE and opcode < 0x80:
                    scan.problems.append(
                        f'{file.name}: invalid record (opcode {opcode:#04x}) at byte {offset}; '
                        'stopped there')
                    break
                body = _body(stream, head, size)
                cut = len(body) < head.length
                before = sum(scan.counts.values())
                try:
                    if opcode == Opcode.CHUNK:
                        yield from self.chunk(body, cut)
                    else:
                        yield from self.record(opcode, body)
                except (*_RECORD_ERRORS, _CutRecordError) as error:
                    if opcode == Opcode.CHUNK and not cut:
                        bad_chunks += 1
                    elif not cut:
                        scan.problems.append(
                            f'{file.name}: unreadable record at byte {offset} ({error}); '
                            'stopped there')
                        break
                if cut:
                    kept = sum(scan.counts.values()) - before
                    what = (f'; kept {kept} messages of the cut chunk (unverified: its '
                            'checksum is in the lost part)') if opcode == Opcode.CHUNK else ''
                    scan.problems.append(
                        f'{file.name} is truncated at byte {offset + 9 + len(body)}, inside a '
                        f'record that starts at byte {offset}{what}')
                    break
                if opcode == Opcode.DATA_END:
                    break
            else:
                scan.problems.append(f'{file.name} ends without an MCAP footer (truncated)')
        if bad_chunks:
            scan.problems.append(f'{file.name}: skipped {bad_chunks} corrupted chunk(s)')


def scan_mcap(
    file: Path,
    scan: ScanResult,
    want: Want | None,
    known: dict[int, McapChannel] | None = None,
) -> Iterator[tuple[McapChannel, int, bytes]]:
    """Read an MCAP file record by record, keeping what is intact.

    Args:
        file: The ``.mcap`` file (its magic checked by the caller).
        scan: Filled with channels, counts, times, chunk compressions and problems.
        want: Decides which messages to yield; None yields none (counting only).
        known: Channels by MCAP channel id from elsewhere (an indexed file's summary,
            :func:`top_level_channels`), which make messages readable even when the
            chunk holding the channel records is lost.

    Yields:
        ``(channel, log time in ns, CDR bytes)`` of each wanted message, in file order.

    A corrupted chunk is skipped and counted in ``scan.problems``; the scan ends at
    the footer, at the data end record, at the first unreadable record outside a
    chunk, or inside the last record of a truncated file (keeping the complete
    records of a cut chunk).
    """
    return _FileScan(file, scan, want, known).run()


# -- channels and chunk kinds from outside the chunks ----------------------------------
def top_level_channels(file: Path) -> dict[int, McapChannel]:
    """Collect the schema and channel records outside chunks, the summary's included.

    The first chunk usually holds the only in-data copy of the channel records; when
    it is lost, the copies in the summary section (if readable) still name every
    channel. Records that do not parse are skipped; the walk stops at the footer or
    at a record that is not MCAP.

    Returns:
        The channels that have a schema, by MCAP channel id.
    """
    size = file.stat().st_size
    schemas: dict[int, tuple[str, str]] = {}
    records: dict[int, Channel] = {}
    with file.open('rb') as stream:
        for head in _heads(stream, size, len(MCAP_MAGIC)):
            opcode = head.opcode
            if opcode is None or opcode == Opcode.FOOTER or opcode == 0 or (
                    _LAST_OPCODE < opcode < 0x80):
                break
            if (opcode not in (Opcode.SCHEMA, Opcode.CHANNEL)
                    or head.length > size - head.offset - _HEAD.size):
                continue
            body = _body(stream, head, size)
            try:
                if opcode == Opcode.SCHEMA:
                    sid, name, msgdef = _schema_of(body)
                    schemas.setdefault(sid, (name, msgdef))
                else:
                    channel = Channel.read(_fields(body))
                    records.setdefault(channel.id, channel)
            except _RECORD_ERRORS:
                pass
    out = {}
    for cid, channel in records.items():
        chan = _channel_of(channel, schemas)
        if chan.msgtype:
            out[cid] = chan
    return out


def summary_channels(file: Path) -> dict[int, McapChannel]:
    """Read the channels of an indexed MCAP file from its summary section.

    Returns:
        The channels by MCAP channel id ({} when the file has no readable summary).
    """
    try:
        with file.open('rb') as stream:
            summary = make_reader(stream).get_summary()
    except (*_RECORD_ERRORS, OSError):
        return {}
    if summary is None:
        return {}
    schemas = {sid: (s.name, s.data.decode('utf-8', errors='replace'))
               for sid, s in summary.schemas.items()}
    return {cid: _channel_of(channel, schemas) for cid, channel in summary.channels.items()}


def chunk_compressions(file: Path) -> set[str]:
    """Return the compressions of an MCAP file's chunks (``''``: uncompressed).

    The summary's chunk indexes name them; when the file has no readable summary,
    the chunk records' headers do.
    """
    try:
        with file.open('rb') as stream:
            summary = make_reader(stream).get_summary()
        if summary is not None and summary.chunk_indexes:
            return {index.compression for index in summary.chunk_indexes}
    except _RECORD_ERRORS:
        pass
    kinds = set()
    size = file.stat().st_size
    with file.open('rb') as stream:
        for head in _heads(stream, size, len(MCAP_MAGIC)):
            if head.opcode is None or head.opcode == Opcode.FOOTER:
                break
            if head.opcode != Opcode.CHUNK:
                continue
            # Only the header: start and end time, uncompressed size and CRC, compression.
            header = _fields(stream.read(min(head.length, _CHUNK_FIXED + 4 + 64)))
            try:
                header.read(_CHUNK_FIXED)
                kinds.add(header.read_prefixed_string())
            except _RECORD_ERRORS:
                continue
    return kinds
