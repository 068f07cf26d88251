"""Reading MCAP files, finished or not: messages and summaries.

A finished file is read with mcap's own reader (:func:`read_messages`). The lenient readers
(:func:`summarize`, :func:`iter_messages_lenient`, :func:`iter_messages_at`,
``read_messages(..., lenient=True)``) walk the file's records with
:class:`~cmsensord.sinks.mcap_records.RecordWalker`, so a partial record is never parsed and
nothing is raised on the content, and read past damage from the next chunk that checks out
(:class:`~cmsensord.sinks.mcap_chunk_check.Resync`, as salvage and the report do).

Every reader here gives a message's time as its publish time: the stamp it was made with (its
``timestamp`` field), also for a message the sink wrote with a clamped log time
(:mod:`cmsensord.sinks.reorder`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Generator, Iterator
from pathlib import Path
from typing import Any, BinaryIO

from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from cmsensord.errors import SinkError
from cmsensord.sinks.mcap_chunk_check import Resync
from cmsensord.sinks.mcap_chunks import MAGIC
from cmsensord.sinks.mcap_cut import CUT_HEAD, cut_text, is_unfinished_name, short_text
from cmsensord.sinks.mcap_encoding import NS
from cmsensord.sinks.mcap_records import KNOWN_OPCODES, NOT_MCAP, RecordWalker, parse_record
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
        self.error: str | None = None  # the damage that ended the read
        self.skipped: list[str] = []  # the damage read past, one line each
        self.valid_bytes = 0  # end of the last good record
        self.cut: str | None = None  # what the file's ending before its footer lost
        self._cut_at: int | None = None  # where it ends inside a record, or after one (no footer)
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.metadata: dict[str, dict[str, str]] = {}

    def records(self) -> Iterator[Any]:
        """Yield the records (chunks broken up) of every intact stretch of the file.

        Records of unknown kinds are skipped (MCAP spec). Damage (a record that does not
        parse, or claims more bytes than the limit or the file holds) is read past from the
        next chunk that checks out, each stretch skipped said in :attr:`skipped`; with no
        good chunk after it, the damage ends the read (:attr:`error`, or :attr:`truncated`
        when the file ends inside a record). A file ending before its footer says what that lost
        in :attr:`cut` (:mod:`~cmsensord.sinks.mcap_cut`), also as :attr:`error` unless it is a
        ``.part`` (one being written). Raises SinkError when the file cannot be opened.
        """
        try:
            f = open(self.path, "rb")
        except OSError as err:
            raise SinkError(f"{self.path}: cannot read: {err.strerror or err}") from None
        with f:
            resync = Resync(f, os.fstat(f.fileno()).st_size, None)
            try:
                start = None
                while (damage := (yield from self._stretch(f, start))) is not None:
                    start = resync.next_chunk(damage + 1, self.channels)
                    if start is None:
                        break
                    self.skipped.append(self.error or f"a record at byte {damage} claims more bytes "
                                                      "than the file holds")
                    self.error, self.truncated = None, False
                self._say_cut(f)
            finally:
                resync.close()

    def _say_cut(self, f: BinaryIO) -> None:
        """:attr:`cut` (and :attr:`error`) for a file that ended inside a record or without a footer."""
        if not self.truncated or self._cut_at is None:
            return
        size = os.fstat(f.fileno()).st_size
        f.seek(self._cut_at)
        self.cut = cut_text(f.read(CUT_HEAD), self._cut_at, size)
        if self.error is None and not is_unfinished_name(self.path.name):
            self.error = self.cut

    def _stretch(self, f: BinaryIO, start: int | None) -> Generator[Any, None, int | None]:
        """The records from ``start`` (None: the file's start) up to the end or to damage;
        returns the offset of the damage (None: the read ends here)."""
        walker = RecordWalker(f)
        for pos, opcode, raw in walker.records(start):
            if opcode in KNOWN_OPCODES:
                try:
                    parsed = self._parse(raw)
                except Exception as err:  # noqa: BLE001 - any corruption is damage
                    self.error = f"bad record at byte {pos}: {type(err).__name__}: {err}"
                    return pos
            else:
                parsed = []
            self.valid_bytes = pos + len(raw)
            for record in parsed:
                self._remember(record)
                yield record
            if opcode == Opcode.FOOTER:
                self._cut_at = None
                self.complete = walker.closing_magic()
                self.truncated = not self.complete
                if self.complete:
                    self.valid_bytes += len(MAGIC)
                return None
        self.valid_bytes = walker.valid_bytes
        if walker.end == RecordWalker.NOT_MCAP:
            self.error = NOT_MCAP
            return None
        if walker.end == RecordWalker.TOO_LONG:
            self.error = walker.error
            return walker.valid_bytes
        self.truncated = True
        if walker.end == RecordWalker.IN_MAGIC:          # empty, or too short for any record
            f.seek(0)
            self.cut = short_text(f.read(len(MAGIC)))
            if not is_unfinished_name(self.path.name):
                self.error = self.cut
        if walker.end in (RecordWalker.IN_RECORD, RecordWalker.AT_END):
            self._cut_at = walker.valid_bytes
        return walker.valid_bytes if walker.end == RecordWalker.IN_RECORD else None

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
            yield scan.topic(record.channel_id), record.publish_time, record.data, scan.valid_bytes


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

    Reads sequentially without raising, past damage from the next chunk that checks out.
    Returns a dict: path, complete, truncated, error (the damage that ended the read, also a
    finished file cut short), cut (what ending before the footer lost, a ``.part`` file's too),
    skipped (the damage read past, a line each), file_bytes, valid_bytes, messages, topics {topic: count}, schemas
    {topic: schema name}, start_ns, end_ns, duration_s (of the messages' publish times), event_counts
    {kind: count}, events [the first max_events in the file, as {time_ns (publish time), kind,
    channel, message}, in time order], events_omitted, metadata.
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
        t = record.publish_time
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
        "cut": scan.cut,
        "skipped": scan.skipped,
        "file_bytes": file_bytes,
        "valid_bytes": scan.valid_bytes,
        "messages": n,
        "topics": topics,
        "schemas": schemas,
        "start_ns": start_ns,
        "end_ns": end_ns,
        "duration_s": (end_ns - start_ns) / NS if start_ns is not None and end_ns is not None else 0.0,
        "event_counts": dict(sorted(events.counts.items())),
        "events": sorted(events.events, key=lambda e: e["time_ns"]),
        "events_omitted": events.omitted,
        "metadata": scan.metadata,
    }
