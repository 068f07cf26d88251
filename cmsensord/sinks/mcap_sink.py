"""MCAP sink: JSON messages with jsonschema schemas into one crash-safe MCAP file.

Owns the file format side of the output contract (schemas in
:mod:`cmsensord.sinks.schemas`):

* one file ``<prefix>-<UTC yyyymmddTHHMMSSZ>.mcap``, written as ``*.mcap.part``
  and renamed by :meth:`McapSink.close` once the summary and footer are on
  disk (then the directory is fsynced). A ``.part`` file left by a crash holds
  every chunk flushed before it; :func:`summarize` reads it up to the first
  incomplete record.
* chunks are finished and written every ``flush_s`` seconds (by the injected
  clock), so at most ``flush_s`` of data is lost on a crash;
* schemas and channels are registered lazily, on the first message of a topic;
* JSON never carries NaN or infinity: they become ``null``. The fast path
  encodes with ``allow_nan=False``; only a message that fails it is
  sanitised and encoded again, so clean messages cost nothing extra;
* the MCAP records come from mcap's record classes, but messages are packed
  into the open chunk directly (:class:`_ChunkWriter`), which costs ~1 us
  instead of ~6 us per message through ``mcap.writer.Writer``.

Rotation (``rotate_s``/``rotate_mb``) and periodic fsync (``fsync_s``) are the
caller's policy; :attr:`McapSink.bytes_written`, :attr:`McapSink.opened_at`
and :meth:`McapSink.sync` give it what it needs.
"""

from __future__ import annotations

import io
import json
import math
import os
import struct
import time
from pathlib import Path
from typing import Any, Callable, Iterator

import zlib

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

__all__ = ["McapSink", "ns_to_stamp", "read_messages", "summarize", "iter_messages_lenient"]

