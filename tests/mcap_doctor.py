"""A walk over an MCAP file doing the checks of ``mcap doctor --strict-message-order``.

The Go tool (foxglove/mcap, ``go/cli/mcap/cmd/doctor.go``) reads the file record by
record; per chunk it decompresses the records, checks the CRC and the size, and for
every message that its log time is not less than the latest log time seen in the file
so far (an error with ``--strict-message-order``), that the chunk's message_start_time
and message_end_time are the earliest and latest log times of its messages, and that
the message index after the chunk has an entry at the message's offset with its log
time.  This module does the same in Python with mcap's own record parser, plus the
summary's statistics and chunk indexes, and returns the list of problems.
"""

from __future__ import annotations

import io
import zlib
from pathlib import Path

import zstandard
from mcap.records import Channel, Chunk, ChunkIndex, Message, MessageIndex, Schema, Statistics
from mcap.stream_reader import StreamReader


def _chunk_records(chunk: Chunk) -> tuple[bytes, list]:
    if chunk.compression == "zstd":
        raw = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    elif chunk.compression == "":
        raw = chunk.data
    else:
        raise ValueError(f"compression {chunk.compression!r} not handled by this check")
    return raw, list(_with_offsets(raw))


def _with_offsets(raw: bytes):
    """(offset in the uncompressed chunk, record) of every record of a chunk."""
    pos = 0
    while pos < len(raw):
        length = int.from_bytes(raw[pos + 1:pos + 9], "little")
        record = next(iter(StreamReader(io.BytesIO(raw[pos:pos + 9 + length]), skip_magic=True).records))
        yield pos, record
        pos += 9 + length


class _Doctor:
    """The walk's state: topics, the latest log time, the chunk waiting for its indexes."""

    def __init__(self) -> None:
        self.problems: list[str] = []
        self.topics: dict[int, str] = {}
        self.latest = 0
        self.count = 0
        self.ranges: list[tuple[int, int]] = []     # each chunk's (message_start_time, message_end_time)

    def chunk(self, c: Chunk, indexes: dict[int, MessageIndex]) -> None:
        raw, records = _chunk_records(c)
        if len(raw) != c.uncompressed_size:
            self.problems.append("Uncompressed chunk data size != Chunk.uncompressed_size")
        if c.uncompressed_crc and zlib.crc32(raw) != c.uncompressed_crc:
            self.problems.append("invalid chunk CRC")
        times = []
        for offset, rec in records:
            if isinstance(rec, Channel):
                self.topics[rec.id] = rec.topic
            elif isinstance(rec, Message):
                self.message(rec, offset, indexes.get(rec.channel_id))
                times.append(rec.log_time)
            elif not isinstance(rec, Schema):
                self.problems.append(f"Illegal record in chunk: {type(rec).__name__}")
        if times:
            if min(times) != c.message_start_time:
                self.problems.append(f"Chunk.message_start_time {c.message_start_time} does not match "
                                     f"the earliest message log time {min(times)}")
            if max(times) != c.message_end_time:
                self.problems.append(f"Chunk.message_end_time {c.message_end_time} does not match "
                                     f"the latest message log time {max(times)}")
            self.ranges.append((c.message_start_time, c.message_end_time))

    def message(self, rec: Message, offset: int, index: MessageIndex | None) -> None:
        topic = self.topics.get(rec.channel_id, "?")
        if rec.log_time < self.latest:
            self.problems.append(f"Message.log_time {rec.log_time} on {topic!r} is less than "
                                 f"the latest log time {self.latest}")
        self.latest = max(self.latest, rec.log_time)
        self.count += 1
        entry = [t for t, o in (index.records if index else []) if o == offset]
        if not entry:
            self.problems.append(f"No MessageIndex entry for channel {rec.channel_id} at offset {offset}")
        elif entry[0] != rec.log_time:
            self.problems.append(f"MessageIndex entry for channel {rec.channel_id} at offset {offset} "
                                 f"has timestamp {entry[0]}, but message has {rec.log_time}")


def doctor(path: str | Path) -> list[str]:
    """The problems ``mcap doctor --strict-message-order`` would report in ``path`` (empty: none)."""
    d = _Doctor()
    chunk: Chunk | None = None
    indexes: dict[int, MessageIndex] = {}
    stats: list[Statistics] = []
    chunk_index: list[ChunkIndex] = []
    with open(path, "rb") as f:
        for rec in StreamReader(f, emit_chunks=True, validate_crcs=True).records:
            if chunk is not None and not isinstance(rec, MessageIndex):
                d.chunk(chunk, indexes)
                chunk, indexes = None, {}
            if isinstance(rec, Chunk):
                chunk = rec
            elif isinstance(rec, MessageIndex):
                indexes[rec.channel_id] = rec
            elif isinstance(rec, Channel):
                d.topics[rec.id] = rec.topic
            elif isinstance(rec, Message):
                d.problems.append("Message outside a chunk")
            elif isinstance(rec, Statistics):
                stats.append(rec)
            elif isinstance(rec, ChunkIndex):
                chunk_index.append(rec)
    if chunk is not None:
        d.chunk(chunk, indexes)
    if len(stats) != 1 or stats[0].message_count != d.count:
        d.problems.append(f"Statistics {stats} do not count the {d.count} messages")
    if [(c.message_start_time, c.message_end_time) for c in chunk_index] != d.ranges:
        d.problems.append("chunk indexes do not match the chunks' time ranges")
    return d.problems
