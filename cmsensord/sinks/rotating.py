"""The daemon's log writer: MCAP files rotated, flushed, fsynced, salvaged and kept within bounds.

Owns the policy of ``output`` in the configuration; each file is an
:class:`~cmsensord.sinks.mcap_file.McapSink` (``*.mcap.part``, renamed to ``*.mcap`` when
finished). Rotation happens between messages, so no message is split across files; a file
opened by a rotation that gets no message before :meth:`RotatingSink.close` is deleted, never
finished empty. Each file is in log-time order (:mod:`cmsensord.sinks.reorder`: late messages
are held back up to the lag they come with, at most 10 s unless a longer one is expected in a
replay; the lag carries over to the next file, :mod:`.reorder_lag`). Messages held there are
not yet in the file: what the durability rules below say of "the messages of the last second"
covers them only in a stream that comes in order (RMS mode); in RAW mode with order tracking add the
orders' lag (a few seconds), with captures their ``post_s`` and 2 s, except while the link is quiet
(:meth:`RotatingSink.release_held`).

Durability (with :meth:`RotatingSink.tick` called once per loop iteration, as
the live loop does):

* the open chunk is written to the kernel early enough that a kill -9 loses at
  most the messages of the last ``flush_s``, though a loaded machine delays ticks
  and the reorder window holds messages (:mod:`cmsensord.sinks.flush_margin`);
* the file is fsynced every ``fsync_s``, and at the first tick after an event
  of :data:`~cmsensord.sinks.durable.FSYNC_AT_ONCE` (failures, alarms, the disk ...;
  routine ones ride ``fsync_s``): it is on stable storage by the end of the loop
  iteration that wrote it, or of the next one when raised after that iteration's
  tick (at most one fsync per iteration, so a burst of events costs one fsync);
* a new file's directory is fsynced once it is created (its name is durable before its data);
  a finished file is fsynced, renamed and its directory fsynced.

Start: leftover ``<prefix>-*.mcap.part`` files (a crash, a kill, a disk error) are salvaged
(:func:`~cmsensord.sinks.mcap_salvage.salvage`) into ``<stem>.salvaged.mcap`` before the first
file is opened, or, with ``background_salvage``, by a thread while the first file is written (the
daemon: start-up never waits for it); then retention runs. A leftover whose salvage the full disk
refuses waits for room like a file abandoned during the run (:mod:`cmsensord.sinks.disk_outage`).
:meth:`RotatingSink.stop_salvage` (the daemon on SIGTERM) stops that thread between two records and
leaves the ``.part`` it was reading as it was, for the next start; :meth:`RotatingSink.close` waits
for the thread. Retention (after each rotation, at start and on a full disk):
:mod:`cmsensord.sinks.retention`.

Disk errors: no OSError ever leaves this class; a failing disk is an outage
(:mod:`cmsensord.sinks.disk_outage`). The sink's events: :mod:`cmsensord.sinks.sink_events`.
"""

from __future__ import annotations

import collections
import contextlib
import errno
import logging
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from cmsensord.config import OutputConfig
from cmsensord.errors import SinkError
from cmsensord.sinks import disk_events
from cmsensord.sinks.disk_events import SALVAGE_EVENT  # noqa: F401  (the event kinds: disk_events)
from cmsensord.sinks.disk_outage import DiskOutages
from cmsensord.sinks.durable import urgent, urgent_in
from cmsensord.sinks.flush_margin import FlushMargin
from cmsensord.sinks.log_dir import place_of
from cmsensord.sinks.mcap_file import McapSink, SinkIOError
from cmsensord.sinks.mcap_salvage import SalvageResult, salvage_leftovers
from cmsensord.sinks.reorder_lag import ReorderLag
from cmsensord.sinks.retention import MB, RetentionTold, apply_retention, still_there
from cmsensord.sinks.sink_events import SinkEvents

log = logging.getLogger("cmsensord")

#: errno values that mean the disk is full or failing rather than misconfigured: at
#: start the sink then runs without a file and retries (at run time every error does)
_TRANSIENT = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EIO})
#: ... with ``wait_for_disk`` (the daemon), a read-only file system too (an SD card the kernel
#: remounted read-only after errors: it must not keep the service from restarting)
_WAITED = _TRANSIENT | {errno.EROFS}
_QUEUED_EVENTS = 1000


