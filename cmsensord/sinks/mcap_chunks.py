"""MCAP records and the chunk writer shared by the sink and salvage.

:data:`MAGIC`, record serialisation with mcap's own record classes
(:func:`build_records`), the layout of a message record, and
:class:`ChunkWriter`, which writes a chunked, indexed MCAP file to a file
object. It keeps no clock and opens no file: the sink
(:mod:`cmsensord.sinks.mcap_file`) decides when a chunk is finished and owns
the file; salvage (:mod:`cmsensord.sinks.mcap_salvage`) feeds it chunks
copied from another file.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterable
from itertools import chain
from typing import Any

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

try:
    import lz4.frame as lz4_frame
except ImportError:  # optional, as in mcap itself
    lz4_frame = None

from cmsensord.errors import SinkError

__all__ = ["MAGIC", "MESSAGE_FIXED", "OP_MESSAGE", "ChunkWriter", "build_records", "lz4_frame"]

MAGIC = b"\x89MCAP0\r\n"


def build_records(*records: Any) -> bytes:
    """Serialise mcap record objects with mcap's own record code."""
    builder = RecordBuilder()
    for record in records:
        record.write(builder)
    return builder.end()


_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, record length, channel, records' byte length
MESSAGE_FIXED = 2 + 4 + 8 + 8  # body bytes of a message record before its data
OP_MESSAGE = int(Opcode.MESSAGE)


def message_index(channel_id: int, records: list[tuple[int, int]]) -> bytes:
    """The MessageIndex record of ``records`` (log time, offset in the chunk) of one channel,
    the bytes ``mcap.records.MessageIndex(...).write`` builds, packed in one call."""
    n = len(records)
    return _INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 6 + 16 * n, channel_id, 16 * n) + \
        struct.pack(f"<{2 * n}Q", *chain.from_iterable(records))


