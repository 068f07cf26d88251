"""A fast lenient reader of MCAP messages for long logs: chunks parsed with ``struct``, not record objects.

:meth:`FastScan.messages` yields the same (topic, publish_time_ns, data) as
:func:`~cmsensord.sinks.mcap_read.iter_messages_at` of an undamaged file, plus the
bytes read so far, about ten times faster: the file is walked with the rules of
:class:`~cmsensord.sinks.mcap_read.RecordWalker` (a ``.part`` file ends at its
last complete record, a record claiming more than ``RECORD_LIMIT`` bytes is
damage, nothing is raised on the content; the file is memory-mapped, not read into memory), each chunk is checked
against its CRC and decompressed once, and the Channel and Message records in it
are read by their fixed layouts (MCAP specification, "Records"). Damage (a chunk
that cannot be decompressed or fails its CRC, a record claiming more bytes than
there are) is read past as salvage reads past it: from the next chunk record that
checks out (:class:`~cmsensord.sinks.mcap_chunk_check.Resync`), each stretch
skipped listed in :attr:`FastScan.skipped`; with no good chunk after it, the
damage ends the read (:attr:`FastScan.error`). A file that ends before its footer
says what that lost in :attr:`FastScan.cut`: a ``.part`` file is an unfinished one (read up to
its last complete record), any other is cut short (the same text as :attr:`FastScan.error`); a
file shorter than the magic is empty or cut inside it, or not MCAP, in the words of ``summary``
(:func:`~cmsensord.sinks.mcap_cut.short_text`).
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from mcap.records import Metadata

from cmsensord.errors import SinkError
from cmsensord.sinks.mcap_chunk_check import Resync
from cmsensord.sinks.mcap_chunks import MAGIC
from cmsensord.sinks.mcap_cut import CUT_HEAD, cut_text, is_unfinished_name, short_text
from cmsensord.sinks.mcap_records import NOT_MCAP, RECORD_LIMIT, parse_record

__all__ = ["FastScan", "head_metadata"]

_OP_HEADER = 0x01
_OP_METADATA = 0x0C
_OP_CHANNEL = 0x04
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
_OP_FOOTER = 0x02
_HEAD = struct.Struct("<BQ")
_MSG = struct.Struct("<HIQQ")          # channel_id, sequence, log_time, publish_time
_CHUNK = struct.Struct("<QQQI")         # message start, end, uncompressed size, uncompressed crc


_ZSTD: list[Any] = []


def head_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """The Metadata records at the head of an MCAP file, before its first other record (where
    cmsensord's sink writes them): name -> map; {} for a file that cannot be read or is not
    MCAP, and what was read up to a damaged record."""
    out: dict[str, dict[str, str]] = {}
    try:
        with open(path, "rb") as f:
            if f.read(len(MAGIC)) != MAGIC:
                return out
            while len(head := f.read(9)) == 9:
                opcode, length = _HEAD.unpack(head)
                if opcode not in (_OP_HEADER, _OP_METADATA) or length > RECORD_LIMIT:
                    break
                body = f.read(length)
                if len(body) < length:
                    break
                record = parse_record(head + body)
                if isinstance(record, Metadata):
                    out[record.name] = dict(record.metadata)
    except Exception:  # noqa: BLE001 - a file that cannot be read, or mcap's parser on damage
        pass
    return out


def _zstd() -> Any:
    """One zstd decompressor for every chunk (making one costs more than a small chunk's data)."""
    if not _ZSTD:
        import zstandard
        _ZSTD.append(zstandard.ZstdDecompressor())
    return _ZSTD[0]


class FastScan:
    """One file's messages (:meth:`messages`); :attr:`skipped` the damage read past,
    :attr:`error` the damage that ended the read."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.topics: dict[int, str] = {}
        self.error: str | None = None
        self.skipped: list[str] = []
        self.complete = False
        self.cut: str | None = None      # what a file ending short lost (:mod:`~cmsensord.sinks.mcap_cut`)

    def messages(self) -> Iterator[tuple[str, int, bytes, int]]:
        """(topic, publish time [ns]: the message's own stamp, data, bytes read) of every message
        the file's intact records hold."""
        try:
            f = open(self.path, "rb")
            size = os.fstat(f.fileno()).st_size
        except OSError as err:
            raise SinkError(f"{self.path}: cannot read: {err.strerror or err}") from None
        with f:
            if size < len(MAGIC):
                self._short(f.read(size))
                return
            resync = Resync(f, size, None)
            try:
                with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
                    yield from self._walk(buf, size, resync)
            finally:
                resync.close()

    def _short(self, head: bytes) -> None:
        """A file of fewer bytes than the magic (``head``): empty or cut inside the magic, in
        :attr:`cut` (and :attr:`error` unless it is a ``.part``), or not MCAP."""
        text = short_text(head)
        if text == NOT_MCAP:
            self.error = text
            return
        self.cut = text
        if not is_unfinished_name(self.path.name):
            self.error = text

    def _walk(self, buf: mmap.mmap, size: int, resync: Resync) -> Iterator[tuple[str, int, bytes, int]]:
        """The top-level records of the mapped file, as :class:`RecordWalker` walks them, damage
        read past from the next good chunk (:meth:`_past`)."""
        if buf[: len(MAGIC)] != MAGIC:
            self.error = NOT_MCAP
            return
        pos = len(MAGIC)
        while pos + 9 <= size:
            opcode, length = _HEAD.unpack_from(buf, pos)
            end = pos + 9 + length
            damage = None
            if length > RECORD_LIMIT:
                damage = f"record at byte {pos} claims {length} bytes"
            elif end > size:
                damage = ""                             # the file ends inside a record
            elif opcode == _OP_CHUNK:
                try:
                    records = self._chunk_records(buf[pos:end])
                except (ValueError, struct.error, zlib.error) as err:
                    damage = f"bad chunk at byte {pos}: {err}"
                else:
                    for topic, t, data in self._records(records, pos):
                        yield topic, t, data, end
            elif opcode in (_OP_CHANNEL, _OP_MESSAGE):
                for topic, t, data in self._records(buf[pos:end], pos):
                    yield topic, t, data, end
            elif opcode == _OP_FOOTER:
                self.complete = buf[end: end + len(MAGIC)] == MAGIC
                return
            if damage is not None:
                end = self._past(resync, pos, damage, buf)
                if end is None:
                    return
            if self.error:
                return
            pos = end
        self._cut(buf, pos, size)

    def _cut(self, buf: mmap.mmap, pos: int, size: int) -> None:
        """The file ends inside the record at ``pos`` (or after it, with no footer): what that
        lost in :attr:`cut`, and as :attr:`error` too unless the file is one being written."""
        self.cut = cut_text(buf[pos: pos + CUT_HEAD], pos, size)
        if not is_unfinished_name(self.path.name):
            self.error = self.cut

    def _past(self, resync: Resync, pos: int, damage: str, buf: mmap.mmap) -> int | None:
        """Damage at byte ``pos`` (``""``: the file ends inside a record): the offset of the next
        good chunk, the damage listed in :attr:`skipped`; None when there is none (the damage
        ends the read, in :attr:`error`; a file ending inside a record, :meth:`_cut`)."""
        nxt = resync.next_chunk(pos + 1, {})
        if nxt is None:
            self.error = damage or None
            if not damage:
                self._cut(buf, pos, len(buf))
            return None
        self.skipped.append(damage or f"a record at byte {pos} claims more bytes than the file holds")
        return nxt

    @staticmethod
    def _chunk_records(raw: bytes) -> bytes:
        """The decompressed, CRC-checked records of a chunk record (opcode and length included)."""
        _start, _end, size, crc = _CHUNK.unpack_from(raw, 9)
        off = 9 + _CHUNK.size
        (n,) = struct.unpack_from("<I", raw, off)
        compression = raw[off + 4: off + 4 + n].decode()
        off += 4 + n
        (n,) = struct.unpack_from("<Q", raw, off)
        body = raw[off + 8: off + 8 + n]
        if compression not in ("", "zstd", "lz4"):
            raise ValueError(f"unknown compression {compression!r}")
        try:
            if compression == "zstd":
                body = _zstd().decompress(body, max_output_size=size)
            elif compression == "lz4":
                import lz4.frame  # type: ignore[import-not-found,unused-ignore]
                body = lz4.frame.decompress(body)
        except Exception as err:  # noqa: BLE001 - any failure of the codec is damage
            raise ValueError(f"cannot decompress ({compression}): {err}") from None
        if len(body) != size or (crc and zlib.crc32(body) != crc):
            raise ValueError("CRC or size mismatch")
        return body

    def _records(self, buf: bytes, pos: int) -> Iterator[tuple[str, int, bytes]]:
        """Messages of a run of records (from the record at byte ``pos``); Channel records
        remembered on the way; a record running past the end sets :attr:`error`."""
        off, n = 0, len(buf)
        topics = self.topics
        while off + 9 <= n:
            opcode, length = _HEAD.unpack_from(buf, off)
            body = off + 9
            off = body + length
            if off > n:
                self.error = f"bad chunk at byte {pos}: a record runs past its end"
                return
            if opcode == _OP_MESSAGE:
                cid, _seq, _log, t = _MSG.unpack_from(buf, body)
                yield topics.get(cid, f"<channel {cid}>"), t, buf[body + _MSG.size: off]
            elif opcode == _OP_CHANNEL:
                cid, _schema, tlen = struct.unpack_from("<HHI", buf, body)
                topics[cid] = buf[body + 8: body + 8 + tlen].decode("utf-8", "replace")