_NS = 1_000_000_000
_MAGIC = b"\x89MCAP0\r\n"
_COMPRESSION = {"zstd": "zstd", "lz4": "lz4", "none": ""}  # option -> Chunk.compression
# A record longer than this in a file we wrote means corruption, not data
# (chunks are ~1 MiB); reading it would only waste memory.
_RECORD_LIMIT = 256 * 1024 * 1024
_KNOWN_OPCODES = frozenset(int(op) for op in Opcode)


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

    def __init__(self, fh: io.BufferedWriter, compression: str, chunk_size: int) -> None:
        if compression == "lz4" and _lz4 is None:
            raise SinkError("lz4 compression needs the lz4 package (pip install lz4)")
        self._fh = fh
        self._compression = compression
        self._chunk_size = chunk_size
        self.pos = 0  # bytes written to fh
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
        chunk_raw = _records(
            Chunk(
                compression=self._compression,
                data=data,
                message_start_time=self._t0,
                message_end_time=self._t1,
                uncompressed_crc=zlib.crc32(raw),
                uncompressed_size=len(raw),
            )
        )
        chunk_start = self.pos
        index_start = chunk_start + len(chunk_raw)
        builder = RecordBuilder()
        offsets: dict[int, int] = {}
        for channel_id, records in self._index.items():
            offsets[channel_id] = index_start + builder.count
            MessageIndex(channel_id=channel_id, records=records).write(builder)
            self._channel_counts[channel_id] = self._channel_counts.get(channel_id, 0) + len(records)
        index_raw = builder.end()
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=self._t0,
                message_end_time=self._t1,
                chunk_start_offset=chunk_start,
                chunk_length=len(chunk_raw),
                message_index_offsets=offsets,
                message_index_length=len(index_raw),
                compression=self._compression,
                compressed_size=len(data),
                uncompressed_size=len(raw),
            )
        )
        if self._message_count:
            self._start_time = min(self._start_time, self._t0)
            self._end_time = max(self._end_time, self._t1)
        else:
            self._start_time, self._end_time = self._t0, self._t1
        self._message_count += self._n
        self._new_chunk()  # before writing: a failing disk must not make the chunk grow
        self._out(chunk_raw + index_raw)

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
        SinkError: the directory cannot be created or written (one-line message
            naming it), or an argument is invalid.
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
        self._closed = False

        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise SinkError(
                f"{self.out_dir}: cannot create output directory: {err.strerror or err}"
            ) from None
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(wall_clock()))
        self._fh = self._open_unique(prefix, stamp)

        try:
            self._writer = _ChunkWriter(self._fh, _COMPRESSION[compression], chunk_size)
            self._writer.start(library=f"cmsensord/{__version__}")
            if metadata:
                self._writer.add_metadata("cmsensord", {str(k): str(v) for k, v in metadata.items()})
            self._fh.flush()
        except (OSError, SinkError) as err:
            self._fh.close()
            self.part_path.unlink(missing_ok=True)
            if isinstance(err, SinkError):
                raise
            raise SinkError(f"{self.part_path}: cannot write: {err.strerror or err}") from None
        self.opened_at = clock()
        self._last_flush = self.opened_at

    def _open_unique(self, prefix: str, stamp: str) -> io.BufferedWriter:
        for k in range(1000):
            base = f"{prefix}-{stamp}" + (f"-{k}" if k else "")
            final = self.out_dir / f"{base}.mcap"
            part = self.out_dir / f"{base}.mcap.part"
            if final.exists():
                continue
            try:
                fh = open(part, "xb")  # exclusive: never clobber another writer's file
            except FileExistsError:
                continue
            except OSError as err:
                raise SinkError(
                    f"{self.out_dir}: cannot write in output directory: {err.strerror or err}"
                ) from None
            self.path = final
            self.part_path = part
            return fh
        raise SinkError(f"{self.out_dir}: no free file name for {prefix}-{stamp}.mcap")

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
        try:
            self._writer.add_message(entry[0], stamp_ns, body.encode())
        except OSError as err:  # a chunk got full and could not be written
            raise SinkError(f"{self.part_path}: write failed: {err.strerror or err}") from None
        self.messages_written += 1
        if self._clock() - self._last_flush >= self._flush_s:
            self.flush()

    @staticmethod
    def _encode_slow(topic: str, msg: dict) -> str:
        try:
            return _encode(_sanitize(msg))
        except (ValueError, TypeError, RecursionError) as err:
            raise SinkError(f"{topic}: message cannot be encoded as JSON: {err}") from None

    def _register(self, topic: str, kind: str) -> tuple[int, str]:
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
    def closed(self) -> bool:
        return self._closed

    def flush(self) -> None:
        """Finish the chunk in progress and write it (no fsync)."""
        self._last_flush = self._clock()
        if self._closed:
            return
        try:
            self._writer.finish_chunk()
            self._fh.flush()
        except OSError as err:
            raise SinkError(f"{self.part_path}: write failed: {err.strerror or err}") from None

    def sync(self) -> None:
        """flush() and fsync the file (call every ``fsync_s``)."""
        self.flush()
        if self._closed:
            return
        try:
            os.fsync(self._fh.fileno())
        except OSError as err:
            raise SinkError(f"{self.part_path}: fsync failed: {err.strerror or err}") from None

    def close(self) -> Path:
        """Write summary and footer, fsync, rename .part -> .mcap, fsync the directory.

        Idempotent; returns the final path. If finishing fails, the ``.part``
        file is kept (its flushed chunks are readable) and SinkError is raised.
        """
        if self._closed:
            return self.path
        self._closed = True
        self._channels = {}  # any later write() goes through _register(), which refuses
        try:
            self._writer.finish()
            self._fh.flush()
            os.fsync(self._fh.fileno())
        except OSError as err:
            self.path = self.part_path
            try:
                self._fh.close()
            except OSError:
                pass  # already failing; the first error is the one to report
            raise SinkError(
                f"{self.part_path}: cannot finish MCAP file: {err.strerror or err}"
            ) from None
        try:
            self._fh.close()
            os.replace(self.part_path, self.path)
            _fsync_dir(self.out_dir)
        except OSError as err:
            raise SinkError(f"{self.part_path}: cannot close: {err.strerror or err}") from None
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
                    self.error = "not an MCAP file (bad magic)"
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
