"""Checking the chunk records of a ``.part`` file, and finding the next intact one after damage.

:func:`check_chunk` takes a complete chunk record apart exactly as the writer
(:class:`~cmsensord.sinks.mcap_chunks.ChunkWriter`) builds it: decompressed
size and CRC, record framing, schema and channel records; it rebuilds the
message index and leaves out messages on channels no record defines.
:class:`Resync` scans a file for the next chunk record that passes those
checks, so salvage (:mod:`cmsensord.sinks.mcap_salvage`) can skip a damaged
record whatever part of it was hit.
"""

from __future__ import annotations

import mmap
import struct
import threading
import zlib
from typing import BinaryIO

import zstandard
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Schema

from cmsensord.sinks.mcap_chunks import MESSAGE_FIXED, OP_MESSAGE, lz4_frame
from cmsensord.sinks.mcap_records import RECORD_LIMIT, parse_record

__all__ = ["ChunkDamaged", "Interrupted", "Resync", "check_chunk"]


class ChunkDamaged(Exception):
    """A complete record failed its checks (salvage skips it)."""


class Interrupted(Exception):
    """The stop flag was set during a scan (salvage leaves the ``.part`` as it was)."""


def _decompress(chunk: Chunk) -> bytes:
    """The chunk's records, checked against its size and CRC; ChunkDamaged if they fail."""
    if chunk.compression == "zstd":
        data = zstandard.ZstdDecompressor().decompress(
            chunk.data, max_output_size=chunk.uncompressed_size
        )
    elif chunk.compression == "lz4":
        if lz4_frame is None:
            raise ChunkDamaged("lz4 chunk, but the lz4 package is not installed")
        data = lz4_frame.decompress(chunk.data)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise ChunkDamaged(f"unknown chunk compression {chunk.compression!r}")
    if len(data) != chunk.uncompressed_size:
        raise ChunkDamaged(f"chunk holds {len(data)} bytes, its header says {chunk.uncompressed_size}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ChunkDamaged("chunk CRC mismatch")
    return bytes(data)



def _index_records(
    data: bytes, channels: dict[int, Channel]
) -> tuple[dict[int, list[tuple[int, int]]], int, int, int, list[Schema], list[Channel],
           list[tuple[int, int]]]:
    """Walk the records of a decompressed chunk and rebuild its message index.

    Returns (index {channel: [(log time, offset)]}, messages, first and last
    log time, schemas, channels defined in it, spans of the records to keep);
    a channel defined in it is also added to ``channels``. A message on a
    channel no record defines (its definition was in a damaged chunk) is left
    out of the index and of the spans. Raises ChunkDamaged for a record that
    crosses the end of the chunk, a message too short for its fields, or a
    schema or channel record that does not parse.
    """
    index: dict[int, list[tuple[int, int]]] = {}
    schemas: list[Schema] = []
    new_channels: list[Channel] = []
    spans: list[tuple[int, int]] = []
    n = t0 = t1 = 0
    off, end = 0, len(data)
    while off < end:
        if off + 9 > end:
            raise ChunkDamaged("a record header crosses the end of the chunk")
        opcode, length = struct.unpack_from("<BQ", data, off)
        stop = off + 9 + length
        if stop > end:
            raise ChunkDamaged("a record crosses the end of the chunk")
        if opcode == OP_MESSAGE:
            if length < MESSAGE_FIXED:
                raise ChunkDamaged("a message record too short for its fields")
            channel_id, _seq, log_time = struct.unpack_from("<HIQ", data, off + 9)
            if channel_id not in channels:
                off = stop
                continue
            index.setdefault(channel_id, []).append((log_time, off))
            if n:
                t0, t1 = min(t0, log_time), max(t1, log_time)
            else:
                t0 = t1 = log_time
            n += 1
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            try:
                record = parse_record(data[off:stop])
            except Exception as err:  # noqa: BLE001 - corruption
                raise ChunkDamaged(f"bad schema/channel record: {type(err).__name__}: {err}") from None
            if isinstance(record, Schema):
                schemas.append(record)
            elif isinstance(record, Channel):
                channels[record.id] = record
                new_channels.append(record)
        spans.append((off, stop))
        off = stop
    return index, n, t0, t1, schemas, new_channels, spans


def check_chunk(
    raw: bytes, channels: dict[int, Channel]
) -> tuple[Chunk, dict[int, list[tuple[int, int]]], int, list[Schema], list[Channel], int]:
    """Check a complete chunk record and rebuild its message index.

    Returns (chunk as written to the salvaged file, index {channel: [(log
    time, offset)]}, messages, schemas, channels defined in it, messages left
    out). Messages on a channel no record defines are left out: the chunk is
    then rewritten uncompressed with the other records. Raises ChunkDamaged for
    anything else that is not exactly what the writer produces.
    """
    try:
        chunk = parse_record(raw)
        if not isinstance(chunk, Chunk):
            raise ChunkDamaged("a chunk opcode that does not parse as a chunk")
        data = _decompress(chunk)
    except ChunkDamaged:
        raise
    except Exception as err:  # noqa: BLE001 - any failure of the parser or codec is damage
        raise ChunkDamaged(f"{type(err).__name__}: {err}") from None
    index, n, t0, t1, schemas, new_channels, spans = _index_records(data, channels)
    compression, stored, dropped = chunk.compression, chunk.data, 0
    kept = sum(b - a for a, b in spans)
    if kept != len(data):               # messages on undefined channels left out
        total = _count_messages(data)
        data = stored = b"".join(data[a:b] for a, b in spans)
        compression = ""
        index, n, t0, t1, _s, _c, _spans = _index_records(data, dict(channels))
        dropped = total - n
    fresh = Chunk(  # times from the messages themselves: the header's are not CRC-protected
        compression=compression,
        data=stored,
        message_start_time=t0,
        message_end_time=t1,
        uncompressed_crc=zlib.crc32(data),
        uncompressed_size=len(data),
    )
    return fresh, index, n, schemas, new_channels, dropped


def _count_messages(data: bytes) -> int:
    """The message records of a decompressed chunk already walked by _index_records."""
    n = off = 0
    while off + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, off)
        n += opcode == OP_MESSAGE
        off += 9 + length
    return n


