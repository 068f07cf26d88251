"""A bounded, crash-safe on-disk FIFO of MQTT messages, each with a sequence number.

Append-only segment files ``q-<first seq>.seg`` hold records
``<u32 body length><u32 CRC-32 of body>`` + body ``<u64 seq><u8 retain><u16 topic length>
topic payload`` (:mod:`.queue_records`). Appends reach the OS at once and are fsync'd every ``fsync_s`` by
:meth:`DiskQueue.sync`, so a kill -9 (or power loss) loses at most that much. When the queue is
opened, a record that fails its length or CRC check is skipped and reading goes on at the next
valid record (the next offset where a length and a CRC check out, with a higher seq), so a
damaged record costs itself only; damaged bytes at the end of a segment are cut off (at the end
of the newest, a torn record: what a crash while writing leaves; every seq its bytes could have
held is retired). The seq of a damaged record is neither sent nor used again; the acknowledged
cursor moves over it. Only regular files named ``q-<20 digits>.seg`` are segments: another
entry so named (a directory) is left alone and listed in :attr:`DiskQueue.strays`. An ``acked``
file that cannot be read is :attr:`DiskQueue.cursor_error`: everything kept is sent again, from
the oldest segment.
The broker's acknowledgements move the ``acked`` cursor (file ``acked``, written with each sync);
segments wholly acknowledged are deleted. Beyond ``max_bytes`` the oldest segment is dropped
and its unsent records counted. Sending reads from the send cursor (:meth:`next_batch`), which a
reconnection rewinds to the first unacknowledged record, so every record is delivered in order,
at least once. A record the disk refuses (full, failing, read-only) is held in memory, sent
from there, and written before any later one once the disk takes data again
(:data:`HOLD_BYTES` at most, the oldest dropped and counted); held records not written by
:meth:`DiskQueue.close` are lost. Seqs are leased ahead on disk (:mod:`.seq_lease`): a run
never gives a seq a run before it may have sent to another message.

With ``wait_for_disk`` (the daemon), a directory on a full, failing or read-only file system
(:data:`DISK_FAULTS`) is no error at start: the queue opens with what it can read, and its
appends are held in memory as on a disk that failed later; a torn tail or an acknowledged
segment it cannot remove stays for the next start.
"""

from __future__ import annotations

import bisect
import collections
import contextlib
import errno
import os
import re
import stat
import time
from dataclasses import dataclass
from pathlib import Path

from cmsensord.publish.queue_records import SHORTEST, Record, Scan, encode, read_records
from cmsensord.publish.seq_lease import SeqLease
from cmsensord.sinks.mcap_file import fsync_dir, make_dirs

#: the most payload bytes held in memory while the disk refuses them (and at most ``max_bytes``)
HOLD_BYTES = 4 << 20
#: the name of a segment: ``q-<the seq of its first record, 20 digits>.seg``
_SEGMENT_NAME = re.compile(r"q-([0-9]{20})\.seg")
#: errno values of a full, failing or read-only file system (``wait_for_disk``: no error at start)
DISK_FAULTS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EROFS})


@dataclass
class _Segment:
    first: int          # seq of its first record
    path: Path
    size: int
    last: int           # seq of its last record (first - 1 when empty)
    named: int          # the seq its name gives (its first record's, unless that was damaged)


def _not_a_segment(path: Path) -> str | None:
    """What ``path`` is when it is not a segment file (a regular file named as the queue names
    them), else None."""
    if not _SEGMENT_NAME.fullmatch(path.name):
        return "named unlike its segments (q-<first seq in 20 digits>.seg)"
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "a broken symbolic link"
    if stat.S_ISDIR(mode):
        return "a directory"
    return None if stat.S_ISREG(mode) else "a special file (FIFO, socket or device)"


