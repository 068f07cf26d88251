"""MCAP sink: JSON messages with jsonschema schemas into one crash-safe MCAP file.

Owns the file format side of the output contract (schemas in
:mod:`cmsensord.sinks.schemas`):

* one file ``<prefix>-<UTC yyyymmddTHHMMSSZ>.mcap``, written as ``*.mcap.part``
  and renamed by :meth:`McapSink.close` once the summary and footer are on
  disk (then the directory is fsynced). A ``.part`` file left by a crash holds
  every chunk flushed before it; :func:`summarize` reads it up to the first
  incomplete record, and :func:`salvage` rewrites its complete chunks into a
  finished ``<stem>.salvaged.mcap``.
* chunks are finished and written (unbuffered: straight to the kernel, so a
  kill -9 loses nothing written) every ``flush_s`` seconds by the injected
  clock, so at most ``flush_s`` of data is lost on a crash of the process;
* every OSError is a :class:`SinkIOError` naming the operation; after one the
  file is *failed* and never written or fsynced again (see :class:`McapSink`);
* schemas and channels are registered lazily, on the first message of a topic;
* JSON never carries NaN or infinity: they become ``null``. The fast path
  encodes with ``allow_nan=False``; only a message that fails it is
  sanitised and encoded again, so clean messages cost nothing extra;
* the MCAP records come from mcap's record classes, but messages are packed
  into the open chunk directly (:class:`_ChunkWriter`), which costs ~1 us
  instead of ~6 us per message through ``mcap.writer.Writer``.

Rotation (``rotate_s``/``rotate_mb``), periodic fsync (``fsync_s``),
retention and what to do after an error are the caller's policy
(:class:`~cmsensord.sinks.rotating.RotatingSink`); :attr:`McapSink.bytes_written`,
:attr:`McapSink.opened_at`, :attr:`McapSink.unpersisted`, :meth:`McapSink.sync`,
:meth:`McapSink.abandon`, :func:`log_files` and :func:`salvage_leftovers` give it
what it needs.
"""

from __future__ import annotations

import fcntl
import io
import json
import math
import os
import re
import struct
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.stream_reader import StreamReader, breakup_chunk

try:
    import lz4.frame as _lz4
except ImportError:  # optional, as in mcap itself
    _lz4 = None

from cmsensord import __version__
from cmsensord.errors import SinkError
from cmsensord.sinks.schemas import (
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    SCHEMAS,
    TOPIC_EVENTS,
    schema_bytes,
    schema_name,
)

__all__ = [
    "McapSink",
    "SinkIOError",
    "SalvageResult",
    "ns_to_stamp",
    "read_messages",
    "summarize",
    "iter_messages_lenient",
    "salvage",
    "salvage_leftovers",
    "log_files",
    "NOT_MCAP",
]

_NS = 1_000_000_000
_MAGIC = b"\x89MCAP0\r\n"
_COMPRESSION = {"zstd": "zstd", "lz4": "lz4", "none": ""}  # option -> Chunk.compression
# A record longer than this in a file we wrote means corruption, not data
# (chunks are ~1 MiB); reading it would only waste memory.
_RECORD_LIMIT = 256 * 1024 * 1024
_KNOWN_OPCODES = frozenset(int(op) for op in Opcode)
#: summarize()'s ``error`` for a file that does not start with the MCAP magic
NOT_MCAP = "not an MCAP file (bad magic)"


class SinkIOError(SinkError):
    """The file system refused an operation (ENOSPC, EIO, EDQUOT, a failed fsync, ...).

    ``op`` is what failed: ``"open"`` (directory, new file or its header),
    ``"write"`` (a chunk), ``"fsync"``, ``"close"`` (summary, footer, rename)
    or ``"read"`` (salvage); ``errno`` the OSError's errno (None when there was
    no OSError, e.g. a write to a file abandoned earlier); ``path`` the file.
    """

    def __init__(self, message: str, *, op: str, err: OSError | None, path: Path) -> None:
        super().__init__(message)
        self.op = op
        self.errno = err.errno if err is not None else None
        self.path = path


def _why(err: OSError) -> str:
    return err.strerror or str(err)


class _RawFile:
    """An unbuffered file: every write() puts all its bytes in the kernel or raises.

    The sink writes whole records (a finished chunk with its message indexes
    in one call), so Python-level buffering gains nothing, and without it the
    bytes on disk after an error are exactly those the kernel accepted: a
    failed file is closed without any buffered data being written later.
    """

    def __init__(self, fd: int) -> None:
        self.fd = fd

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self.fd, view)  # a short count on a full disk: the next call raises
            view = view[n:]

    def flush(self) -> None:
        """Nothing to do: write() leaves nothing in this process."""

    def fileno(self) -> int:
        return self.fd

    def close(self) -> None:
        if self.fd >= 0:
            fd, self.fd = self.fd, -1
            os.close(fd)