class ChunkWriter:
    """Writes a chunked, indexed MCAP file to ``fh``, one finished chunk at a time.

    Messages are packed into the open chunk; :meth:`finish_chunk` (called by
    the sink every ``flush_s``, and here when the chunk passes ``chunk_size``
    uncompressed bytes) compresses it and writes it, with its message
    indexes, in one ``fh.write`` call. Every record but Message is built by
    mcap's own record classes. The layout is that of ``mcap.writer.Writer``
    with its defaults (schemas and channels inside chunks, a message index
    after each chunk, a summary with repeated schemas and channels,
    statistics, chunk and metadata indexes, summary offsets, CRCs), with the
    data-section CRC always filled in and no summary offset for an empty
    summary group.

    It is used instead of ``mcap.writer.Writer`` (mcap 1.6) because:

    * salvage copies compressed chunks verbatim: :meth:`add_chunk` writes a
      chunk read from another file, compressed data unchanged, with a
      rebuilt message index and its schemas and channels in the summary;
      mcap's Writer builds chunks only from messages;
    * :attr:`persisted` counts exactly the messages of the chunks whose
      write returned (the chunk and its message indexes are one write), and
      the open chunk is emptied before it is written, so a chunk whose write
      failed is neither counted nor written again; mcap's Writer counts
      messages when they are added and tells nothing of which are in the file;
    * add_message() is one struct.pack and two bytearray appends (~1 us a
      message; mcap's ``Writer.add_message`` builds a Message object and
      packs it field by field, ~4 us).

    Unbuffered writes and time-bounded chunks come from the caller: ``fh``
    is the sink's :class:`~cmsensord.sinks.mcap_file.RawFile` (straight to the
    kernel), and the sink calls :meth:`finish_chunk` by its clock.
    """

    def __init__(self, fh: Any, compression: str, chunk_size: int) -> None:
        """``fh``: has write(bytes); ``compression``: "zstd", "lz4" or "" (the Chunk
        record's field); ``chunk_size``: uncompressed bytes that finish a chunk."""
        if compression == "lz4" and lz4_frame is None:
            raise SinkError("lz4 compression needs the lz4 package (pip install lz4)")
        self._fh = fh
        self._compression = compression
        self._chunk_size = chunk_size
        self.pos = 0  # bytes written to fh
        self.persisted = 0  # messages in chunks handed to the kernel completely
        self._data_crc = 0
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        # the summary's ChunkIndex records of the chunks written, serialised as they are written:
        # ~190 bytes a chunk of 11 channels (mcap's objects, a dict each: ~1.3 KB)
        self._chunk_index_raw = bytearray()
        self._chunk_count = 0
        self._metadata_indexes: list[MetadataIndex] = []
        self._channel_counts: dict[int, int] = {}
        self._message_count = 0
        self._start_time = 0
        self._end_time = 0
        # one compressor kept (zstandard.compress makes and frees one per call: its context's
        # tables, ~15 us a chunk); the same frames, byte for byte
        self._zstd = zstandard.ZstdCompressor() if compression == "zstd" else None
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
        """Magic and Header record (``library`` names the writer)."""
        self._out(MAGIC + build_records(Header(profile="", library=library)))

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A Metadata record, written at once (outside any chunk) and indexed in the summary."""
        raw = build_records(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=self.pos, length=len(raw), name=name))
        self._out(raw)

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """A Schema record into the open chunk; returns its id (1, 2, ...)."""
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._chunk += build_records(schema)
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int) -> int:
        """A Channel record into the open chunk; returns its id (1, 2, ...)."""
        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata={},
        )
        self._channels.append(channel)
        self._chunk += build_records(channel)
        return channel.id

    def add_message(self, channel_id: int, log_time: int, data: bytes,
                    publish_time: int | None = None, split: bool = True) -> None:
        """A Message record (sequence 0, publish time = ``publish_time`` or ``log_time``, ns)
        into the open chunk; the chunk is finished when it passes ``chunk_size`` bytes (unless
        ``split`` is False: :meth:`add_group`)."""
        chunk = self._chunk
        records = self._index.get(channel_id)
        if records is None:
            records = self._index[channel_id] = []
        records.append((log_time, len(chunk)))
        chunk += _MESSAGE_HEAD.pack(
            OP_MESSAGE, MESSAGE_FIXED + len(data), channel_id, 0, log_time,
            log_time if publish_time is None else publish_time
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
        if split and len(chunk) > self._chunk_size:
            self.finish_chunk()

    def add_group(self, messages: Iterable[tuple[int, bytes]], log_time: int,
                  publish_time: int | None = None) -> None:
        """Messages ``(channel_id, data)`` that must be whole or absent after a crash (a
        capture): the open chunk is written first, then the group alone in one chunk (whatever
        ``chunk_size``), written at once. A file cut anywhere in it holds all or none of them."""
        self.finish_chunk()
        for channel_id, data in messages:
            self.add_message(channel_id, log_time, data, publish_time, split=False)
        self.finish_chunk()

    def finish_chunk(self) -> None:
        """Compress the open chunk and write it with its message indexes."""
        if not self._n:  # keep schema/channel records for the next chunk
            return
        raw = bytes(self._chunk)
        if self._zstd is not None:
            data = self._zstd.compress(raw)
        elif self._compression == "lz4":
            data = lz4_frame.compress(raw)
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
        chunk_raw = build_records(chunk)
        t0, t1 = chunk.message_start_time, chunk.message_end_time
        chunk_start = self.pos
        index_start = chunk_start + len(chunk_raw)
        parts: list[bytes] = []
        size = 0
        offsets: dict[int, int] = {}
        for channel_id, records in index.items():
            offsets[channel_id] = index_start + size
            parts.append(message_index(channel_id, records))
            size += len(parts[-1])
            self._channel_counts[channel_id] = self._channel_counts.get(channel_id, 0) + len(records)
        index_raw = b"".join(parts)
        self._chunk_index_raw += build_records(
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
        self._chunk_count += 1
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
        self._out(build_records(DataEnd(data_section_crc=self._data_crc)))
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
                        chunk_count=self._chunk_count,
                        message_start_time=self._start_time,
                        message_end_time=self._end_time,
                        channel_message_counts=dict(self._channel_counts),
                    )
                ],
            ),
            (Opcode.CHUNK_INDEX, self._chunk_index_raw),
            (Opcode.METADATA_INDEX, self._metadata_indexes),
        )
        for opcode, records in groups:
            if not records:
                continue
            group_start = builder.count
            if isinstance(records, bytearray):   # records serialised already
                builder.write(records)
            else:
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
        self._out(summary + build_records(footer) + MAGIC)
