"""The rotating sink's disk outages (a base of :class:`~cmsensord.sinks.rotating.RotatingSink`).

Disk errors: no OSError ever leaves the sink. A failing operation (open, write, flush,
fsync, close) abandons the file: closed without another byte, kept as ``.part`` when it
holds complete chunks (salvaged when logging is back, or at the next start), else deleted. A
salvage the still-full disk refuses (ENOSPC, EDQUOT), of such a file or of an earlier run's
leftover at start, is tried again after each rotation, once the free space holds the file
(:meth:`DiskOutages._salvage_waiting`); at a stop what still waits is left for the next start,
one journal line.
A failed fsync is never retried on the same file. A new file is tried at once, then every
``retry_s``; messages written while no file is open, and those of the chunk that could
not be written, are counted in :attr:`dropped`. Logging counts as back when a new file has been
fsynced with messages in it (a full disk takes a header; a file of a header alone is fsynced once,
then at the next tick after a message). One ``disk_error`` event per outage, one when logging
resumes (the count).
A full or failing disk at start (for the daemon, ``wait_for_disk``, a read-only one too) is
such an outage, and so is, at any time, the output directory off the device it was on at start
(unmounted: nothing is made on the file system under it, :mod:`cmsensord.sinks.log_dir`); any
other reason the first file cannot be opened is a SinkError.
"""

from __future__ import annotations

import collections
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from cmsensord.config import OutputConfig
from cmsensord.sinks import disk_events
from cmsensord.sinks.mcap_file import McapSink, SinkIOError, moved_error
from cmsensord.sinks.mcap_salvage import SalvageResult
from cmsensord.sinks.retention import DISK_EVENT, file_sizes, free_bytes

if TYPE_CHECKING:
    from cmsensord.sinks.rotating import RotatingSink

__all__ = ["DiskOutages"]

_FULL = disk_events.FULL