def ns_to_stamp(ns: int) -> dict[str, int]:
    """Nanoseconds -> ``{"sec": ns // 10**9, "nsec": ns % 10**9}``."""
    return {"sec": ns // _NS, "nsec": ns % _NS}


# ---------------------------------------------------------------------------
# JSON encoding
# ---------------------------------------------------------------------------


def _default(obj: Any) -> Any:
    """json ``default=`` hook: numpy scalars and arrays -> Python objects."""
    tolist = getattr(obj, "tolist", None)  # np.ndarray and np.generic both have it
    if tolist is not None:
        return tolist()
    raise TypeError(f"object of type {type(obj).__name__} is not JSON serializable")


# One encoder, built once: json.dumps(**kwargs) would build a new one per call.
# check_circular=False: no id() bookkeeping per container (~20 % faster); a
# circular message then fails with RecursionError, handled like any bad message.
_encode = json.JSONEncoder(
    allow_nan=False, separators=(",", ":"), default=_default, check_circular=False
).encode


def _sanitize(obj: Any) -> Any:
    """A copy of ``obj`` with every non-finite float replaced by None.

    The slow path: only called for a message the strict encoder rejected.
    """
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _sanitize(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_sanitize(v) for v in obj]
    if isinstance(obj, (str, int)) or obj is None:
        return obj
    tolist = getattr(obj, "tolist", None)
    if tolist is not None:
        return _sanitize(tolist())
    return obj


# ---------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------


def _records(*records: Any) -> bytes:
    """Serialise mcap record objects with mcap's own record code."""
    builder = RecordBuilder()
    for record in records:
        record.write(builder)
    return builder.end()


_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
_MESSAGE_FIXED = 2 + 4 + 8 + 8
_OP_MESSAGE = int(Opcode.MESSAGE)


class _ChunkWriter:
    """A minimal chunked MCAP writer with a cheap add_message().

    mcap's ``Writer.add_message`` costs ~6 us a message in Python (a Message
    object, several struct.pack calls and BytesIO seeks per record); here a
    message is one struct.pack and two bytearray appends into the open chunk.
    Every other record (header, schema, channel, chunk, message index, chunk
    index, statistics, summary offsets, footer) is built by mcap's own record
    classes, and the file layout is the one ``mcap.writer.Writer`` produces with
    its defaults: schemas and channels inside chunks, a message index after
    each chunk, summary with repeated schemas and channels, statistics, chunk
    and metadata indexes, summary offsets and CRCs (including the data-section
    CRC, which mcap's writer leaves 0 by default).
    """

    def __init__(self, fh: Any, compression: str, chunk_size: int) -> None:
        if compression == "lz4" and _lz4 is None:
            raise SinkError("lz4 compression needs the lz4 package (pip install lz4)")
        self._fh = fh
        self._compression = compression
        self._chunk_size = chunk_size
        self.pos = 0  # bytes written to fh
        self.persisted = 0  # messages in chunks handed to the kernel completely
        self._data_crc = 0
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._channel_counts: dict[int, int] = {}
        self._message_count = 0
        self._start_time = 0
        self._end_time = 0
        self._new_chunk()

    def _new_chunk(self) -> None:
        self._chunk = bytearray()
        self._index: dict[int, list[tuple[int, int]]] = {}
        self._n = 0
        self._t0 = 0
        self._t1 = 0

    def _out(self, data: bytes) -> None:
        self._fh.write(data)
        self._data_crc = zlib.crc32(data, self._data_crc)
        self.pos += len(data)

    def start(self, library: str) -> None:
        self._out(_MAGIC + _records(Header(profile="", library=library)))

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        raw = _records(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=self.pos, length=len(raw), name=name))
        self._out(raw)

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._chunk += _records(schema)
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int) -> int:
        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata={},
        )
        self._channels.append(channel)
        self._chunk += _records(channel)
        return channel.id

    def add_message(self, channel_id: int, log_time: int, data: bytes) -> None:
        chunk = self._chunk
        records = self._index.get(channel_id)
        if records is None:
            records = self._index[channel_id] = []
        records.append((log_time, len(chunk)))
        chunk += _MESSAGE_HEAD.pack(
            _OP_MESSAGE, _MESSAGE_FIXED + len(data), channel_id, 0, log_time, log_time
        )
        chunk += data
        if self._n:
            if log_time < self._t0:
                self._t0 = log_time
            elif log_time > self._t1:
                self._t1 = log_time
        else:
            self._t0 = self._t1 = log_time
        self._n += 1
        if len(chunk) > self._chunk_size:
            self.finish_chunk()

    def finish_chunk(self) -> None:
        """Compress the open chunk and write it with its message indexes."""
        if not self._n:  # keep schema/channel records for the next chunk
            return
        raw = bytes(self._chunk)
        if self._compression == "zstd":
            data = zstandard.compress(raw)
        elif self._compression == "lz4":
            data = _lz4.compress(raw)
        else:
            data = raw
        chunk = Chunk(
            compression=self._compression,
            data=data,
            message_start_time=self._t0,
            message_end_time=self._t1,
            uncompressed_crc=zlib.crc32(raw),
            uncompressed_size=len(raw),
        )
        index, n = self._index, self._n
        self._new_chunk()  # before writing: a failing disk must not make the chunk grow
        self._write_chunk(chunk, index, n)

    def add_chunk(
        self,
        chunk: Chunk,
        index: dict[int, list[tuple[int, int]]],
        n: int,
        schemas: list[Schema],
        channels: list[Channel],
    ) -> None:
        """Write a chunk taken from another file (salvage) with the message
        index rebuilt from its content; its schemas and channels join the summary."""
        self._schemas.extend(schemas)
        self._channels.extend(channels)
        self._write_chunk(chunk, index, n)

    def _write_chunk(self, chunk: Chunk, index: dict[int, list[tuple[int, int]]], n: int) -> None:
        chunk_raw = _records(chunk)
        t0, t1 = chunk.message_start_time, chunk.message_end_time
        chunk_start = self.pos
        index_start = chunk_start + len(chunk_raw)
        builder = RecordBuilder()
        offsets: dict[int, int] = {}
        for channel_id, records in index.items():
            offsets[channel_id] = index_start + builder.count
            MessageIndex(channel_id=channel_id, records=records).write(builder)
            self._channel_counts[channel_id] = self._channel_counts.get(channel_id, 0) + len(records)
        index_raw = builder.end()
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=t0,
                message_end_time=t1,
                chunk_start_offset=chunk_start,
                chunk_length=len(chunk_raw),
                message_index_offsets=offsets,
                message_index_length=len(index_raw),
                compression=chunk.compression,
                compressed_size=len(chunk.data),
                uncompressed_size=chunk.uncompressed_size,
            )
        )
        if n:
            if self._message_count:
                self._start_time = min(self._start_time, t0)
                self._end_time = max(self._end_time, t1)
            else:
                self._start_time, self._end_time = t0, t1
        self._message_count += n
        self._out(chunk_raw + index_raw)
        self.persisted += n

    def finish(self) -> None:
        """Last chunk, DataEnd, summary section, footer and closing magic."""
        self.finish_chunk()
        self._out(_records(DataEnd(data_section_crc=self._data_crc)))
        summary_start = self.pos
        builder = RecordBuilder()
        offsets: list[SummaryOffset] = []
        groups = (
            (Opcode.SCHEMA, self._schemas),
            (Opcode.CHANNEL, self._channels),
            (
                Opcode.STATISTICS,
                [
                    Statistics(
                        message_count=self._message_count,
                        schema_count=len(self._schemas),
                        channel_count=len(self._channels),
                        attachment_count=0,
                        metadata_count=len(self._metadata_indexes),
                        chunk_count=len(self._chunk_indexes),
                        message_start_time=self._start_time,
                        message_end_time=self._end_time,
                        channel_message_counts=dict(self._channel_counts),
                    )
                ],
            ),
            (Opcode.CHUNK_INDEX, self._chunk_indexes),
            (Opcode.METADATA_INDEX, self._metadata_indexes),
        )
        for opcode, records in groups:
            if not records:
                continue
            group_start = builder.count
            for record in records:
                record.write(builder)
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode,
                    group_start=summary_start + group_start,
                    group_length=builder.count - group_start,
                )
            )
        summary_offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        # Footer CRC: summary bytes, then the footer's opcode, length and first two fields.
        crc = zlib.crc32(summary)
        crc = zlib.crc32(
            struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4, summary_start, summary_offset_start),
            crc,
        )
        footer = Footer(
            summary_start=summary_start,
            summary_offset_start=summary_offset_start,
            summary_crc=crc,
        )
        self._out(summary + _records(footer) + _MAGIC)


