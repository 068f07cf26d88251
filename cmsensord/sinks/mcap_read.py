"""Reading MCAP files, finished or not: the record walker, messages and summaries.

:class:`RecordWalker` is the one sequential reader of top-level records: it
checks each record's length before anything parses it, so a file that ends
inside a record (a ``.part`` file of a crashed process) or claims an absurd
length (corruption) ends the walk without an exception. Salvage
(:mod:`cmsensord.sinks.mcap_salvage`) and the lenient readers here
(:func:`summarize`, :func:`iter_messages_lenient`, ``read_messages(...,
lenient=True)``) both walk files with it. A finished file is read with
mcap's own reader (:func:`read_messages`).
"""

from __future__ import annotations

import io
import json
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from cmsensord.errors import SinkError
from cmsensord.sinks.mcap_chunks import MAGIC
from cmsensord.sinks.mcap_encoding import NS
from cmsensord.sinks.schemas import TOPIC_EVENTS

__all__ = [
    "NOT_MCAP",
    "RecordWalker",
    "parse_record",
    "read_messages",
    "iter_messages_lenient",
    "iter_messages_at",
    "summarize",
]

#: summarize()'s ``error`` for a file that does not start with the MCAP magic
NOT_MCAP = "not an MCAP file (bad magic)"
# A record longer than this in a file we wrote means corruption, not data
# (chunks are ~1 MiB); reading it would only waste memory.
RECORD_LIMIT = 256 * 1024 * 1024
_HEAD = struct.Struct("<BQ")  # opcode, record length
_KNOWN_OPCODES = frozenset(int(op) for op in Opcode)


class RecordWalker:
    """The top-level records of an MCAP file open in ``f``, read sequentially.

    :meth:`records` reads the magic, then yields ``(offset, opcode, raw)`` for
    every complete record (``raw``: opcode, length and body, as in the file).
    It stops, never raising on the content, when the file ends or a record
    claims more than ``RECORD_LIMIT`` bytes, and then sets :attr:`end`:

    * ``NOT_MCAP``: the file does not start with the magic;
    * ``IN_MAGIC``: the file ends inside the magic (or is empty);
    * ``AT_END``: the file ends just after a complete record;
    * ``IN_RECORD``: the file ends inside a record;
    * ``TOO_LONG``: a record claims too many bytes (:attr:`error` says which).

    :attr:`end` stays None when the caller stops first. :attr:`valid_bytes` is
    the offset after the magic and the last complete record read (0 without
    the magic).
    """

    NOT_MCAP = "not_mcap"
    IN_MAGIC = "in_magic"
    AT_END = "at_end"
    IN_RECORD = "in_record"
    TOO_LONG = "too_long"

    def __init__(self, f: BinaryIO) -> None:
        self._f = f
        self.end: str | None = None
        self.error: str | None = None
        self.valid_bytes = 0

    def records(self, start: int | None = None) -> Iterator[tuple[int, int, bytes]]:
        """(offset, opcode, raw record) of each complete record, in file order.

        ``start``: the offset of a record to resume at (after damage); the
        magic is then not read again.
        """
        f = self._f
        if start is None:
            magic = f.read(len(MAGIC))
            if magic != MAGIC:
                self.end = self.IN_MAGIC if MAGIC.startswith(magic) else self.NOT_MCAP
                return
            start = len(MAGIC)
        else:
            f.seek(start)
        self.end = self.error = None
        pos = self.valid_bytes = start
        while True:
            head = f.read(_HEAD.size)
            if len(head) < _HEAD.size:
                self.end = self.IN_RECORD if head else self.AT_END
                return
            opcode, length = _HEAD.unpack(head)
            if length > RECORD_LIMIT:
                self.end = self.TOO_LONG
                self.error = f"record at byte {pos} claims {length} bytes"
                return
            body = f.read(length)
            if len(body) < length:
                self.end = self.IN_RECORD
                return
            self.valid_bytes = pos + _HEAD.size + length
            yield pos, opcode, head + body
            pos = self.valid_bytes

    def closing_magic(self) -> bool:
        """After the Footer record has been yielded: whether the closing magic follows."""
        return self._f.read(len(MAGIC)) == MAGIC


def parse_record(raw: bytes) -> Any:
    """One complete record (from :meth:`RecordWalker.records`) as an mcap record object.

    A chunk stays a Chunk. Raises whatever mcap's parser raises on bad content.
    """
    return next(iter(StreamReader(io.BytesIO(raw), skip_magic=True, emit_chunks=True).records))