class Resync:
    """Finds where intact records resume after damage: the next chunk record of
    the file whose length fits, whose CRC is set and whose content checks out."""

    _MIN_CHUNK = 8 + 8 + 8 + 4 + 4 + 8  # a chunk record body with no compression name, no data

    def __init__(self, f: BinaryIO, size: int, stop: threading.Event | None) -> None:
        self._f, self._size, self._stop = f, size, stop
        self._mm: mmap.mmap | None = None

    def close(self) -> None:
        if self._mm is not None:
            self._mm.close()

    def _map(self) -> mmap.mmap:
        if self._mm is None:
            self._mm = mmap.mmap(self._f.fileno(), 0, access=mmap.ACCESS_READ)
        return self._mm

    def zero_tail(self) -> int:
        """The offset where the run of zero bytes that ends the file begins (the file's size
        when its last byte is not zero): what a file system that extended the file past the
        last write it got to disk (a power cut) reads back."""
        if self._size == 0:
            return 0
        mm, end = self._map(), self._size
        while end > 0:
            start = max(0, end - (1 << 16))
            kept = len(mm[start:end].rstrip(b"\0"))
            if kept:
                return start + kept
            end = start
        return 0

    def next_chunk(self, start: int, channels: dict[int, Channel]) -> int | None:
        """The offset of the first good chunk record at or after ``start``, or None."""
        if self._size <= start:
            return None
        mm, size, i = self._map(), self._size, start
        while (i := mm.find(b"\x06", i)) >= 0 and i + 9 + self._MIN_CHUNK <= size:
            if self._stop is not None and self._stop.is_set():
                raise Interrupted
            length = struct.unpack_from("<Q", mm, i + 1)[0]
            if (self._MIN_CHUNK <= length <= RECORD_LIMIT and i + 9 + length <= size
                    and struct.unpack_from("<I", mm, i + 33)[0] != 0):
                try:
                    check_chunk(mm[i: i + 9 + length], dict(channels))
                    return i
                except ChunkDamaged:
                    pass
            i += 1
        return None

    def indexed_messages(self, start: int, end: int) -> int:
        """Messages listed by the message index records from ``start`` up to ``end``
        (those that follow a damaged chunk): what it held, as far as they tell."""
        n, pos = 0, start
        self._f.seek(pos)
        while pos + 9 + 6 <= end:
            opcode, length = struct.unpack("<BQ", self._f.read(9))
            if opcode != Opcode.MESSAGE_INDEX or pos + 9 + length > end or length < 6:
                break
            body = self._f.read(length)
            n += struct.unpack_from("<I", body, 2)[0] // 16
            pos += 9 + length
        return n