class McapSink:
    """Writes messages to one MCAP file; schemas and channels registered lazily per topic.

    Args:
        out_dir: directory of the file, created (with parents) if needed.
        prefix: file name prefix.
        compression: ``"zstd"``, ``"lz4"`` or ``"none"``.
        flush_s: finish and write the current chunk when this many seconds (by
            ``clock``) have passed since the last flush.
        clock: monotonic seconds, injectable for tests.
        metadata: written as an MCAP Metadata record named ``"cmsensord"``.
        wall_clock: Unix seconds used for the file name (injectable for tests).
        chunk_size: uncompressed bytes after which a chunk is finished anyway.

    Raises:
        SinkError: an argument is invalid; :class:`SinkIOError` (a SinkError,
            ``op="open"``) when the directory cannot be created or the file
            and its header cannot be written (one-line message naming it).

    Errors while writing: every OSError becomes a :class:`SinkIOError` naming
    the operation, and the file is then *failed*: nothing more is written to
    it (a failed fsync is never retried, since the kernel may already have
    dropped the dirty pages), :meth:`close` only closes the descriptor and
    keeps the ``.part`` file, whose complete chunks :func:`salvage` recovers.
    The ``.part`` file is locked (``flock``) while this sink has it open, so a
    salvage by another process never touches a file being written.
    """

    def __init__(
        self,
        out_dir: str | Path,
        *,
        prefix: str = "cmsensord",
        compression: str = "zstd",
        flush_s: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
        metadata: dict[str, str] | None = None,
        wall_clock: Callable[[], float] = time.time,
        chunk_size: int = 1024 * 1024,
    ) -> None:
        if compression not in _COMPRESSION:
            raise SinkError(
                f"unknown MCAP compression {compression!r} (one of {', '.join(_COMPRESSION)})"
            )
        if not flush_s > 0:
            raise SinkError(f"flush_s must be > 0 (got {flush_s!r})")
        self.out_dir = Path(out_dir)
        self._clock = clock
        self._flush_s = float(flush_s)
        self._channels: dict[str, tuple[int, str]] = {}  # topic -> (channel id, kind)
        self._schemas: dict[str, int] = {}  # kind -> schema id
        self.messages_written = 0
        self._synced = 0  # persisted messages at the last successful fsync
        self._closed = False
        self._failed = False

        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise SinkIOError(
                f"{self.out_dir}: cannot create output directory: {_why(err)}",
                op="open", err=err, path=self.out_dir,
            ) from None
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(wall_clock()))
        self._fh = self._open_unique(prefix, stamp)

        try:
            self._writer = _ChunkWriter(self._fh, _COMPRESSION[compression], chunk_size)
            self._writer.start(library=f"cmsensord/{__version__}")
            if metadata:
                self._writer.add_metadata("cmsensord", {str(k): str(v) for k, v in metadata.items()})
        except (OSError, SinkError) as err:
            self._fh.close()
            try:
                self.part_path.unlink(missing_ok=True)  # a header alone holds nothing to keep
            except OSError:
                pass
            if isinstance(err, SinkError):
                raise
            raise SinkIOError(
                f"{self.part_path}: cannot write: {_why(err)}", op="open", err=err, path=self.part_path
            ) from None
        self.opened_at = clock()
        self._last_flush = self.opened_at

    def _open_unique(self, prefix: str, stamp: str) -> _RawFile:
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
        # after the newest file of this stamp: names stay in creation order even when
        # retention has deleted older files of the same second
        first = 0
        pattern = _log_name(prefix)
        try:
            for name in os.listdir(self.out_dir):
                m = pattern.fullmatch(name)
                if m is not None and m.group(1) == stamp:
                    first = max(first, int(m.group(2) or 0) + 1)
        except OSError:
            pass  # the open below reports an unusable directory
        for k in range(first, first + 1000):
            base = f"{prefix}-{stamp}" + (f"-{k}" if k else "")
            final = self.out_dir / f"{base}.mcap"
            part = self.out_dir / f"{base}.mcap.part"
            if final.exists():
                continue
            try:
                fd = os.open(part, flags, 0o644)  # exclusive: never clobber another writer's file
            except FileExistsError:
                continue
            except OSError as err:
                raise SinkIOError(
                    f"{self.out_dir}: cannot write in output directory: {_why(err)}",
                    op="open", err=err, path=part,
                ) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # salvage skips locked files
            except OSError:
                pass  # no flock on this file system: salvage runs only at start anyway
            self.path = final
            self.part_path = part
            return _RawFile(fd)
        raise SinkError(f"{self.out_dir}: no free file name for {prefix}-{stamp}.mcap")

    def _fail(self, op: str, err: OSError) -> SinkIOError:
        """Mark the file failed (nothing more is written to it); the error to raise."""
        self._failed = True
        self._channels = {}  # every later write() goes through _register(), which refuses
        verb = {"write": "write failed", "fsync": "fsync failed", "close": "cannot finish MCAP file"}
        return SinkIOError(
            f"{self.part_path}: {verb.get(op, op + ' failed')}: {_why(err)}",
            op=op, err=err, path=self.part_path,
        )

    # -- hot path ----------------------------------------------------------

    def write(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> None:
        """Append one message.

        ``schema`` is the kind key ("severity", "akf", "event", "diagnostics",
        "orders"); a topic's kind is fixed by its first message. A
        ``"timestamp": {"sec", "nsec"}`` field is added from ``stamp_ns`` unless
        ``msg`` has one; ``msg`` itself is not modified. log_time =
        publish_time = ``stamp_ns``.
        """
        entry = self._channels.get(topic)
        if entry is None or entry[1] != schema:
            entry = self._register(topic, schema)
        if type(stamp_ns) is not int:
            stamp_ns = int(stamp_ns)
        if stamp_ns < 0:
            raise SinkError(f"{topic}: negative timestamp {stamp_ns} ns")
        try:
            body = _encode(msg)
        except (ValueError, TypeError, RecursionError):  # NaN/inf (allow_nan=False), bad type
            body = self._encode_slow(topic, msg)
        if "timestamp" not in msg:
            sec, nsec = divmod(stamp_ns, _NS)
            if len(body) > 2:
                body = f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},{body[1:]}'
            else:
                body = f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}}}}'
        self.messages_written += 1  # before: if its chunk cannot be written it is lost
        try:
            self._writer.add_message(entry[0], stamp_ns, body.encode())
        except OSError as err:  # a chunk got full and could not be written
            raise self._fail("write", err) from None
        if self._clock() - self._last_flush >= self._flush_s:
            self.flush()

    @staticmethod
    def _encode_slow(topic: str, msg: dict) -> str:
        try:
            return _encode(_sanitize(msg))
        except (ValueError, TypeError, RecursionError) as err:
            raise SinkError(f"{topic}: message cannot be encoded as JSON: {err}") from None

    def _register(self, topic: str, kind: str) -> tuple[int, str]:
        if self._failed:
            raise SinkIOError(
                f"{self.part_path}: write to a file abandoned after an error", op="write",
                err=None, path=self.part_path,
            )
        if self._closed:
            raise SinkError(f"{self.path}: write after close")
        if topic in self._channels:
            raise SinkError(
                f"{topic}: written with schema {kind!r}, but the topic has schema "
                f"{self._channels[topic][1]!r}"
            )
        if kind not in SCHEMAS:
            raise SinkError(f"{topic}: unknown schema {kind!r} (one of {', '.join(SCHEMAS)})")
        schema_id = self._schemas.get(kind)
        if schema_id is None:
            schema_id = self._writer.register_schema(
                name=schema_name(kind), encoding=SCHEMA_ENCODING, data=schema_bytes(kind)
            )
            self._schemas[kind] = schema_id
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding=MESSAGE_ENCODING, schema_id=schema_id
        )
        entry = self._channels[topic] = (channel_id, kind)
        return entry

    # -- durability --------------------------------------------------------

    @property
    def bytes_written(self) -> int:
        """Bytes in the file so far (flushed chunks; the open chunk is not counted)."""
        return self._writer.pos

    @property
    def persisted(self) -> int:
        """Messages in chunks written completely to the file (on a kill -9 they survive)."""
        return self._writer.persisted

    @property
    def unpersisted(self) -> int:
        """Messages accepted by write() but not (or not completely) in the file."""
        return self.messages_written - self._writer.persisted

    @property
    def unsynced(self) -> int:
        """Messages in the file but written after the last successful fsync: after a
        failed fsync they may not be on the disk (the kernel may have dropped them)."""
        return self._writer.persisted - self._synced

    @property
    def last_flush(self) -> float:
        """Clock time of the last flush (or of opening the file)."""
        return self._last_flush

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def failed(self) -> bool:
        """An operation on the file failed: nothing more is written to it."""
        return self._failed

    def fileno(self) -> int:
        """The file descriptor of the ``.part`` file (-1 once closed)."""
        return self._fh.fileno()

    def flush(self) -> None:
        """Finish the chunk in progress and write it (no fsync).

        Raises SinkIOError (and the file is failed) if the write fails.
        """
        self._last_flush = self._clock()
        if self._closed:
            return
        if self._failed:
            raise SinkIOError(f"{self.part_path}: write to a file abandoned after an error",
                              op="write", err=None, path=self.part_path)
        try:
            self._writer.finish_chunk()
        except OSError as err:
            raise self._fail("write", err) from None

    def sync(self) -> None:
        """flush() and fsync the file (call every ``fsync_s``).

        A failed fsync fails the file: it is never fsynced (or written) again.
        """
        self.flush()
        if self._closed:
            return
        try:
            os.fsync(self._fh.fileno())
        except OSError as err:
            raise self._fail("fsync", err) from None
        self._synced = self._writer.persisted

    def abandon(self) -> Path:
        """Close the descriptor without writing anything more; the ``.part`` file stays.

        Returns the ``.part`` path. For a failed file (or at any time: the
        flushed chunks are a valid prefix that :func:`salvage` recovers).
        """
        if not self._closed:
            self._closed = True
            self._failed = True
            self._channels = {}
            self.path = self.part_path
            try:
                self._fh.close()
            except OSError:
                pass  # the file is given up: nothing to report beyond the first error
        return self.part_path

    def close(self) -> Path:
        """Write summary and footer, fsync, rename .part -> .mcap, fsync the directory.

        Idempotent; returns the final path. If finishing fails (or the file
        failed earlier), the ``.part`` file is kept (its flushed chunks are
        readable and salvageable) and SinkIOError is raised.
        """
        if self._closed:
            return self.path
        if self._failed:
            self.abandon()
            raise SinkIOError(f"{self.part_path}: not finished: abandoned after an earlier error",
                              op="close", err=None, path=self.part_path)
        self._closed = True
        self._channels = {}  # any later write() goes through _register(), which refuses
        op = "close"
        try:
            self._writer.finish()
            op = "fsync"
            os.fsync(self._fh.fileno())
        except OSError as err:
            error = self._fail(op, err)
            self.path = self.part_path
            try:
                self._fh.close()
            except OSError:
                pass  # already failing; the first error is the one to report
            raise error from None
        try:
            os.replace(self.part_path, self.path)  # still open and locked: no salvage can interfere
        except OSError as err:
            self.path = self.part_path
            try:
                self._fh.close()
            except OSError:
                pass
            raise SinkIOError(f"{self.part_path}: cannot close: {_why(err)}", op="close",
                              err=err, path=self.part_path) from None
        try:
            self._fh.close()
        except OSError:
            pass  # everything is written and fsynced; close has nothing left to lose
        try:
            _fsync_dir(self.out_dir)
        except OSError as err:  # finished and renamed; only the rename may not be durable
            raise SinkIOError(f"{self.out_dir}: directory fsync failed after finishing "
                              f"{self.path.name}: {_why(err)}", op="fsync", err=err,
                              path=self.path) from None
        return self.path

    def __enter__(self) -> "McapSink":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


