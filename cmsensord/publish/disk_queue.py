"""A bounded, crash-safe on-disk FIFO of MQTT messages, each with a sequence number.

Append-only segment files ``q-<first seq>.seg`` hold records
``<u32 body length><u32 CRC-32 of body>`` + body ``<u64 seq><u8 retain><u16 topic length>
topic payload``. Appends reach the OS at once and are fsync'd every ``fsync_s`` by
:meth:`DiskQueue.sync`, so a kill -9 (or power loss) loses at most that much; a torn record at
the end of a segment fails its length or CRC check and is cut off when the queue is opened.
The broker's acknowledgements move the ``acked`` cursor (file ``acked``, written with each sync);
segments wholly acknowledged are deleted. Beyond ``max_bytes`` the oldest segment is dropped
and its unsent records counted. Sending reads from the send cursor (:meth:`next_batch`), which a
reconnection rewinds to the first unacknowledged record, so every record is delivered in order,
at least once.

With ``wait_for_disk`` (the daemon), a directory on a full, failing or read-only file system
(:data:`DISK_FAULTS`) is no error at start: the queue opens with what it can read, and its
first append fails as on a disk that failed later (the publisher keeps messages in memory
until the directory takes them); a torn tail or an acknowledged segment it cannot remove
stays for the next start.
"""

from __future__ import annotations

import errno
import os
import struct
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

from cmsensord.sinks.mcap_file import fsync_dir, make_dirs

_HEAD = struct.Struct("<II")          # body length, CRC-32 of the body
_BODY = struct.Struct("<QBH")         # seq, retain, topic length
#: no record body is larger than this (a torn length field reads as garbage beyond it)
MAX_RECORD = 16 << 20
#: errno values of a full, failing or read-only file system (``wait_for_disk``: no error at start)
DISK_FAULTS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EROFS})


@dataclass(frozen=True)
class Record:
    """One queued message."""

    seq: int
    topic: str
    payload: bytes
    retain: bool


@dataclass
class _Segment:
    first: int          # seq of its first record
    path: Path
    size: int
    last: int           # seq of its last record (first - 1 when empty)


def _encode(rec: Record) -> bytes:
    topic = rec.topic.encode()
    body = _BODY.pack(rec.seq, int(rec.retain), len(topic)) + topic + rec.payload
    return _HEAD.pack(len(body), zlib.crc32(body)) + body


def _read_records(data: bytes) -> tuple[list[tuple[int, Record]], int]:
    """The valid records of a segment's bytes with their offsets, and where the valid part ends."""
    out, pos = [], 0
    while pos + _HEAD.size <= len(data):
        length, crc = _HEAD.unpack_from(data, pos)
        end = pos + _HEAD.size + length
        if length < _BODY.size or length > MAX_RECORD or end > len(data):
            break
        body = data[pos + _HEAD.size:end]
        if zlib.crc32(body) != crc:
            break
        seq, retain, tlen = _BODY.unpack_from(body)
        topic = body[_BODY.size:_BODY.size + tlen].decode(errors="replace")
        out.append((pos, Record(seq, topic, body[_BODY.size + tlen:], bool(retain))))
        pos = end
    return out, pos