def read_messages(path: str | Path, *, lenient: bool = False) -> list[tuple[str, int, dict]]:
    """All messages of a file as (topic, stamp_ns, decoded JSON), in file order.

    The stamp is the message's publish time: the stamp it was written with, also for
    a message the sink wrote with a clamped log time (:mod:`cmsensord.sinks.reorder`).

    Uses mcap's reader (``make_reader``) on a finished file; ``lenient=True``
    reads a truncated ``.part`` file up to its first incomplete record.
    """
    if lenient:
        return [(topic, t, json.loads(data)) for topic, t, data in iter_messages_lenient(path)]
    with open(path, "rb") as f:
        reader = make_reader(f)
        return [
            (channel.topic, message.publish_time, json.loads(message.data))
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

        Walks the file with :class:`RecordWalker`, so a partial record is
        never parsed and nothing is raised on the content; records of
        unknown kinds are skipped (MCAP spec). Raises SinkError when the file
        cannot be opened.
        """
        try:
            f = open(self.path, "rb")
        except OSError as err:
            raise SinkError(f"{self.path}: cannot read: {err.strerror or err}") from None
        with f:
            walker = RecordWalker(f)
            for pos, opcode, raw in walker.records():
                if opcode in _KNOWN_OPCODES:
                    try:
                        parsed = self._parse(raw)
                    except Exception as err:  # noqa: BLE001 - any corruption ends the scan
                        self.error = f"bad record at byte {pos}: {type(err).__name__}: {err}"
                        self.valid_bytes = pos
                        return
                else:
                    parsed = []
                self.valid_bytes = pos + len(raw)
                for record in parsed:
                    self._remember(record)
                    yield record
                if opcode == Opcode.FOOTER:
                    self.complete = walker.closing_magic()
                    self.truncated = not self.complete
                    if self.complete:
                        self.valid_bytes += len(MAGIC)
                    return
            self.valid_bytes = walker.valid_bytes
            if walker.end == RecordWalker.NOT_MCAP:
                self.error = NOT_MCAP
            elif walker.end == RecordWalker.TOO_LONG:
                self.error = walker.error
            else:
                self.truncated = True

    def _remember(self, record: Any) -> None:
        if isinstance(record, Schema):
            self.schemas[record.id] = record
        elif isinstance(record, Channel):
            self.channels[record.id] = record
        elif isinstance(record, Metadata):
            self.metadata[record.name] = dict(record.metadata)

    @staticmethod
    def _parse(raw: bytes) -> list[Any]:
        record = parse_record(raw)
        if isinstance(record, Chunk):
            return breakup_chunk(record, validate_crc=True)
        return [record]

    def topic(self, channel_id: int) -> str:
        """The topic of a channel seen so far, or ``<channel N>``."""
        channel = self.channels.get(channel_id)
        return channel.topic if channel is not None else f"<channel {channel_id}>"


def iter_messages_lenient(path: str | Path) -> Iterator[tuple[str, int, bytes]]:
    """(topic, stamp_ns, raw data) of every readable message (the stamp: its publish time, as in
    :func:`read_messages`), never raising on damage."""
    scan = _Scan(path)
    for record in scan.records():
        if isinstance(record, Message):
            yield scan.topic(record.channel_id), record.publish_time, record.data


def iter_messages_at(path: str | Path) -> Iterator[tuple[str, int, bytes, int]]:
    """As :func:`iter_messages_lenient`, with the byte offset read so far (for a progress bar)."""
    scan = _Scan(path)
    for record in scan.records():
        if isinstance(record, Message):
            yield scan.topic(record.channel_id), record.log_time, record.data, scan.valid_bytes


class _Events:
    """Counts of ``/cm/events`` messages by kind, and the first ``max_events`` of them."""

    def __init__(self, max_events: int) -> None:
        self.max_events = max_events
        self.counts: dict[str, int] = {}
        self.events: list[dict[str, Any]] = []
        self.omitted = 0

    def add(self, time_ns: int, data: bytes) -> None:
        try:
            event = json.loads(data)
            kind = str(event.get("kind"))
        except (ValueError, AttributeError):
            event, kind = {}, "<undecodable>"
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if len(self.events) < self.max_events:
            self.events.append(
                {
                    "time_ns": time_ns,
                    "kind": kind,
                    "channel": event.get("channel"),
                    "message": event.get("message"),
                }
            )
        else:
            self.omitted += 1


def _topics_and_schemas(
    scan: _Scan, counts_by_id: dict[int, int]
) -> tuple[dict[str, int], dict[str, str]]:
    """({topic: messages}, {topic: schema name}) from the message counts per channel id."""
    topics: dict[str, int] = {}
    schemas: dict[str, str] = {}
    for cid, count in counts_by_id.items():
        channel = scan.channels.get(cid)
        topic = scan.topic(cid)
        topics[topic] = topics.get(topic, 0) + count
        if channel is not None and channel.schema_id in scan.schemas:
            schemas[topic] = scan.schemas[channel.schema_id].name
    return dict(sorted(topics.items())), dict(sorted(schemas.items()))


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
    counts_by_id: dict[int, int] = {}
    start_ns: int | None = None
    end_ns: int | None = None
    events = _Events(max_events)
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
            events.add(t, record.data)
    topics, schemas = _topics_and_schemas(scan, counts_by_id)
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
        "topics": topics,
        "schemas": schemas,
        "start_ns": start_ns,
        "end_ns": end_ns,
        "duration_s": (end_ns - start_ns) / NS if start_ns is not None and end_ns is not None else 0.0,
        "event_counts": dict(sorted(events.counts.items())),
        "events": events.events,
        "events_omitted": events.omitted,
        "metadata": scan.metadata,
    }