# ---------------------------------------------------------------------------
# Our files in a directory; salvage of a leftover .part file
# ---------------------------------------------------------------------------

_SALVAGED = ".salvaged"


def _log_name(prefix: str) -> re.Pattern[str]:
    """File names this sink writes with ``prefix``: finished, salvaged and .part."""
    return re.compile(
        rf"{re.escape(prefix)}-(\d{{8}}T\d{{6}}Z)(?:-(\d+))?(?:{re.escape(_SALVAGED)})?\.mcap(\.part)?"
    )


def log_files(out_dir: str | Path, prefix: str) -> tuple[list[Path], list[Path]]:
    """(finished ``*.mcap``, unfinished ``*.mcap.part``) files of ``prefix`` in ``out_dir``,
    each oldest first: by the UTC stamp of the name, then its number (``-2``
    before ``-10``). Only names this sink writes count: another prefix's
    files, or other files, are never listed. A missing directory has none.
    """
    pattern = _log_name(prefix)
    finished: list[tuple[str, int, str]] = []
    parts: list[tuple[str, int, str]] = []
    try:
        names = os.listdir(out_dir)
    except FileNotFoundError:
        return [], []
    for name in names:
        m = pattern.fullmatch(name)
        if m is not None:
            (parts if m.group(3) else finished).append((m.group(1), int(m.group(2) or 0), name))
    return ([Path(out_dir) / n for *_key, n in sorted(finished)],
            [Path(out_dir) / n for *_key, n in sorted(parts)])


