"""Salvage: the complete chunks of a leftover ``.part`` file, rewritten into a finished file.

A ``.part`` file is what a crash, a kill or a disk error leaves of a
:class:`~cmsensord.sinks.mcap_file.McapSink` file: every chunk flushed before
it, then possibly a partial record. :func:`salvage` walks it with
:class:`~cmsensord.sinks.mcap_read.RecordWalker`, checks each complete chunk
(CRC, record framing, channels), and copies the good ones, compressed data
unchanged, through :class:`~cmsensord.sinks.mcap_chunks.ChunkWriter` into
``<stem>.salvaged.mcap``; :func:`salvage_leftovers` does that for every
``.part`` file of a prefix in a directory.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import zstandard
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Metadata, Schema

from cmsensord import __version__
from cmsensord.sinks.mcap_chunks import MESSAGE_FIXED, OP_MESSAGE, ChunkWriter, lz4_frame
from cmsensord.sinks.mcap_file import (
    RawFile,
    SinkIOError,
    fsync_dir,
    log_files,
    os_error_text,
    salvaged_path,
)
from cmsensord.sinks.mcap_read import NOT_MCAP, RecordWalker, parse_record

__all__ = ["SalvageResult", "salvage", "salvage_leftovers"]


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
    """The chunk's records, checked against its size and CRC; _Damaged if they fail."""
    if chunk.compression == "zstd":
        data = zstandard.ZstdDecompressor().decompress(
            chunk.data, max_output_size=chunk.uncompressed_size
        )
    elif chunk.compression == "lz4":
        if lz4_frame is None:
            raise _Damaged("lz4 chunk, but the lz4 package is not installed")
        data = lz4_frame.decompress(chunk.data)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise _Damaged(f"unknown chunk compression {chunk.compression!r}")
    if len(data) != chunk.uncompressed_size:
        raise _Damaged(f"chunk holds {len(data)} bytes, its header says {chunk.uncompressed_size}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise _Damaged("chunk CRC mismatch")
    return bytes(data)



def _index_records(
    data: bytes, channels: dict[int, Channel]
) -> tuple[dict[int, list[tuple[int, int]]], int, int, int, list[Schema], list[Channel]]:
    """Walk the records of a decompressed chunk and rebuild its message index.

    Returns (index {channel: [(log time, offset)]}, messages, first and last
    log time, schemas, channels defined in it); a channel defined in it is
    also added to ``channels``. Raises _Damaged for a record that crosses
    the end of the chunk, a message too short for its fields or on a channel
    no record defines, or a schema or channel record that does not parse.
    """
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
        if opcode == OP_MESSAGE:
            if length < MESSAGE_FIXED:
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
                record = parse_record(data[off:stop])
            except Exception as err:  # noqa: BLE001 - corruption
                raise _Damaged(f"bad schema/channel record: {type(err).__name__}: {err}") from None
            if isinstance(record, Schema):
                schemas.append(record)
            elif isinstance(record, Channel):
                channels[record.id] = record
                new_channels.append(record)
        off = stop
    return index, n, t0, t1, schemas, new_channels


def _open_chunk(
    raw: bytes, channels: dict[int, Channel]
) -> tuple[Chunk, dict[int, list[tuple[int, int]]], int, list[Schema], list[Channel]]:
    """Check a complete chunk record and rebuild its message index.

    Returns (chunk as written to the salvaged file, index {channel: [(log
    time, offset)]}, messages, schemas, channels defined in it). Raises
    _Damaged for anything that is not exactly what the writer produces.
    """
    try:
        chunk = parse_record(raw)
        if not isinstance(chunk, Chunk):
            raise _Damaged("a chunk opcode that does not parse as a chunk")
        data = _decompress(chunk)
    except _Damaged:
        raise
    except Exception as err:  # noqa: BLE001 - any failure of the parser or codec is damage
        raise _Damaged(f"{type(err).__name__}: {err}") from None
    index, n, t0, t1, schemas, new_channels = _index_records(data, channels)
    fresh = Chunk(  # times from the messages themselves: the header's are not CRC-protected
        compression=chunk.compression,
        data=chunk.data,
        message_start_time=t0,
        message_end_time=t1,
        uncompressed_crc=zlib.crc32(data),
        uncompressed_size=len(data),
    )
    return fresh, index, n, schemas, new_channels


class _SalvagedFile:
    """The salvaged file of ``part``: ``<stem>.salvaged.mcap.tmp`` until finished.

    Created at the first complete chunk; metadata records met before it are
    kept until then, so they come first in the file as in the ``.part``.
    """

    def __init__(self, part: Path) -> None:
        self.part = part
        self.tmp = salvaged_path(part).with_suffix(".mcap.tmp")
        self._fh: RawFile | None = None
        self._writer: ChunkWriter | None = None
        self._metadata: list[Metadata] = []

    @property
    def created(self) -> bool:
        return self._writer is not None

    def add_metadata(self, record: Metadata) -> None:
        if self._writer is None:
            self._metadata.append(record)
        else:
            self._writer.add_metadata(record.name, dict(record.metadata))

    def add_chunk(
        self,
        chunk: Chunk,
        index: dict[int, list[tuple[int, int]]],
        n: int,
        schemas: list[Schema],
        channels: list[Channel],
    ) -> None:
        if self._writer is None:
            self._writer = self._create()
        self._writer.add_chunk(chunk, index, n, schemas, channels)

    def _create(self) -> ChunkWriter:
        flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0)
        self._fh = RawFile(os.open(self.tmp, flags, 0o644))
        writer = ChunkWriter(self._fh, "", 1)
        writer.start(library=f"cmsensord/{__version__}")
        for record in self._metadata:
            writer.add_metadata(record.name, dict(record.metadata))
        return writer

    def finish(self, salvage_metadata: dict[str, str], durable: bool) -> Path:
        """Add the ``cmsensord.salvage`` metadata record, the summary and footer; fsync
        (``durable``), close and rename to ``<stem>.salvaged.mcap``; returns that path."""
        assert self._writer is not None and self._fh is not None
        self._writer.add_metadata("cmsensord.salvage", salvage_metadata)
        self._writer.finish()
        if durable:
            os.fsync(self._fh.fileno())
        self._fh.close()
        final = salvaged_path(self.part)
        os.replace(self.tmp, final)
        return final

    def discard(self) -> None:
        """After an error: close and delete the partial file (further errors ignored)."""
        if self._fh is None:
            return
        with contextlib.suppress(OSError):
            self._fh.close()
        with contextlib.suppress(OSError):
            self.tmp.unlink(missing_ok=True)