class RotatingSink(SinkEvents, DiskOutages, ReorderLag):
    """``write``/``flush``/``close`` like McapSink, over a sequence of files; never raises
    an OSError (see the module docstring).

    Args:
        output: the ``output`` configuration.
        metadata: written into every file as the ``cmsensord`` metadata record.
        clock: monotonic seconds (injectable for tests).
        on_rotate: called with each finished file's path.
        on_event: ``on_event(kind, message, **fields)``; may be set later.
        salvage: salvage leftover ``.part`` files at start.
        background_salvage: ... in a thread, after the first file is open.
        wall_clock: Unix seconds, for the file names.
        max_lag_s: the longest lag :meth:`expect_lag` opens the reorder window to.
        wait_for_disk: a read-only file system (EROFS) at start is an outage too (the daemon).

    Raises:
        SinkError: at start, when the output directory cannot be used for a
            reason other than a full or failing disk, or with ``wait_for_disk`` a
            read-only one (permissions, not a directory): a configuration error, one line.
    """

    def __init__(self, output: OutputConfig, *, metadata: dict[str, str] | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 on_rotate: Callable[[Path], None] | None = None,
                 on_event: Callable[..., Any] | None = None,
                 salvage: bool = True,
                 wall_clock: Callable[[], float] = time.time,
                 background_salvage: bool = False, max_lag_s: float | None = None,
                 wait_for_disk: bool = False, own_files: bool = False):
        self.output = output
        self.own_files = own_files           # retention counts and deletes this run's files only
        self.lock: Any = None                # the output directory's hold (a replay's): release lets it go
        self.max_lag_s = self.max_lag_s if max_lag_s is None else max_lag_s
        self.metadata, self.clock, self.wall_clock, self.on_rotate = metadata or {}, clock, wall_clock, on_rotate
        self.paths: list[Path] = []          # finished files still there, oldest first
        self.messages_written = 0            # messages handed to write()
        self.dropped = 0                     # ... of which not in any file (disk errors)
        self.disk_errors = 0                 # failed operations, retries included
        self._rotate_bytes = int(output.rotate_mb * MB)
        self._pending: collections.deque[tuple[str, str, dict]] = collections.deque(maxlen=_QUEUED_EVENTS)
        self._on_event = on_event
        #: called when an event is queued or the salvage thread hands its results over: the live
        #: loop wakes and ticks
        self.wake: Callable[[], Any] | None = None
        self._delivering = False
        self._closed = False
        self._current: McapSink | None = None
        self._event_dirty = False            # an urgent event was written since the last fsync
        self._need_sync = False              # fsync at the next tick (a new file after an error)
        now = clock()
        self._last_sync = now
        self._margin = FlushMargin(output.flush_s, now)
        self._opened = now
        # outage state
        self._outage: dict[str, Any] | None = None
        self._next_retry = now
        self._last_errno: int | None = None
        self._abandoned: list[Path] = []      # kept for salvage: an outage's, or waiting for room
        self._salvage_told: set[Path] = set()   # ... whose salvage the full disk refused, said once
        #: the leftovers' salvage results, handed to the writing thread (:meth:`_take_salvaged`)
        self._salvaged: collections.deque[SalvageResult | SinkIOError] = collections.deque()
        self.retention = RetentionTold()    # what retention said once and does not repeat
        self.device = place_of(output.dir)   # files are made on this device only
        self._salvage_stop = threading.Event()
        self._salvager: threading.Thread | None = None
        if salvage and not background_salvage:
            self._salvage_leftovers()
            self._take_salvaged()
        self._retention()
        try:
            self._current = self._open()
        except SinkIOError as err:
            if err.errno not in (_WAITED if wait_for_disk else _TRANSIENT):
                raise                        # misconfigured: the daemon stops with one line
            self._failed(err, None)
        if salvage and background_salvage:   # the file being written is flock'ed: left alone
            self._salvager = threading.Thread(target=self._salvage_leftovers, name="salvage",
                                              daemon=True)
            self._salvager.start()
        self._deliver()

    def _salvage_leftovers(self) -> None:
        """Salvage the leftover ``.part`` files (in the background salvage thread, or at start).
        Each result is handed to the writing thread (:attr:`_salvaged`), which makes it an event
        and counts it (:meth:`_take_salvaged`); this method touches nothing else of the sink."""
        results = salvage_leftovers(self.output.dir, self.output.prefix, stop=self._salvage_stop)
        for result in results:
            self._salvaged.append(result)
        if results and self.wake is not None:
            self.wake()                      # the live loop ticks: the lines come at once

    # -- files -------------------------------------------------------------

    def _open(self) -> McapSink:
        o = self.output
        sink = self._window_of(McapSink(o.dir, prefix=o.prefix, compression=o.compression, flush_s=o.flush_s,
                                        clock=self.clock, metadata=self.metadata, wall_clock=self.wall_clock,
                                        device=self.device))
        if sink.dir_sync_error is not None:
            disk_events.dir_fsync_failed(self, sink.dir_sync_error, sink.part_path)
        self._opened = self.clock()
        self._last_sync = self._opened
        return sink

    @property
    def current(self) -> McapSink | None:
        """The file being written, or None while the disk fails."""
        return self._current

    @property
    def path(self) -> Path | None:
        """The file being written (its final name), or None while the disk fails."""
        return self._current.path if self._current is not None else None

    # -- writing -----------------------------------------------------------

    def write(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> None:
        """Append one message; while no file can be written it is counted in ``dropped``.

        Raises SinkError only for a message that cannot be encoded or a misuse
        (wrong schema for a topic), as McapSink does; never for the disk.
        """
        self.messages_written += 1
        cur = self._file(1)
        if cur is None:
            return
        try:
            cur.write(topic, schema, stamp_ns, msg)
        except SinkIOError as err:
            self._failed(err, cur)
            self._deliver()
            return
        if urgent(topic, msg):
            self._event_dirty = True
        self._written(cur)

    def write_many(self, messages: Sequence[tuple[str, str, int, dict]]) -> None:
        """:meth:`write` of each of ``messages`` in turn, in fewer calls (McapSink.write_many
        from chunk to chunk): the same files, bytes and counts. Rotation and the sink's events
        are looked at before the first message, after each chunk and after the last (write():
        after each message), so at the same messages if the clock stands still meanwhile."""
        i, n = 0, len(messages)
        while i < n:
            cur = self._current
            if (cur is None or self._pending or self.clock() - self._opened >= self.output.rotate_s
                    or cur.bytes_written >= self._rotate_bytes):
                self.write(*messages[i])    # a rotation, a retry or events due after it
                i += 1
                continue
            try:
                j = cur.write_many(messages, i)
            except SinkError as err:        # counted as write() counts, the failing one too
                j = cur.batch_at
                self._event_dirty |= urgent_in(messages, i, j)
                self.messages_written += j + 1 - i
                if not isinstance(err, SinkIOError):
                    raise
                self._failed(err, cur)
                self._deliver()
                i = j + 1
                continue
            self._event_dirty |= urgent_in(messages, i, j)
            self.messages_written += j - i
            i = j
            self._written(cur)

    def write_group(self, messages: list[tuple[str, str, int, dict]]) -> bool:
        """Append messages ``(topic, schema, stamp_ns, msg)`` that are whole or absent after a
        crash (:meth:`McapSink.write_group`); like :meth:`write` otherwise (a rotation comes
        after the group, never inside it). False when the group went to no file (dropped)."""
        self.messages_written += len(messages)
        cur = self._file(len(messages))
        if cur is None:
            return False
        try:
            cur.write_group(messages)
        except SinkIOError as err:
            self._failed(err, cur)
            self._deliver()
            return False
        self._written(cur)
        return True

    def _file(self, n: int) -> McapSink | None:
        """The file to write ``n`` messages to; None while there is none (they are dropped)."""
        cur = self._current
        if cur is None:
            self._retry_if_due()
            cur = self._current
            if cur is None:
                self._drop(n)
                self._deliver()
        return cur

    def _written(self, cur: McapSink) -> None:
        """After messages went to ``cur``: fsynced at the next tick during an outage (logging back
        once they are on it), rotated by time or size, or the sink's events delivered."""
        self._need_sync |= self._outage is not None
        if (self.clock() - self._opened >= self.output.rotate_s
                or cur.bytes_written >= self._rotate_bytes):
            self.rotate()
        elif self._pending:
            self._deliver()
        if cur.bytes_written >= self.retention.next_bytes:     # the cap holds the growing file too
            self._retention()

    def release_held(self) -> None:
        """The stream paused (the link went quiet): what the reorder window holds is written
        and flushed, so a crash during the pause loses none of it."""
        cur = self._current
        if cur is not None and not self._hold_all:
            try:
                cur.release_held()
            except SinkIOError as err:
                self._failed(err, cur)
                return
            self.flush()

    def tick(self) -> None:
        """Once per loop iteration: make pending events durable, flush at least every
        ``flush_s``, fsync every ``fsync_s``, rotate by time, retry after a disk error.

        The background salvage's results handed over before the call become events
        (:meth:`_take_salvaged`), and events queued before it are delivered first, so this call
        makes them durable. Cheap when there is nothing to do; at most one fsync
        per call.
        """
        if self._salvaged:
            self._take_salvaged()
        self._deliver()
        now = self.clock()
        self._margin.tick(now, self._current.reorder if self._current is not None else None)
        if self._current is None:
            self._retry_if_due()
        cur = self._current
        if cur is not None:
            if now - self._opened >= self.output.rotate_s:
                self.rotate()
            elif (self._event_dirty or self._need_sync
                  or now - self._last_sync >= self.output.fsync_s):
                self._sync(cur)
            elif now - cur.last_flush + self._margin.margin(cur.reorder) >= self.output.flush_s:
                self._flush(cur)             # the next tick, however late, would be past flush_s
        self._deliver()

    def flush(self) -> None:
        """Write the open chunk; fsync when fsync_s has passed or an urgent event is pending."""
        cur = self._current
        if cur is None:
            self._retry_if_due()
        elif (self._event_dirty or self._need_sync
              or self.clock() - self._last_sync >= self.output.fsync_s):
            self._sync(cur)
        else:
            self._flush(cur)
        self._deliver()

    def _flush(self, cur: McapSink) -> None:
        try:
            cur.flush()
        except SinkIOError as err:
            self._failed(err, cur)
            return
        self._check_present(cur)

    def _sync(self, cur: McapSink) -> None:
        try:
            cur.sync()
        except SinkIOError as err:
            self._failed(err, cur)
            return
        if not self._check_present(cur):
            return
        self._last_sync, self._event_dirty = self.clock(), False
        self._need_sync = self._outage is not None and not cur.persisted and cur.messages_written > 0
        if self._outage is not None and cur.persisted:
            self._resumed()

    def rotate(self) -> Path | None:
        """Finish the current file and start the next; returns the finished path
        (None if it could not be finished: it is then kept as ``.part``)."""
        was_out = self._outage is not None   # ends in _finish_current: salvaged there
        done = self._finish_current()      # on failure a new file is already being tried
        if not self._closed and self._current is None and self._outage is None:
            try:
                self._current = self._open()
            except SinkIOError as err:
                self._failed(err, None)
        if not self._closed:
            self._retention()
            if done is not None and not was_out:
                self._salvage_waiting()
        if done is not None and self.on_rotate is not None:
            self.on_rotate(done)
        self._deliver()
        return done

    def reopen(self) -> Path | None:
        """Finish the current file and start a new one (SIGHUP, for log rotation
        tools); while the disk fails, try a new file now. Returns the finished path."""
        if self._closed:
            return None
        if self._current is None:
            log.info("reopen: trying a new log file now")
            self._next_retry = self.clock()
            self._retry_if_due()
            self._deliver()
            return None
        done = self.rotate()
        log.info("reopen: finished %s, now writing %s", done, self.path)
        return done

    def close(self) -> Path | None:
        """Finish the current file; returns its path (None if it could not be
        finished). Every finished file still in the directory is in ``paths``; files kept for
        salvage and not salvaged yet are left for the next start (one journal line). Idempotent."""
        if self._closed:
            return self.paths[-1] if self.paths else None
        self._closed = True                  # first: a failure now must not open a new file
        if self._salvager is not None:
            self._salvager.join()
            self._take_salvaged()
            self._deliver()                  # its events, into the file still open
        cur = self._current
        if cur is not None and cur.messages_written == 0 and self.paths:
            self._current = None             # opened by a rotation, nothing came: no empty file
            part = cur.abandon()
            with contextlib.suppress(OSError):   # a header alone: salvage deletes it at the next start
                part.unlink()
            done: Path | None = self.paths[-1]
        else:
            done = self._finish_current()
            self._deliver()
        disk_events.left_waiting(self._abandoned)
        return done

    def release(self) -> None:
        """Let the output directory's hold go (``lock``: its ``close``), once."""
        if self.lock is not None:
            self.lock.close()
            self.lock = None

    def stop_salvage(self) -> None:
        """Stop the background salvage between two records (a stop signal): the
        ``.part`` it was reading is left as it was, for the next start."""
        self._salvage_stop.set()

    def _finish_current(self) -> Path | None:
        cur = self._current
        if cur is None:
            return None
        self._horizon_ns = cur.reorder.horizon_ns
        try:
            done = cur.close()
        except SinkIOError as err:
            if cur.path.exists() and not cur.part_path.exists():
                done = cur.path              # finished and renamed; the directory fsync failed
                disk_events.dir_fsync_failed(self, err, done)
            else:
                self._failed(err, cur)
                return None
        self._current = None
        self.paths = [*still_there(self.paths), done]
        self._event_dirty = self._need_sync = False
        if self._outage is not None:
            self._resumed()                  # close fsyncs: the disk takes data again
        return done

    # -- retention ---------------------------------------------------------

    def _retention(self) -> None:
        """Delete the oldest finished files while over ``retain_mb`` or under ``min_free_mb``
        (:func:`cmsensord.sinks.retention.apply_retention`)."""
        apply_retention(self)
