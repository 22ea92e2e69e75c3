"""Write rosbag2 MCAP bags with rosbags (no rclpy).

A bag is a rosbag2 directory: ``metadata.yaml`` plus one ``.mcap`` file whose
chunks are zstd-compressed, with ROS 2 Jazzy message definitions embedded as
MCAP schemas. ``ros2 bag`` on a full ROS 2 install, rosbags, the ``mcap``
reader with ``mcap-ros2-support`` and evo all read these bags.

:class:`BagWriter` uses rosbags' rosbag2 writer with the MCAP storage plugin in
``CompressionMode.STORAGE``: rosbags then compresses every MCAP chunk with zstd
(what ``ros2 bag record --storage-preset-profile zstd_fast`` does); the file and
message compression modes of ``metadata.yaml`` stay empty, as rosbag2 writes them
for chunk compression. The zstd frames carry their content checksum, so a
corrupted chunk is detected on reading instead of decoding into garbage (rosbags
leaves the MCAP chunk CRC at zero). The metadata is rosbag2 version 8, the
version ROS 2 Jazzy writes.

A finished bag appears atomically: the writer works in a hidden scratch sibling
directory and, on a clean close, hands the finished bag to
:func:`vbn_common.atomic.atomic_output`, which flushes it to disk and renames it
into place; the scratch directory is removed, also when the block raises. (The
scratch directory exists because rosbags names the ``.mcap`` file after the bag
directory: the bag must be written under its final name.) ``vbn record`` instead
writes in place (``atomic=False``) and closes the bag on any exit, Ctrl-C
included, so that what was recorded stays readable.
"""
from __future__ import annotations

from collections.abc import Sequence
import os
from pathlib import Path
import shutil
import sys
import tempfile
from types import TracebackType
from typing import Any

from rosbags.interfaces import Connection, Qos
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

from vbn_common.atomic import atomic_output, check_output_folder
from vbn_common.bags.qos import parse_qos_profiles
from vbn_common.bags.serialization import (
    TYPESTORE,
    msgdef_hash,
    normalize_msgtype,
    serialize,
)
from vbn_common.errors import VbnCommonError

if sys.version_info >= (3, 14):  # pragma: no cover
    from compression import zstd
else:
    from backports import zstd

__all__ = ['ROSBAG2_VERSION', 'BagWriter']

