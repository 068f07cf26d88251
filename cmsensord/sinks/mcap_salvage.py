"""Salvage: the complete chunks of a leftover ``.part`` file, rewritten into a finished file.

A ``.part`` file is what a crash, a kill or a disk error leaves of a
:class:`~cmsensord.sinks.mcap_file.McapSink` file: every chunk flushed before
it, then possibly a partial record. :func:`salvage` walks it with
:class:`~cmsensord.sinks.mcap_read.RecordWalker`, checks each complete chunk
(:func:`~cmsensord.sinks.mcap_chunk_check.check_chunk`: CRC, record framing,
channels), and copies the good ones, compressed data
unchanged, through :class:`~cmsensord.sinks.mcap_chunks.ChunkWriter` into
``<stem>.salvaged.mcap``; :func:`salvage_leftovers` does that for every
``.part`` file of a prefix in a directory. A damaged record is skipped: the
scan resynchronises at the next chunk record whose CRC checks out, so every
intact chunk after the damage is kept, and a damaged ``.part`` is kept as
``<name>.damaged`` rather than deleted (retention counts it, and deletes it as it deletes
the logs, oldest first: :mod:`cmsensord.sinks.retention`). Zero bytes that run from the
last good record to the end of the file (a power cut: the file system had extended the file
past the last write it got to disk) are a cut, not damage: dropped, nothing kept.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import stat
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Metadata, Schema

from cmsensord import __version__
from cmsensord.sinks.mcap_chunk_check import ChunkDamaged, Interrupted, Resync, check_chunk
from cmsensord.sinks.mcap_chunks import ChunkWriter
from cmsensord.sinks.mcap_file import (
    RawFile,
    SinkIOError,
    fsync_dir,
    log_files,
    os_error_text,
    salvaged_path,
)
from cmsensord.sinks.mcap_records import NOT_MCAP, RecordWalker, parse_record

__all__ = ["SalvageResult", "salvage", "salvage_leftovers"]


@dataclass
class SalvageResult:
    """What :func:`salvage` did with one ``.part`` file.

    ``action``: ``"salvaged"`` (``path`` is the finished file; the ``.part`` is
    gone, or kept as ``kept`` = ``<name>.damaged`` when a damaged record was
    skipped), ``"removed"`` (it ended before its first complete chunk: nothing
    to recover; deleted), ``"set_aside"`` (damaged with no intact chunk, or
    not MCAP at all: renamed to ``<name>.unreadable`` and kept for a human),
    ``"busy"`` (another writer holds it open: left alone), ``"skipped"`` (not
    a regular file, e.g. a FIFO or a symbolic link: left alone, never opened
    for reading), ``"interrupted"`` (the stop flag was set: left as it was).
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
    damage: str = ""  # the first damaged record, one line
    lost_chunks: int = 0  # damaged chunks skipped
    lost_messages: int = 0  # messages known lost (damaged chunks' indexes, undefined channels)
    kept: Path | None = None  # the damaged .part, kept under this name

    def event_details(self) -> dict[str, Any]:
        """The ``details`` of this salvage's event."""
        details: dict[str, Any] = {"action": self.action, "source": str(self.source),
                                   "chunks": self.chunks, "dropped_bytes": self.dropped_bytes}
        if self.path is not None:
            details["file"] = str(self.path)
        if self.damaged:
            details.update(lost_chunks=self.lost_chunks, lost_messages=self.lost_messages)
        if self.kept is not None:
            details["kept"] = str(self.kept)
        return details

    def message(self) -> str:
        """One line for the event."""
        name = self.source.name
        if self.action == "salvaged":
            text = (f"{name}: salvaged {self.messages} message(s) from {self.chunks} complete "
                    f"chunk(s) into {self.path.name if self.path else '?'}")
            if self.kept is not None:
                text += (f"; {self.lost_chunks} damaged chunk(s) skipped, {self.lost_messages} "
                         f"message(s) known lost ({self.damage}); source kept as {self.kept.name}")
            if self.dropped_bytes:
                text += f"; {self.dropped_bytes} byte(s) after them dropped ({self.reason})"
            return text
        if self.action == "removed":
            return (f"{name}: nothing recoverable: no complete chunk in its {self.source_bytes} "
                    f"byte(s) (it ended within a flush period of being opened); removed")
        if self.action == "set_aside":
            return (f"{name}: nothing recoverable ({self.reason}); kept as "
                    f"{self.path.name if self.path else name}")
        if self.action == "skipped":
            return f"{name}: {self.reason}, not a regular file; skipped"
        if self.action == "interrupted":
            return f"{name}: salvage interrupted by stop; left for the next start"
        return f"{name}: in use by another writer; left alone"


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
        flags = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
                 | getattr(os, "O_CLOEXEC", 0))
        try:                            # never through a name planted in the directory
            fd = os.open(self.tmp, flags, 0o644)
        except FileExistsError:         # a stale .tmp (or a planted link): remove the name itself
            os.unlink(self.tmp)
            fd = os.open(self.tmp, flags, 0o644)
        self._fh = RawFile(fd)
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