def salvaged_path(part: str | Path) -> Path:
    """``<stem>.mcap.part`` -> ``<stem>.salvaged.mcap`` (the name of its salvaged file)."""
    part = Path(part)
    name = part.name
    stem = name[: -len(".mcap.part")] if name.endswith(".mcap.part") else name
    return part.with_name(stem + _SALVAGED + ".mcap")


@dataclass
class SalvageResult:
    """What :func:`salvage` did with one ``.part`` file.

    ``action``: ``"salvaged"`` (``path`` is the finished file; the ``.part`` is
    gone), ``"removed"`` (it ended before its first complete chunk: nothing to
    recover; deleted), ``"set_aside"`` (damaged before any complete chunk, or
    not MCAP at all: renamed to ``<name>.unreadable`` and kept for a human),
    ``"busy"`` (another writer holds it open: left alone).
    """

    source: Path
    action: str
    path: Path | None = None
    messages: int = 0
    chunks: int = 0
    source_bytes: int = 0
    dropped_bytes: int = 0  # after the last complete record: the unflushed tail
    damaged: bool = False  # a complete record failed its checks (CRC, parse)
    reason: str = ""  # what ended the scan, one line

    def message(self) -> str:
        """One line for the event."""
        name = self.source.name
        if self.action == "salvaged":
            text = (f"{name}: salvaged {self.messages} message(s) from {self.chunks} complete "
                    f"chunk(s) into {self.path.name if self.path else '?'}")
            if self.dropped_bytes:
                text += f"; {self.dropped_bytes} byte(s) after them dropped ({self.reason})"
            return text
        if self.action == "removed":
            return (f"{name}: nothing recoverable: no complete chunk in its {self.source_bytes} "
                    f"byte(s) (it ended within a flush period of being opened); removed")
        if self.action == "set_aside":
            return (f"{name}: nothing recoverable ({self.reason}); kept as "
                    f"{self.path.name if self.path else name}")
        return f"{name}: in use by another writer; left alone"