#: rosbag2 metadata version written by ROS 2 Jazzy.
ROSBAG2_VERSION = 8


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
        VbnCommonError: ``path`` exists (without ``overwrite``) or the
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
            raise VbnCommonError(
                f'unknown bag compression {compression!r} (expected zstd or none)')
        if self.path.exists() and not (overwrite and atomic):
            raise VbnCommonError(f'{self.path} exists already, not overwriting')
        self.compression = compression
        self.atomic = atomic
        self.overwrite = overwrite
        self._scratch: Path | None = None
        self._writer: Writer | None = None
        self._closed = False
        self.message_count = 0

    # -- lifecycle -----------------------------------------------------------------
    def open(self) -> BagWriter:
        """Create the bag directory (or its scratch sibling) and open the MCAP file.

        Returns:
            The writer itself.

        Raises:
            VbnCommonError: The bag is open already or cannot be created.
        """
        if self._writer is not None:
            raise VbnCommonError(f'bag {self.path} is already open')
        check_output_folder(self.path)  # never create missing parents: say which
        if self.atomic:
            self._scratch = Path(tempfile.mkdtemp(
                prefix=f'.{self.path.name}.tmp-', dir=self.path.parent))
            target = self._scratch / self.path.name
        else:
            target = self.path
        writer = Writer(target, version=ROSBAG2_VERSION, storage_plugin=StoragePlugin.MCAP)
        if self.compression == 'zstd':
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        try:
            writer.open()
        except Exception as error:
            self._remove_scratch()
            raise VbnCommonError(f'cannot create bag {self.path}: {error}') from error
        storage = writer.storage
        if self.compression == 'zstd' and hasattr(storage, 'compressor'):
            # Standard zstd frames with their content checksum: readers detect a
            # corrupted chunk (rosbags writes no MCAP chunk CRC). rosbags offers no
            # option for it, so its MCAP storage's compressor is replaced.
            storage.compressor = _zstd_compress_checked
        self._writer = writer
        return self

    def close(self) -> None:
        """Finish the bag: write the MCAP summary and ``metadata.yaml``, rename into place.

        Safe to call twice.

        Raises:
            VbnCommonError: A bag appeared at ``path`` while writing (without
                ``overwrite``) or the bag cannot be renamed into place.
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
            self._publish()

    def _publish(self) -> None:
        """Move the finished bag from the scratch directory to ``path``, atomically."""
        assert self._scratch is not None
        try:
            if self.path.exists() and not self.overwrite:  # appeared while writing
                raise VbnCommonError(f'{self.path} exists already, not overwriting')
            with atomic_output(self.path, directory=True) as temporary:
                (self._scratch / self.path.name).rename(temporary)
        finally:
            self._remove_scratch()

    def abort(self) -> None:
        """Discard the bag being written (atomic mode leaves nothing behind)."""
        if self._closed:
            return
        self._closed = True
        writer, self._writer = self._writer, None
        if writer is not None:
            self.abort_writer(writer)

    def abort_writer(self, writer: Writer) -> None:
        """Abort ``writer`` and remove the scratch directory."""
        try:
            writer.abort()
        except Exception:  # noqa: BLE001 - best effort while already failing
            pass
        self._remove_scratch()

    def _remove_scratch(self) -> None:
        if self._scratch is not None:
            shutil.rmtree(self._scratch, ignore_errors=True)
            self._scratch = None

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
                list of rosbags ``Qos`` (see :func:`~vbn_common.bags.default_qos`)
                or QoS dicts. Recorded in the metadata so that ``play`` offers the same QoS.
            msgdef: The ``ros2msg`` definition text for a type unknown to the Jazzy
                typestore (``vbn record`` of a custom type).
            rihs01: The type hash for ``msgdef``; computed from it when omitted.

        Returns:
            The connection to pass to :meth:`write` or :meth:`write_raw`.

        Raises:
            VbnCommonError: The bag is not open, the topic exists already
                or the message type is unknown and no ``msgdef`` is given.
        """
        writer = self._require_open()
        msgtype = normalize_msgtype(msgtype)
        if any(conn.topic == topic for conn in writer.connections):
            raise VbnCommonError(f'topic {topic} was added twice to bag {self.path}')
        qos = parse_qos_profiles(qos_profiles)
        if msgdef is None:
            if msgtype not in TYPESTORE.fielddefs:
                raise VbnCommonError(
                    f'unknown message type {msgtype!r} for topic {topic}: not a ROS 2 Jazzy '
                    'type known to rosbags; pass its msgdef')
            return writer.add_connection(
                topic, msgtype, typestore=TYPESTORE, offered_qos_profiles=qos)
        if not rihs01:
            rihs01 = msgdef_hash(msgdef, msgtype)
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

        Raises:
            VbnCommonError: The bag is not open or the time is negative.
        """
        writer = self._require_open()
        if timestamp_ns < 0:
            raise VbnCommonError(f'negative timestamp {timestamp_ns} ns')
        writer.write(connection, int(timestamp_ns), bytes(cdr_bytes))
        self.message_count += 1

    @property
    def is_open(self) -> bool:
        """Whether messages can be written now."""
        return self._writer is not None

    def _require_open(self) -> Writer:
        if self._writer is None:
            raise VbnCommonError(f'bag {self.path} is not open for writing')
        return self._writer


def _zstd_compress_checked(data: bytes) -> bytes:
    return zstd.compress(data, options={zstd.CompressionParameter.checksum_flag: 1})