_KNOWN_OPCODES = frozenset(int(op) for op in Opcode)
#: the least a file system extends a file by (its zero blocks after a power cut), in bytes
_SECTOR = 512

_WALK_END = {  # RecordWalker.end -> (damaged, reason) when the file itself ends the walk
    RecordWalker.NOT_MCAP: (True, NOT_MCAP),
    RecordWalker.IN_MAGIC: (False, "ends inside the magic"),
    RecordWalker.AT_END: (False, "ends after a complete record"),
    RecordWalker.IN_RECORD: (False, "ends inside a record"),
}


def _note_damage(result: SalvageResult, what: str) -> None:
    result.damaged = True
    result.damage = result.damage or what


def _copy_records(f: BinaryIO, out: _SalvagedFile, result: SalvageResult,
                  stop: threading.Event | None = None) -> int:
    """Copy the good chunks and the metadata of ``f`` into ``out``.

    A damaged chunk or metadata record, an unknown opcode or an impossible
    length is skipped: the scan resumes at the next good chunk record
    (:class:`Resync`); the messages of a damaged chunk are counted as lost
    from the message index records after it. Stops at the end of the file
    (its unflushed tail) or of the data section (DataEnd or Footer: a
    finished file). Counts the messages and chunks in ``result`` and sets its
    ``damaged``, ``damage`` and ``reason``; returns the offset up to which
    ``f`` was read as good (its size for a finished file). Raises
    Interrupted when ``stop`` is set. Header and message index records
    (rebuilt) are skipped.
    """
    walker = RecordWalker(f)
    channels: dict[int, Channel] = {}
    resync = Resync(f, result.source_bytes, stop)
    start: int | None = None
    try:
        while True:
            bad = _copy_until_damage(walker, start, out, result, channels, stop)
            if bad is None:             # the walk reached the end of the data or of the file
                if walker.end in (RecordWalker.TOO_LONG, RecordWalker.IN_RECORD):
                    bad = (walker.valid_bytes, walker.error or "ends inside a record", 0)
                else:
                    break
            elif bad[0] < 0:            # DataEnd or Footer
                return result.source_bytes
            pos, what, after = bad
            if _zero_cut(resync, pos, after, result):
                return pos
            nxt = resync.next_chunk(pos + 1, channels)
            if nxt is None:
                if what != "ends inside a record":
                    _note_damage(result, what)
                result.reason = what
                return pos
            if what == "ends inside a record":      # not the tail: its length was hit
                what = f"a record at byte {pos} claims more bytes than the file holds"
            _note_damage(result, what)
            if after:                   # a damaged chunk: what its message index says it held
                result.lost_messages += resync.indexed_messages(after, nxt)
            start = nxt
    finally:
        resync.close()
    assert walker.end is not None
    if walker.end == RecordWalker.TOO_LONG:
        result.damaged, result.reason = True, walker.error or ""
    else:
        damaged, result.reason = _WALK_END[walker.end]
        result.damaged = result.damaged or damaged
    return walker.valid_bytes


def _zero_cut(resync: Resync, pos: int, after: int, result: SalvageResult) -> bool:
    """Whether the bad record at ``pos`` (a chunk ending at ``after``; else 0) is where a run of
    zero bytes to the end of the file begins: from its first byte on, or within the chunk and
    at least a sector long. That is a cut, not damage (a file system extended the file by zero
    blocks past the last write it got to disk, a power cut): the scan ends there as at a cut
    record, and ``result.reason`` says so (its chunk is not counted as damaged)."""
    zeros = resync.zero_tail()
    if not (zeros <= pos or (after and zeros < after and result.source_bytes - zeros >= _SECTOR)):
        return False
    if after:
        result.lost_chunks -= 1         # counted as damaged when its check failed
    where = "all zero bytes" if zeros <= pos else f"zero bytes from byte {zeros} on, inside the chunk at byte {pos}"
    result.reason = f"a cut: {where}, as a file system leaves a file extended past its last write by a power cut"
    return True