class DiskQueue:
    """The store-and-forward queue in ``directory`` (created if missing; OSError if unusable,
    but for :data:`DISK_FAULTS` with ``wait_for_disk``: see the module docstring)."""

    def __init__(self, directory: str | os.PathLike, *, max_bytes: int, fsync_s: float = 1.0,
                 segment_bytes: int | None = None, wait_for_disk: bool = False) -> None:
        self.dir = Path(directory)
        self._wait_for_disk = wait_for_disk
        self._new_dirs: list[Path] = []         # their names fsynced into their parents at the first sync
        try:
            self._new_dirs = make_dirs(self.dir)
        except OSError as err:
            self._unless_waiting(err)           # made by the first segment (_new_segment)
        self.max_bytes, self.fsync_s = max_bytes, fsync_s
        self._new_name = False
        self.segment_bytes = segment_bytes or max(4096, min(1 << 20, max_bytes // 8))
        self.segments: list[_Segment] = []
        self.truncated_bytes = 0        # torn tails cut off at open
        self.dropped = 0                # records dropped by the bound, since start
        self._fd: int | None = None
        self._dirty = False
        self._synced_at = time.monotonic()
        self._acked_ids: set[int] = set()
        self._cache: tuple[Path | None, int, list[Record]] = (None, 0, [])
        self.acked = self._read_acked()
        self._acked_written = self.acked
        self._open_segments()
        last = self.segments[-1].last if self.segments else 0
        self.next_seq = max(last, self.acked) + 1
        self.send_seq = self.acked + 1

    # -- opening ---------------------------------------------------------------------------
    def _unless_waiting(self, err: OSError) -> None:
        """Raise ``err`` unless it is a disk fault the queue waits out (``wait_for_disk``)."""
        if not (self._wait_for_disk and err.errno in DISK_FAULTS):
            raise err

    def _read_acked(self) -> int:
        try:
            return int((self.dir / "acked").read_text().strip() or 0)
        except (OSError, ValueError):
            return 0

    def _open_segments(self) -> None:
        for path in sorted(self.dir.glob("q-*.seg")):
            data = path.read_bytes()
            records, valid = _read_records(data)
            if valid < len(data):               # a torn or corrupt tail: cut it off
                self.truncated_bytes += len(data) - valid
                try:                            # else never appended to (a new segment is) nor read
                    with open(path, "r+b") as f:
                        f.truncate(valid)
                except OSError as err:
                    self._unless_waiting(err)
            if not records or records[-1][1].seq <= self.acked:
                try:
                    path.unlink()
                except OSError as err:
                    self._unless_waiting(err)
                continue
            self.segments.append(_Segment(records[0][1].seq, path, valid, records[-1][1].seq))

    # -- writing ---------------------------------------------------------------------------
    def append(self, topic: str, payload_of, retain: bool) -> int:
        """Queue one message; ``payload_of(seq)`` gives its payload bytes. Returns its seq.
        OSError (a full disk) leaves the queue as it was."""
        seq = self.next_seq
        data = _encode(Record(seq, topic, payload_of(seq), retain))
        seg = self.segments[-1] if self.segments and self._fd is not None else None
        if seg is None or seg.size >= self.segment_bytes:
            seg = self._new_segment(seq)
        written = os.write(self._fd, data)      # type: ignore[arg-type]  # opened by _new_segment
        if written != len(data):                # a short write on a full disk: cut it off again
            os.ftruncate(self._fd, seg.size)    # type: ignore[arg-type]
            raise OSError(28, "No space left on device")
        seg.size += len(data)
        seg.last = seq
        self.next_seq = seq + 1
        self._dirty = True
        self._bound()
        return seq

    def _new_segment(self, first: int) -> _Segment:
        self._close_fd()
        path = self.dir / f"q-{first:020d}.seg"
        if not self.dir.is_dir():               # not made at start (wait_for_disk), or removed since
            self._new_dirs += make_dirs(self.dir)
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | getattr(os, "O_CLOEXEC", 0), 0o600)
        seg = _Segment(first, path, os.fstat(self._fd).st_size, first - 1)
        self.segments.append(seg)
        self._new_name = True               # its directory entry is made durable at the next sync
        return seg

    def _close_fd(self) -> None:
        if self._fd is not None:
            if self._dirty:
                os.fsync(self._fd)
            os.close(self._fd)
            self._fd = None

    def _bound(self) -> None:
        """Drop the oldest segments while the queue is larger than max_bytes (never the open one)."""
        while len(self.segments) > 1 and self.size_bytes > self.max_bytes:
            seg = self.segments.pop(0)
            unacked = seg.last - max(seg.first, self.acked + 1) + 1
            self.dropped += max(0, unacked)
            self._move_acked(max(self.acked, seg.last))
            seg.path.unlink(missing_ok=True)

    def sync(self, force: bool = False) -> None:
        """fsync the open segment and write the acked cursor, at most every ``fsync_s``."""
        now = time.monotonic()
        if not force and now - self._synced_at < self.fsync_s:
            return
        self._synced_at = now
        if self._dirty and self._fd is not None:
            os.fsync(self._fd)
            self._dirty = False
        if self.acked != self._acked_written:
            tmp = self.dir / "acked.tmp"
            tmp.write_text(f"{self.acked}\n")
            os.replace(tmp, self.dir / "acked")
            self._acked_written = self.acked
        if self._new_name:                  # once: a file system that refuses it refuses it again
            self._new_name = False
            for new in self._new_dirs:
                fsync_dir(new.parent)
            self._new_dirs = []
            fsync_dir(self.dir)

    def close(self) -> None:
        """Sync and close."""
        try:
            self.sync(force=True)
        finally:
            self._close_fd()

    # -- sending ---------------------------------------------------------------------------
    @property
    def size_bytes(self) -> int:
        return sum(s.size for s in self.segments)

    @property
    def depth(self) -> int:
        """Messages not yet acknowledged."""
        return self.next_seq - 1 - self.acked

    def rewind(self) -> None:
        """Send again from the first unacknowledged record (after a reconnection)."""
        self.send_seq = self.acked + 1

    def next_batch(self, n: int) -> list[Record]:
        """Up to ``n`` records from the send cursor, in order; the cursor moves past them."""
        out: list[Record] = []
        for seg in self.segments:
            if len(out) >= n:
                break
            if seg.last < self.send_seq:
                continue
            records = self._records(seg)
            start = max(0, self.send_seq - seg.first)      # seqs are contiguous in a segment
            for rec in records[start:start + n - len(out)]:
                out.append(rec)
                self.send_seq = rec.seq + 1
        return out

    def _records(self, seg: _Segment) -> list[Record]:
        """The records of ``seg``, parsed once: the last segment read is kept, and only what
        was appended to it since is read again."""
        path, done, records = self._cache
        if path != seg.path:
            path, done, records = seg.path, 0, []
        if done < seg.size:
            with open(seg.path, "rb") as f:
                f.seek(done)
                more, valid = _read_records(f.read(seg.size - done))
            records.extend(r for _, r in more)
            done += valid
        self._cache = (path, done, records)
        return records

    def ack(self, seq: int) -> None:
        """The broker acknowledged ``seq``: the cursor moves over every contiguous acknowledgement
        and wholly acknowledged segments are deleted."""
        if seq <= self.acked:
            return
        self._acked_ids.add(seq)
        acked = self.acked
        while acked + 1 in self._acked_ids:
            acked += 1
            self._acked_ids.discard(acked)
        self._move_acked(acked)

    def _move_acked(self, acked: int) -> None:
        self.acked = acked
        self._acked_ids = {s for s in self._acked_ids if s > acked}
        self.send_seq = max(self.send_seq, acked + 1)
        while self.segments and self.segments[0].last <= acked and (
                len(self.segments) > 1 or self._fd is None):
            self.segments.pop(0).path.unlink(missing_ok=True)