def _held_size(rec: Record) -> int:
    """What a record held in memory takes, about: its payload and topic, and the objects'."""
    return len(rec.payload) + len(rec.topic) + 200



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
        self.truncated_bytes = 0        # a torn tail of the newest segment, cut off at open
        self.torn_seqs = 0              # the seqs retired with it (as many as it could hold records)
        self.damaged_bytes = 0          # other damaged bytes skipped at open (see _open_segments)
        self.damaged_records = 0        # the records they held: seqs missing between valid ones
        self.strays: list[tuple[Path, str]] = []    # entries named like segments that are not one, and what
        self._taken: set[int] = set()   # the first seqs of segment names a stray holds
        self.dropped = 0                # records dropped by the bound, since start
        self._fd: int | None = None
        self._dirty = False
        self._synced_at = time.monotonic()
        self._acked_ids: set[int] = set()
        self._gaps: list[range] = []    # seqs above the cursor that no record holds (damaged, torn)
        self._cache: tuple[Path | None, int, list[Record]] = (None, 0, [])
        self._held: collections.deque[Record] = collections.deque()    # appended, not on the disk yet
        self._held_bytes = 0
        self.write_error: OSError | None = None     # why the disk refused the oldest held record
        self.acked, self.cursor_error = self._read_acked()
        self._acked_written = self.acked if self.cursor_error is None else -1    # rewritten at the first sync
        self.next_seq = max(self._open_segments(), self.acked + 1)
        self.lease = SeqLease(self.dir)         # seqs a run before may have sent from memory
        if self.lease.upto >= self.next_seq:
            self._lose(self.next_seq, self.lease.upto + 1, False)
            self.next_seq = self.lease.upto + 1
        while self.next_seq in self._taken:     # the first segment's name is a stray's: the seq is skipped
            self._lose(self.next_seq, self.next_seq + 1, False)
            self.next_seq += 1
        self.send_seq = self.acked + 1
        # what precedes the oldest segment was acknowledged or dropped: a cursor behind it moves up
        floor = min(self.segments[0].named, self.segments[0].first) - 1 if self.segments else 0
        self._move_acked(max(self.acked, floor))

    # -- opening ---------------------------------------------------------------------------
    def _unless_waiting(self, err: OSError) -> None:
        """Raise ``err`` unless it is a disk fault the queue waits out (``wait_for_disk``)."""
        if not (self._wait_for_disk and err.errno in DISK_FAULTS):
            raise err

    def _read_acked(self) -> tuple[int, str | None]:
        """The acknowledged cursor (file ``acked``; 0 before there is one) and, when the file
        cannot be read as one, why (the cursor is then 0: the queue sends from its oldest)."""
        try:
            text = (self.dir / "acked").read_text(encoding="ascii").strip()
        except FileNotFoundError:
            return 0, None
        except OSError as err:
            return 0, err.strerror or str(err)
        except ValueError:                      # not ASCII
            return 0, "not a number"
        if not text:
            return 0, "empty"
        if not re.fullmatch(r"[0-9]+", text):
            return 0, f"not a number: {text[:20]!r}"
        return int(text), None

    def _segment_paths(self) -> list[Path]:
        """The segment files, oldest first; an entry named like one that is not (a directory, a
        broken link, a FIFO, a file named otherwise) is left alone and listed in :attr:`strays`."""
        paths = []
        for path in sorted(self.dir.glob("q-*.seg")):
            what = _not_a_segment(path)
            if what is None:
                paths.append(path)
                continue
            self.strays.append((path, what))
            if _SEGMENT_NAME.fullmatch(path.name):
                self._taken.add(int(path.name[2:22]))
        return paths

    def _open_segments(self) -> int:
        """Read the segments, oldest first, and return the next seq. A damaged record is
        skipped, the valid ones after it kept: its bytes count in :attr:`damaged_bytes` and the
        seqs missing where it was in :attr:`damaged_records`. Damaged bytes after the last valid
        record are cut off: at the end of the newest segment a torn record (what a crash while
        writing leaves; :attr:`truncated_bytes`), whose seqs are not used again: as many as the
        tail could hold records (a power cut may zero-fill the records of the last ``fsync_s``,
        sent already from the page cache). Seqs no record
        holds are never sent; a segment with nothing unacknowledged is deleted."""
        paths = self._segment_paths()
        expect, hurt, tail = 0, False, 0        # the next seq; damage since the last valid record
        for i, path in enumerate(paths):
            named = int(path.name[2:22])
            if expect and named > expect:       # the end of the segment before was damaged
                self._lose(expect, named, hurt)
                hurt = False
            expect = max(expect, named)
            data = path.read_bytes()
            scan = read_records(data, named - 1)
            ends = {end for _, end in scan.damaged}
            for offset, rec in scan.records:
                hurt = hurt or offset in ends
                self._lose(expect, rec.seq, hurt)
                hurt, expect = False, max(expect, rec.seq + 1)
            tail = len(data) - scan.valid
            damaged = sum(end - start for start, end in scan.damaged)
            newest = i == len(paths) - 1
            self.truncated_bytes += tail if newest else 0
            self.damaged_bytes += damaged - (tail if newest else 0)
            hurt = hurt or tail > 0
            self._keep(path, scan, named, tail)
        if hurt:                                # the torn records' seqs: they may have been sent
            self.torn_seqs = max(1, -(-tail // SHORTEST))
            self._lose(expect, expect + self.torn_seqs, False)
            expect += self.torn_seqs
        return expect or 1

    def _lose(self, start: int, stop: int, damaged: bool) -> None:
        """Seqs ``start`` to ``stop`` - 1 are held by no record; ``damaged``: by damaged ones."""
        if stop > start:
            gaps = self._gaps                   # in order of their starts (:meth:`_over_gaps`)
            if gaps and gaps[-1].stop == start:         # one range for a run of them
                gaps[-1] = range(gaps[-1].start, stop)
            elif not gaps or gaps[-1].start < start:
                gaps.append(range(start, stop))
            else:
                bisect.insort(gaps, range(start, stop), key=lambda g: g.start)
            self.damaged_records += (stop - start) * damaged

    def _keep(self, path: Path, scan: Scan, named: int, tail: int) -> None:
        """A segment read: its damaged tail cut off, then deleted if nothing in it is unacknowledged,
        else kept."""
        if tail:
            try:                                # else never appended to (a new segment is) nor read
                with open(path, "r+b") as f:
                    f.truncate(scan.valid)
            except OSError as err:
                self._unless_waiting(err)
        records = scan.records
        if not records or records[-1][1].seq <= self.acked:
            try:
                path.unlink()
            except OSError as err:
                self._unless_waiting(err)
            return
        self.segments.append(_Segment(records[0][1].seq, path, scan.valid, records[-1][1].seq, named))

    # -- writing ---------------------------------------------------------------------------
    def append(self, topic: str, payload_of, retain: bool, bound: bool = True) -> int:
        """Queue one message; ``payload_of(seq)`` gives its payload bytes. Returns its seq. It is
        held in memory until the disk takes it (:meth:`write_held`): sent from there meanwhile;
        ``bound``: the oldest held records are dropped past their bound (a caller that waits
        while the queue is :attr:`full` passes False: it may pass the bound by this record)."""
        seq = self.next_seq
        rec = Record(seq, topic, payload_of(seq), retain)
        self.next_seq = seq + 1
        self._held.append(rec)
        self._held_bytes += _held_size(rec)
        if bound:
            self._bound_held()
        self.write_held()                       # the directory made again, if it must be
        self.lease.cover(seq)                   # before anything sends it
        return seq

    def write_held(self) -> None:
        """The records held in memory to the disk, oldest first (those acknowledged meanwhile need
        it no more), until it refuses one: :attr:`write_error` is then why (None once it takes one)."""
        held = self._held
        while held:
            if held[0].seq > self.acked:
                try:
                    self._write(held[0])
                except OSError as err:
                    self.write_error = err
                    return
                self.write_error = None
            self._held_bytes -= _held_size(held.popleft())

    def _bound_held(self) -> None:
        """Drop the oldest held records, counted, while they take more than :data:`HOLD_BYTES`
        (and ``max_bytes``): a disk refusing them for long."""
        while self.held_full and len(self._held) > 1:
            rec = self._held.popleft()
            self._held_bytes -= _held_size(rec)
            if rec.seq > self.acked:            # unacknowledged: a rewind cannot send it again
                self.dropped += 1
                self._lose(rec.seq, rec.seq + 1, False)

    @property
    def held_full(self) -> bool:
        """The records held in memory take :data:`HOLD_BYTES` (or ``max_bytes``) or more."""
        return self._held_bytes >= min(HOLD_BYTES, self.max_bytes)

    @property
    def full(self) -> bool:
        """Another record could make the bounds drop an unacknowledged one: the held records at
        their bound, or the segments within one segment of ``max_bytes`` while any is unacknowledged."""
        return self.held_full or (self.depth > 0 and self.size_bytes + self.segment_bytes > self.max_bytes)

    def _write(self, rec: Record) -> None:
        """``rec`` appended to the newest segment (a new one when it is full); OSError (a full
        disk) leaves the segment as it was."""
        data = encode(rec)
        seg = self.segments[-1] if self.segments and self._fd is not None else None
        if seg is None or (seg.size >= self.segment_bytes and rec.seq not in self._taken):
            seg = self._new_segment(rec.seq)
        written = os.write(self._fd, data)      # type: ignore[arg-type]  # opened by _new_segment
        if written != len(data):                # a short write on a full disk: cut it off again
            os.ftruncate(self._fd, seg.size)    # type: ignore[arg-type]
            raise OSError(28, "No space left on device")
        seg.size += len(data)
        seg.last = rec.seq
        self._dirty = True
        self._bound()

    def _new_segment(self, first: int) -> _Segment:
        self._close_fd()
        path = self.dir / f"q-{first:020d}.seg"
        if not self.dir.is_dir():               # not made at start (wait_for_disk), or removed since
            self._new_dirs += make_dirs(self.dir)
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | getattr(os, "O_CLOEXEC", 0), 0o600)
        seg = _Segment(first, path, os.fstat(self._fd).st_size, first - 1, first)
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
            self.dropped += max(0, seg.last - self.acked - self._missing(seg.last))
            self._move_acked(max(self.acked, seg.last))
            with contextlib.suppress(OSError):      # a read-only disk: left for the next start
                seg.path.unlink(missing_ok=True)

    def sync(self, force: bool = False) -> bool:
        """fsync the open segment and write the acked cursor, at most every ``fsync_s``: whether
        it did (OSError: it could not)."""
        now = time.monotonic()
        if not force and now - self._synced_at < self.fsync_s:
            return False
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
        return True

    @property
    def held_unsent(self) -> int:
        """Held records the broker has not acknowledged: lost at the stop if the disk refuses them
        (read from any thread: the deque copied at once)."""
        acked = self.acked
        return sum(rec.seq > acked for rec in list(self._held))

    def close(self) -> None:
        """Write what is held, sync, bring the seq lease down to what was used, and close; a disk
        that refuses it is no error here (:attr:`write_error` says why, :attr:`held_unsent` what
        is lost)."""
        try:
            self.write_held()
            self.sync(force=True)
        except OSError as err:
            self.write_error = err
        finally:
            self.lease.close(self.next_seq)
            with contextlib.suppress(OSError):
                self._close_fd()

    # -- sending ---------------------------------------------------------------------------
    @property
    def size_bytes(self) -> int:
        return sum(s.size for s in self.segments)

    @property
    def depth(self) -> int:
        """Messages not yet acknowledged."""
        return self.next_seq - 1 - self.acked - self._missing(self.next_seq)

    def _missing(self, last: int) -> int:
        """How many seqs above the cursor and up to ``last`` no record holds."""
        return sum(len(gap[:max(0, last - gap.start + 1)]) for gap in self._gaps)

    def rewind(self) -> None:
        """Send again from the first unacknowledged record (after a reconnection)."""
        self.send_seq = self.acked + 1

    def next_batch(self, n: int) -> list[Record]:
        """Up to ``n`` records from the send cursor, in order; the cursor moves past them."""
        out: list[Record] = []
        for seg in list(self.segments):         # a copy: a segment found gone is taken out (:meth:`_gone`)
            if len(out) >= n:
                break
            if seg.last < self.send_seq:
                continue
            try:
                records = self._records(seg)
            except FileNotFoundError:           # deleted under the daemon: its records are lost
                self._gone(seg)
                continue
            start = bisect.bisect_left(records, self.send_seq, key=lambda r: r.seq)
            for rec in records[start:start + n - len(out)]:
                out.append(rec)
                self.send_seq = rec.seq + 1
        for rec in self._held:
            if len(out) >= n:
                break
            if rec.seq >= self.send_seq:
                out.append(rec)
                self.send_seq = rec.seq + 1
        return out

    def _gone(self, seg: _Segment) -> None:
        """Segment ``seg`` deleted from under the queue: its unacknowledged records counted as
        dropped, their seqs as held by no record."""
        newest = seg is self.segments[-1]
        self.segments.remove(seg)
        self.dropped += max(0, seg.last - max(self.acked, seg.first - 1) - self._missing(seg.last))
        self._lose(max(self.acked + 1, seg.first), seg.last + 1, False)
        if newest and self._fd is not None:     # the next record starts a new segment
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None

    def _records(self, seg: _Segment) -> list[Record]:
        """The records of ``seg``, parsed once: the last segment read is kept, and only what
        was appended to it since is read again."""
        path, done, records = self._cache
        if path != seg.path:
            path, done, records = seg.path, 0, []
        if done < seg.size:
            with open(seg.path, "rb") as f:
                f.seek(done)
                scan = read_records(f.read(seg.size - done), records[-1].seq if records else seg.named - 1)
            records.extend(r for _, r in scan.records)
            done += scan.valid
        self._cache = (path, done, records)
        return records

    def ack(self, seq: int) -> None:
        """The broker acknowledged ``seq``: the cursor moves over every contiguous acknowledgement
        and wholly acknowledged segments are deleted."""
        if seq <= self.acked:
            return
        self._acked_ids.add(seq)
        acked = self._over_gaps(self.acked)
        while acked + 1 in self._acked_ids:
            acked = self._over_gaps(acked + 1)
        self._move_acked(acked)

    def _over_gaps(self, acked: int) -> int:
        """``acked`` moved over the seqs right after it that no record holds (none is sent)."""
        for gap in self._gaps:
            if gap.start > acked + 1:
                break
            acked = max(acked, gap.stop - 1)
        return acked

    def _move_acked(self, acked: int) -> None:
        self.acked = acked = self._over_gaps(acked)
        self._acked_ids = {s for s in self._acked_ids if s > acked}
        self._gaps = [gap[max(0, acked + 1 - gap.start):] for gap in self._gaps if gap.stop - 1 > acked]
        self.send_seq = max(self.send_seq, acked + 1)
        while self._held and self._held[0].seq <= acked:       # needs the disk no more
            self._held_bytes -= _held_size(self._held.popleft())
        while self.segments and self.segments[0].last <= acked and (
                len(self.segments) > 1 or self._fd is None):
            with contextlib.suppress(OSError):      # a read-only disk: left for the next start
                self.segments.pop(0).path.unlink(missing_ok=True)