class _Damaged(Exception):
    """Internal: a complete record failed its checks (salvage stops there)."""


def _decompress(chunk: Chunk) -> bytes:
    if chunk.compression == "zstd":
        data = zstandard.ZstdDecompressor().decompress(
            chunk.data, max_output_size=chunk.uncompressed_size
        )
    elif chunk.compression == "lz4":
        if _lz4 is None:
            raise _Damaged("lz4 chunk, but the lz4 package is not installed")
        data = _lz4.decompress(chunk.data)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise _Damaged(f"unknown chunk compression {chunk.compression!r}")
    if len(data) != chunk.uncompressed_size:
        raise _Damaged(f"chunk holds {len(data)} bytes, its header says {chunk.uncompressed_size}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise _Damaged("chunk CRC mismatch")
    return bytes(data)


def _parse_one(raw: bytes) -> Any:
    return next(iter(StreamReader(io.BytesIO(raw), skip_magic=True, emit_chunks=True).records))


def _open_chunk(
    raw: bytes, channels: dict[int, Channel]
) -> tuple[Chunk, dict[int, list[tuple[int, int]]], int, list[Schema], list[Channel]]:
    """Check a complete chunk record and rebuild its message index.

    Returns (chunk as written to the salvaged file, index {channel: [(log
    time, offset)]}, messages, schemas, channels defined in it). Raises
    _Damaged for anything that is not exactly what the writer produces.
    """
    try:
        chunk = _parse_one(raw)
        if not isinstance(chunk, Chunk):
            raise _Damaged("a chunk opcode that does not parse as a chunk")
        data = _decompress(chunk)
    except _Damaged:
        raise
    except Exception as err:  # noqa: BLE001 - any failure of the parser or codec is damage
        raise _Damaged(f"{type(err).__name__}: {err}") from None
    index: dict[int, list[tuple[int, int]]] = {}
    schemas: list[Schema] = []
    new_channels: list[Channel] = []
    n = t0 = t1 = 0
    off, end = 0, len(data)
    while off < end:
        if off + 9 > end:
            raise _Damaged("a record header crosses the end of the chunk")
        opcode, length = struct.unpack_from("<BQ", data, off)
        stop = off + 9 + length
        if stop > end:
            raise _Damaged("a record crosses the end of the chunk")
        if opcode == _OP_MESSAGE:
            if length < _MESSAGE_FIXED:
                raise _Damaged("a message record too short for its fields")
            channel_id, _seq, log_time = struct.unpack_from("<HIQ", data, off + 9)
            if channel_id not in channels:
                raise _Damaged(f"a message on channel {channel_id}, which no record defines")
            index.setdefault(channel_id, []).append((log_time, off))
            if n:
                t0, t1 = min(t0, log_time), max(t1, log_time)
            else:
                t0 = t1 = log_time
            n += 1
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            try:
                record = _parse_one(data[off:stop])
            except Exception as err:  # noqa: BLE001 - corruption
                raise _Damaged(f"bad schema/channel record: {type(err).__name__}: {err}") from None
            if isinstance(record, Schema):
                schemas.append(record)
            elif isinstance(record, Channel):
                channels[record.id] = record
                new_channels.append(record)
        off = stop
    fresh = Chunk(  # times from the messages themselves: the header's are not CRC-protected
        compression=chunk.compression,
        data=chunk.data,
        message_start_time=t0,
        message_end_time=t1,
        uncompressed_crc=zlib.crc32(data),
        uncompressed_size=len(data),
    )
    return fresh, index, n, schemas, new_channels


def salvage(part: str | Path, *, durable: bool = True) -> SalvageResult:
    """Rewrite the complete chunks of a leftover ``.part`` file into a finished file.

    Reads ``part`` record by record (each length-checked before it is
    parsed); every complete chunk whose CRC and records check out is copied,
    compressed data unchanged, with its schemas and channels and a rebuilt
    message index, into ``<stem>.salvaged.mcap`` (written as
    ``<stem>.salvaged.mcap.tmp``, summary and footer added, fsynced, renamed,
    directory fsynced); then the ``.part`` is deleted. The scan ends at the
    first incomplete record (the unflushed tail), at a damaged one, or at the
    end of the data section of a file that was finished but not renamed.
    Metadata records are kept. See :class:`SalvageResult` for what happens
    when nothing is recoverable.

    Never raises on the file's content. Raises SinkIOError when it cannot be
    read or the salvaged file cannot be written (the ``.part`` is then left as
    it was, and a partial ``.tmp`` removed). ``durable=False`` skips the
    fsyncs (tests that salvage thousands of files).
    """
    part = Path(part)
    result = SalvageResult(source=part, action="removed")
    try:
        f = open(part, "rb")
    except OSError as err:
        raise SinkIOError(f"{part}: cannot read: {_why(err)}", op="read", err=err, path=part) from None
    tmp = salvaged_path(part).with_suffix(".mcap.tmp")
    out: _RawFile | None = None
    try:
        with f:
            try:
                fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                result.action = "busy"
                return result
            except OSError:
                pass  # no flock here: only salvage at start, when nothing writes
            result.source_bytes = os.fstat(f.fileno()).st_size
            writer: _ChunkWriter | None = None
            metadata: list[Metadata] = []
            channels: dict[int, Channel] = {}
            valid = 0
            magic = f.read(len(_MAGIC))
            if magic != _MAGIC:
                if not _MAGIC.startswith(magic):
                    result.damaged = True
                    result.reason = NOT_MCAP
                else:
                    result.reason = "ends inside the magic"
            else:
                valid = len(_MAGIC)
                result.reason = "ends inside a record"
                while True:
                    head = f.read(9)
                    if len(head) < 9:
                        if not head:
                            result.reason = "ends after a complete record"
                        break
                    opcode, length = struct.unpack("<BQ", head)
                    if length > _RECORD_LIMIT:
                        result.damaged = True
                        result.reason = f"record at byte {valid} claims {length} bytes"
                        break
                    body = f.read(length)
                    if len(body) < length:
                        break
                    if opcode == Opcode.CHUNK:
                        try:
                            chunk, index, n, schemas, new_channels = _open_chunk(head + body, channels)
                        except _Damaged as err:
                            result.damaged = True
                            result.reason = f"damaged chunk at byte {valid}: {err}"
                            break
                        if writer is None:
                            out = _RawFile(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC
                                                   | getattr(os, "O_CLOEXEC", 0), 0o644))
                            writer = _ChunkWriter(out, "", 1)
                            writer.start(library=f"cmsensord/{__version__}")
                            for record in metadata:
                                writer.add_metadata(record.name, dict(record.metadata))
                        writer.add_chunk(chunk, index, n, schemas, new_channels)
                        result.messages += n
                        result.chunks += 1
                    elif opcode == Opcode.METADATA:
                        try:
                            record = _parse_one(head + body)
                        except Exception as err:  # noqa: BLE001 - corruption
                            result.damaged = True
                            result.reason = f"bad metadata record at byte {valid}: {err}"
                            break
                        if writer is None:
                            metadata.append(record)
                        else:
                            writer.add_metadata(record.name, dict(record.metadata))
                    elif opcode in (Opcode.DATA_END, Opcode.FOOTER):
                        valid = result.source_bytes  # a finished file: the summary is rebuilt
                        result.reason = "a finished file"
                        break
                    # header, message indexes (rebuilt), anything else: skipped
                    valid += 9 + length
            result.dropped_bytes = max(0, result.source_bytes - valid)
            if writer is None:
                if result.damaged:
                    aside = part.with_name(part.name + ".unreadable")
                    os.replace(part, aside)
                    result.action, result.path = "set_aside", aside
                else:
                    part.unlink()
                    result.action = "removed"
                if durable:
                    _fsync_dir(part.parent)
                return result
            writer.add_metadata("cmsensord.salvage", {
                "source": part.name,
                "messages": str(result.messages),
                "source_bytes": str(result.source_bytes),
                "dropped_bytes": str(result.dropped_bytes),
            })
            writer.finish()
            if durable:
                os.fsync(out.fileno())
            out.close()
            final = salvaged_path(part)
            os.replace(tmp, final)
            if durable:
                _fsync_dir(part.parent)
            part.unlink()
            if durable:
                _fsync_dir(part.parent)
            result.action, result.path = "salvaged", final
            return result
    except OSError as err:
        if out is not None:
            try:
                out.close()
            except OSError:
                pass
            try:
                tmp.unlink(missing_ok=True)
            except OSError:
                pass
        raise SinkIOError(f"{part}: cannot salvage: {_why(err)}", op="write", err=err, path=part) from None