class DiskOutages:
    """A failing disk: the file abandoned, one event per outage, a new file tried at once and
    then every ``retry_s``, logging back once a new file is fsynced with messages in it."""

    output: OutputConfig
    clock: Callable[[], float]
    device: Any
    dropped: int
    disk_errors: int
    _current: McapSink | None
    _closed: bool
    _event_dirty: bool
    _need_sync: bool
    _outage: dict[str, Any] | None
    _next_retry: float
    _last_errno: int | None
    _abandoned: list[Path]
    _salvage_told: set[Path]
    _salvaged: collections.deque[SalvageResult | SinkIOError]

    if TYPE_CHECKING:
        def emit(self, kind: str, message: str, **fields: Any) -> None: ...
        def _open(self) -> McapSink: ...
        def _retention(self) -> None: ...
        @property
        def path(self) -> Path | None: ...

    @property
    def logging(self) -> bool:
        """A file is open and no outage is in progress."""
        return self._current is not None and self._outage is None

    def outage_state(self) -> str:
        """"" while logging; during a disk outage, one phrase for the status line."""
        return "" if self._outage is None else disk_events.outage_state(self._outage, self.clock())

    def _drop(self, n: int) -> None:
        self.dropped += n
        if self._outage is not None:
            self._outage["dropped"] += n

    def _check_present(self, cur: McapSink) -> bool:
        """After each flush: True while the open file is still in the output directory; a file
        (or directory) removed under the daemon is reported, with every message written to
        it as lost, and logging goes on in a new file (the directory made again); a directory
        no longer on its device (unmounted) is an outage until it is back."""
        try:
            os.stat(cur.part_path)
            return True
        except FileNotFoundError:
            pass
        except OSError:
            return True                      # not known to be gone: the next write tells
        moved = moved_error(self.output.dir, self.device)
        if moved is not None:                # its file system is gone: the file kept for salvage
            self._failed(moved, cur)
            return False
        lost = cur.messages_written
        cur.abandon()
        self._current = None
        self._drop(lost)
        self._event_dirty = self._need_sync = False
        text, fields = disk_events.removed(cur.part_path, lost)
        self.emit(DISK_EVENT, text, **fields)
        self._next_retry = self.clock()
        self._retry_if_due()
        return False

    def _failed(self, err: SinkIOError, cur: McapSink | None) -> None:
        """Abandon ``cur`` (if any) after ``err``; event at the start of an outage; retry."""
        self.disk_errors += 1
        self._last_errno = err.errno
        now = self.clock()
        lost = unsure = 0
        kept: Path | None = None
        if cur is not None:
            lost = cur.unpersisted
            unsure = cur.unsynced if err.op == "fsync" else 0
            persisted = cur.persisted
            part = cur.abandon()
            if self._current is cur:
                self._current = None
            if persisted:
                kept = part
                self._abandoned.append(part)
            else:
                try:                         # a header alone: nothing to salvage
                    part.unlink(missing_ok=True)
                except OSError:
                    kept = part
        self._event_dirty = self._need_sync = False
        first = self._outage is None
        if self._outage is None:
            self._outage = {"start": now, "dropped": 0, "errors": 0, "error": str(err)}
        outage = self._outage
        self._drop(lost)
        outage["errors"] += 1
        if first:
            text, fields = disk_events.abandoned(err, kept, cur is not None, lost, unsure, self.output.retry_s)
            self.emit(DISK_EVENT, text, **fields)
        if err.errno in _FULL:
            self._retention()
        # a new file at once at the start of an outage (a failed fsync needs nothing
        # else), then every retry_s: a disk that keeps failing gets one file per retry_s
        self._next_retry = now if first else now + self.output.retry_s
        self._retry_if_due()

    def _retry_if_due(self) -> None:
        if self._closed or self._current is not None:
            return
        now = self.clock()
        if now < self._next_retry:
            return
        self._next_retry = now + self.output.retry_s
        if self._last_errno in _FULL:
            self._retention()
        try:
            self._current = self._open()
        except SinkIOError as err:
            self.disk_errors += 1
            self._last_errno = err.errno
            if self._outage is not None:
                self._outage["errors"] += 1
            else:                            # cannot happen: a file was lost before
                self._failed(err, None)
            return
        self._need_sync = True               # logging is back once this file is fsynced

    def _resumed(self) -> None:
        outage, self._outage = self._outage, None
        assert outage is not None
        self._last_errno = None
        where = self.path.name if self.path is not None else "the log"
        text, fields = disk_events.resumed(where, outage, self.clock() - outage["start"])
        self.emit(DISK_EVENT, text, **fields)
        self._take_salvaged()
        abandoned, self._abandoned = self._abandoned, []
        waiting = disk_events.salvage_abandoned(cast("RotatingSink", self), abandoned)
        self._abandoned = [*waiting, *self._abandoned]

    def _salvage_waiting(self) -> None:
        """After a rotation finished a file (the disk took a whole file, and retention made room):
        the abandoned files a full disk refused to salvage, tried again; one larger than the free
        space (its copy would not fit) waits, untried. None during an outage or after close."""
        self._take_salvaged()
        if self._closed or self._outage is not None or not self._abandoned:
            return
        try:
            free: int | None = free_bytes(self.output.dir)
        except OSError:
            free = None                      # not known: tried
        sizes = file_sizes(self._abandoned)      # one gone is tried: salvage drops it
        tried = [p for p in self._abandoned if free is None or sizes.get(p, 0) <= free]
        if tried:
            waiting = disk_events.salvage_abandoned(cast("RotatingSink", self), tried)
            self._abandoned = [p for p in self._abandoned if p not in tried or p in waiting]

    def _take_salvaged(self) -> None:
        """The results of the salvage of an earlier run's leftovers, in order: each one's event
        and count (:func:`~.disk_events.salvage_result`), but a leftover the full disk refused,
        still there, joins the abandoned files (counted and said once, :func:`~.disk_events.refused`).
        Called by the thread that writes (a tick, a rotation, logging resumed, close, the start
        after a salvage in the foreground), never by the salvage thread: that thread only appends
        its results to :attr:`_salvaged`, a deque (append and popleft are atomic), so it never
        touches ``_abandoned``, ``_salvage_told``, ``disk_errors`` or the events, which this thread
        reads and updates with no lock (a lock would have to be taken around every use of them,
        salvages of minutes included)."""
        sink = cast("RotatingSink", self)
        while self._salvaged:
            result = self._salvaged.popleft()
            if isinstance(result, SinkIOError) and result.errno in _FULL and result.path.exists():
                self._abandoned.append(result.path)
                disk_events.refused(sink, result, result.path)
            else:                            # a refused file removed meanwhile: a failed salvage
                disk_events.salvage_result(sink, result)