def _copy_until_damage(walker: RecordWalker, start: int | None, out: _SalvagedFile,
                       result: SalvageResult, channels: dict[int, Channel],
                       stop: threading.Event | None) -> tuple[int, str, int] | None:
    """Copy records from ``start`` until the first damaged one: (its offset, what is
    wrong, the offset after it when it is a chunk of intact length, else 0); (-1, "", 0)
    at the end of the data section; None at the end of the file."""
    for pos, opcode, raw in walker.records(start):
        if stop is not None and stop.is_set():
            raise Interrupted
        if opcode == Opcode.CHUNK:
            try:
                chunk, index, n, schemas, new_channels, dropped = check_chunk(raw, channels)
            except ChunkDamaged as err:
                result.lost_chunks += 1
                return pos, f"damaged chunk at byte {pos}: {err}", pos + len(raw)
            out.add_chunk(chunk, index, n, schemas, new_channels)
            result.messages += n
            result.chunks += 1
            result.lost_messages += dropped
            if dropped:
                _note_damage(result, f"{dropped} message(s) at byte {pos} on undefined channels")
        elif opcode == Opcode.METADATA:
            try:
                record = parse_record(raw)
            except Exception as err:  # noqa: BLE001 - corruption
                return pos, f"bad metadata record at byte {pos}: {err}", 0
            out.add_metadata(record)
        elif opcode in (Opcode.DATA_END, Opcode.FOOTER):
            result.reason = "a finished file"  # its summary is rebuilt
            return -1, "", 0
        elif opcode not in _KNOWN_OPCODES:
            return pos, f"unknown opcode 0x{opcode:02x} at byte {pos}", 0
    return None


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
    """Finish the salvaged file, then delete ``part``, or keep it as ``<name>.damaged``
    when a damaged record was skipped (directory fsynced after each step)."""
    final = out.finish({
        "source": part.name,
        "messages": str(result.messages),
        "source_bytes": str(result.source_bytes),
        "dropped_bytes": str(result.dropped_bytes),
        **({"lost_chunks": str(result.lost_chunks), "lost_messages": str(result.lost_messages)}
           if result.damaged else {}),
    }, durable)
    if durable:
        fsync_dir(part.parent)
    if result.damaged:
        result.kept = part.with_name(part.name + ".damaged")
        os.replace(part, result.kept)
    else:
        part.unlink()
    if durable:
        fsync_dir(part.parent)
    result.action, result.path = "salvaged", final


def _open_regular(part: Path, result: SalvageResult) -> BinaryIO | None:
    """``part`` open for reading when it is a regular file; else None with ``result``
    set to ``skipped`` (a FIFO is never waited on, a symbolic link never followed)."""
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(part, flags)
    except OSError as err:
        if err.errno != errno.ELOOP:
            raise
        result.action, result.reason = "skipped", "a symbolic link"
        return None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        kind = {stat.S_IFIFO: "a FIFO", stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a directory",
                stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device"}
        result.action, result.reason = "skipped", kind.get(stat.S_IFMT(mode), "special")
        return None
    os.set_blocking(fd, True)
    return os.fdopen(fd, "rb")


def salvage(part: str | Path, *, durable: bool = True,
            stop: threading.Event | None = None) -> SalvageResult:
    """Rewrite the complete chunks of a leftover ``.part`` file into a finished file.

    Reads ``part`` record by record (each length-checked before it is
    parsed); every complete chunk whose CRC and records check out is copied,
    compressed data unchanged, with its schemas and channels and a rebuilt
    message index, into ``<stem>.salvaged.mcap`` (written as
    ``<stem>.salvaged.mcap.tmp``, summary and footer added, fsynced, renamed,
    directory fsynced); then the ``.part`` is deleted. The scan ends at the
    first incomplete record (the unflushed tail), at a damaged one, or at the
    end of the data section of a file that was finished but not renamed.
    Metadata records are kept. A damaged record is skipped and the scan
    resumes at the next intact chunk; the ``.part`` is then kept as
    ``<name>.damaged``. A run of zero bytes to the end of the file from a record on (or from
    within the last chunk, a sector at least) is the file's cut (:func:`_zero_cut`). See
    :class:`SalvageResult` for what happens when nothing is recoverable, and for what is not
    a regular file. When
    ``stop`` is set the scan ends between records and the ``.part`` is left
    as it was (``"interrupted"``).

    Never raises on the file's content. Raises SinkIOError when it cannot be
    read or the salvaged file cannot be written (the ``.part`` is then left as
    it was, and a partial ``.tmp`` removed). ``durable=False`` skips the
    fsyncs (tests that salvage thousands of files).
    """
    part = Path(part)
    result = SalvageResult(source=part, action="removed")
    try:
        f = _open_regular(part, result)
        if f is None:
            return result
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
            try:
                valid = _copy_records(f, out, result, stop)
            except Interrupted:
                out.discard()
                result.action = "interrupted"
                return result
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


def salvage_leftovers(out_dir: str | Path, prefix: str, *, durable: bool = True,
                      stop: threading.Event | None = None) -> list[SalvageResult | SinkIOError]:
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
        if stop is not None and stop.is_set():
            break
        try:
            results.append(salvage(part, durable=durable, stop=stop))
        except SinkIOError as err:
            results.append(err)
    return results