def salvage_leftovers(out_dir: str | Path, prefix: str, *, durable: bool = True
                      ) -> list[SalvageResult | SinkIOError]:
    """:func:`salvage` every ``<prefix>-*.mcap.part`` in ``out_dir`` (oldest first).

    One entry per file: its SalvageResult, or the SinkIOError that stopped it
    (the file is then left as it was). Files held open by a writer are
    skipped (``action == "busy"``). Never raises.
    """
    results: list[SalvageResult | SinkIOError] = []
    try:
        _finished, parts = log_files(out_dir, prefix)
    except OSError:
        return results  # an unreadable directory: opening the next file reports it
    for part in parts:
        try:
            results.append(salvage(part, durable=durable))
        except SinkIOError as err:
            results.append(err)
    return results


# ---------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------


def read_messages(path: str | Path, *, lenient: bool = False) -> list[tuple[str, int, dict]]:
    """All messages of a file as (topic, log_time_ns, decoded JSON), in file order.

    Uses mcap's reader (``make_reader``) on a finished file; ``lenient=True``
    reads a truncated ``.part`` file up to its first incomplete record.
    """
    if lenient:
        return [(topic, t, json.loads(data)) for topic, t, data in iter_messages_lenient(path)]
    with open(path, "rb") as f:
        reader = make_reader(f)
        return [
            (channel.topic, message.log_time, json.loads(message.data))
            for _schema, channel, message in reader.iter_messages(log_time_order=False)
        ]