def _lock(f: BinaryIO) -> bool:
    """Lock the ``.part`` file; False when another process holds it (its writer)."""
    try:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError:
        pass  # no flock here: only salvage at start, when nothing writes
    return True


_WALK_END = {  # RecordWalker.end -> (damaged, reason) when the file itself ends the walk
    RecordWalker.NOT_MCAP: (True, NOT_MCAP),
    RecordWalker.IN_MAGIC: (False, "ends inside the magic"),
    RecordWalker.AT_END: (False, "ends after a complete record"),
    RecordWalker.IN_RECORD: (False, "ends inside a record"),
}


def _copy_records(f: BinaryIO, out: _SalvagedFile, result: SalvageResult) -> int:
    """Copy the good chunks and the metadata of ``f`` into ``out``.

    Stops at the first incomplete or damaged record, or at the end of the
    data section (DataEnd or Footer: a finished file). Counts the messages
    and chunks in ``result`` and sets its ``damaged`` and ``reason``; returns
    the offset up to which ``f`` was read as good (its size for a finished
    file). Header and message index records (rebuilt) and unknown records
    are skipped.
    """
    walker = RecordWalker(f)
    channels: dict[int, Channel] = {}
    for pos, opcode, raw in walker.records():
        if opcode == Opcode.CHUNK:
            try:
                chunk, index, n, schemas, new_channels = _open_chunk(raw, channels)
            except _Damaged as err:
                result.damaged, result.reason = True, f"damaged chunk at byte {pos}: {err}"
                return pos
            out.add_chunk(chunk, index, n, schemas, new_channels)
            result.messages += n
            result.chunks += 1
        elif opcode == Opcode.METADATA:
            try:
                record = parse_record(raw)
            except Exception as err:  # noqa: BLE001 - corruption
                result.damaged, result.reason = True, f"bad metadata record at byte {pos}: {err}"
                return pos
            out.add_metadata(record)
        elif opcode in (Opcode.DATA_END, Opcode.FOOTER):
            result.reason = "a finished file"  # its summary is rebuilt
            return result.source_bytes
    assert walker.end is not None                # the loop above ran the walk to its end
    if walker.end == RecordWalker.TOO_LONG:
        result.damaged, result.reason = True, walker.error or ""
    else:
        result.damaged, result.reason = _WALK_END[walker.end]
    return walker.valid_bytes


def _drop_part(part: Path, result: SalvageResult, durable: bool) -> None:
    """Nothing recoverable: delete ``part``, or set it aside when it is damaged."""
    if result.damaged:
        aside = part.with_name(part.name + ".unreadable")
        os.replace(part, aside)
        result.action, result.path = "set_aside", aside
    else:
        part.unlink()
        result.action = "removed"
    if durable:
        fsync_dir(part.parent)


def _replace_part(part: Path, out: _SalvagedFile, result: SalvageResult, durable: bool) -> None:
    """Finish the salvaged file, then delete ``part`` (directory fsynced after each step)."""
    final = out.finish({
        "source": part.name,
        "messages": str(result.messages),
        "source_bytes": str(result.source_bytes),
        "dropped_bytes": str(result.dropped_bytes),
    }, durable)
    if durable:
        fsync_dir(part.parent)
    part.unlink()
    if durable:
        fsync_dir(part.parent)
    result.action, result.path = "salvaged", final


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
        raise SinkIOError(f"{part}: cannot read: {os_error_text(err)}", op="read", err=err,
                          path=part) from None
    out = _SalvagedFile(part)
    try:
        with f:  # open (and locked) until the .part is gone
            if not _lock(f):
                result.action = "busy"
                return result
            result.source_bytes = os.fstat(f.fileno()).st_size
            valid = _copy_records(f, out, result)
            result.dropped_bytes = max(0, result.source_bytes - valid)
            if out.created:
                _replace_part(part, out, result, durable)
            else:
                _drop_part(part, result, durable)
            return result
    except OSError as err:
        out.discard()
        raise SinkIOError(f"{part}: cannot salvage: {os_error_text(err)}", op="write", err=err,
                          path=part) from None


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