class _Scan:
    """State of a lenient sequential read of an MCAP file."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.complete = False  # footer and closing magic seen
        self.truncated = False  # the file ends inside a record
        self.error: str | None = None  # a complete record that could not be parsed
        self.valid_bytes = 0  # end of the last good record
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.metadata: dict[str, dict[str, str]] = {}

    def records(self) -> Iterator[Any]:
        """Yield records (chunks broken up) up to the first incomplete or bad one.

        Each top-level record is length-checked before mcap's StreamReader
        parses it, so a partial record is never parsed and nothing is raised.
        """
        try:
            f = open(self.path, "rb")
        except OSError as err:
            raise SinkError(f"{self.path}: cannot read: {err.strerror or err}") from None
        with f:
            magic = f.read(len(_MAGIC))
            if magic != _MAGIC:
                if _MAGIC.startswith(magic):
                    self.truncated = True
                else:
                    self.error = NOT_MCAP
                return
            pos = len(_MAGIC)
            self.valid_bytes = pos
            while True:
                head = f.read(9)
                if len(head) < 9:
                    self.truncated = True
                    return
                opcode, length = struct.unpack("<BQ", head)
                if length > _RECORD_LIMIT:
                    self.error = f"record at byte {pos} claims {length} bytes"
                    return
                body = f.read(length)
                if len(body) < length:
                    self.truncated = True
                    return
                if opcode in _KNOWN_OPCODES:
                    try:
                        parsed = self._parse(head + body)
                    except Exception as err:  # noqa: BLE001 - any corruption ends the scan
                        self.error = f"bad record at byte {pos}: {type(err).__name__}: {err}"
                        return
                else:
                    parsed = []  # unknown record kinds are skipped (MCAP spec)
                pos += 9 + length
                self.valid_bytes = pos
                for record in parsed:
                    if isinstance(record, Schema):
                        self.schemas[record.id] = record
                    elif isinstance(record, Channel):
                        self.channels[record.id] = record
                    elif isinstance(record, Metadata):
                        self.metadata[record.name] = dict(record.metadata)
                    yield record
                if opcode == Opcode.FOOTER:
                    self.complete = f.read(len(_MAGIC)) == _MAGIC
                    self.truncated = not self.complete
                    if self.complete:
                        self.valid_bytes += len(_MAGIC)
                    return

    @staticmethod
    def _parse(raw: bytes) -> list[Any]:
        reader = StreamReader(io.BytesIO(raw), skip_magic=True, emit_chunks=True)
        record = next(iter(reader.records))
        if isinstance(record, Chunk):
            return breakup_chunk(record, validate_crc=True)
        return [record]


def iter_messages_lenient(path: str | Path) -> Iterator[tuple[str, int, bytes]]:
    """(topic, log_time_ns, raw data) of every readable message, never raising on damage."""
    scan = _Scan(path)
    for record in scan.records():
        if isinstance(record, Message):
            channel = scan.channels.get(record.channel_id)
            topic = channel.topic if channel is not None else f"<channel {record.channel_id}>"
            yield topic, record.log_time, record.data


def summarize(path: str | Path, *, max_events: int = 1000) -> dict[str, Any]:
    """Summary of an MCAP file, also of a truncated ``.part`` file.

    Reads sequentially and stops at the first incomplete or damaged record
    without raising. Returns a dict: path, complete, truncated, error,
    file_bytes, valid_bytes, messages, topics {topic: count}, schemas
    {topic: schema name}, start_ns, end_ns, duration_s, event_counts
    {kind: count}, events [first max_events as {time_ns, kind, channel,
    message}], events_omitted, metadata.
    """
    scan = _Scan(path)
    topics: dict[str, int] = {}
    counts_by_id: dict[int, int] = {}
    start_ns: int | None = None
    end_ns: int | None = None
    event_counts: dict[str, int] = {}
    events: list[dict[str, Any]] = []
    omitted = 0
    n = 0
    for record in scan.records():
        if not isinstance(record, Message):
            continue
        n += 1
        t = record.log_time
        start_ns = t if start_ns is None or t < start_ns else start_ns
        end_ns = t if end_ns is None or t > end_ns else end_ns
        cid = record.channel_id
        counts_by_id[cid] = counts_by_id.get(cid, 0) + 1
        channel = scan.channels.get(cid)
        if channel is not None and channel.topic == TOPIC_EVENTS:
            try:
                event = json.loads(record.data)
                kind = str(event.get("kind"))
            except (ValueError, AttributeError):
                event, kind = {}, "<undecodable>"
            event_counts[kind] = event_counts.get(kind, 0) + 1
            if len(events) < max_events:
                events.append(
                    {
                        "time_ns": t,
                        "kind": kind,
                        "channel": event.get("channel"),
                        "message": event.get("message"),
                    }
                )
            else:
                omitted += 1
    schemas: dict[str, str] = {}
    for cid, count in counts_by_id.items():
        channel = scan.channels.get(cid)
        topic = channel.topic if channel is not None else f"<channel {cid}>"
        topics[topic] = topics.get(topic, 0) + count
        if channel is not None and channel.schema_id in scan.schemas:
            schemas[topic] = scan.schemas[channel.schema_id].name
    try:
        file_bytes = scan.path.stat().st_size
    except OSError:
        file_bytes = scan.valid_bytes
    return {
        "path": str(scan.path),
        "complete": scan.complete,
        "truncated": scan.truncated,
        "error": scan.error,
        "file_bytes": file_bytes,
        "valid_bytes": scan.valid_bytes,
        "messages": n,
        "topics": dict(sorted(topics.items())),
        "schemas": dict(sorted(schemas.items())),
        "start_ns": start_ns,
        "end_ns": end_ns,
        "duration_s": (end_ns - start_ns) / _NS if n else 0.0,
        "event_counts": dict(sorted(event_counts.items())),
        "events": events,
        "events_omitted": omitted,
        "metadata": scan.metadata,
    }
