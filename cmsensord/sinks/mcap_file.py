"""The crash-safe MCAP file: one ``.part`` file written chunk by chunk, finished by a rename.

* one file ``<prefix>-<UTC yyyymmddTHHMMSSZ>.mcap`` (``-1``, ``-2``, ... when
  the name of that second is taken; never sorting before a name already there:
  :mod:`cmsensord.sinks.log_names`), written as ``*.mcap.part`` (the directory
  fsynced once it is created, so what a later fsync of the file makes durable
  survives a power cut under its name) and renamed by :meth:`McapSink.close`
  once the summary and footer are on disk (then the directory is fsynced
  again). A ``.part`` file left by a crash holds every chunk flushed before it
  (:func:`~cmsensord.sinks.mcap_salvage.salvage` recovers them); it is locked
  (``flock``) while a sink has it open;
* chunks are finished and written (unbuffered, :class:`RawFile`: straight to
  the kernel, so a kill -9 loses nothing written) every ``flush_s`` seconds by
  the injected clock, so at most ``flush_s`` of data is lost on a crash of the
  process;
* every OSError is a :class:`SinkIOError` naming the operation; after one the
  file is *failed* and never written or fsynced again (see :class:`McapSink`).

Message encoding and the schema/channel registry are
:mod:`cmsensord.sinks.mcap_encoding`; the records and chunks
:mod:`cmsensord.sinks.mcap_chunks`. Rotation, periodic fsync, retention and
what to do after an error are the caller's policy
(:class:`~cmsensord.sinks.rotating.RotatingSink`): :attr:`McapSink.bytes_written`,
:attr:`McapSink.opened_at`, :attr:`McapSink.unpersisted`, :meth:`McapSink.sync`,
:meth:`McapSink.abandon` and :func:`log_files` give it what it needs.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from cmsensord import __version__
from cmsensord.errors import SinkError
from cmsensord.sinks.json_templates import TEMPLATES
from cmsensord.sinks.log_dir import Place, off_device
from cmsensord.sinks.log_names import log_files, next_name, salvaged_path
from cmsensord.sinks.mcap_chunks import ChunkWriter
from cmsensord.sinks.mcap_encoding import REPEATED, ChannelRegistry, encode_message
from cmsensord.sinks.reorder import GROUP, MAX_S, Payload, ReorderWindow

__all__ = [
    "McapSink",
    "SinkIOError",
    "RawFile",
    "fsync_dir",
    "log_files",
    "make_dirs",
    "moved_error",
    "os_error_text",
    "salvaged_path",
]

_COMPRESSION = {"zstd": "zstd", "lz4": "lz4", "none": ""}  # option -> Chunk.compression


class SinkIOError(SinkError):
    """The file system refused an operation (ENOSPC, EIO, EDQUOT, a failed fsync, ...).

    ``op`` is what failed: ``"open"`` (directory, new file or its header),
    ``"write"`` (a chunk), ``"fsync"``, ``"close"`` (summary, footer, rename)
    or ``"read"`` (salvage); ``errno`` the OSError's errno (None when there was
    no OSError, e.g. a write to a file abandoned earlier); ``path`` the file.
    """

    def __init__(self, message: str, *, op: str, err: OSError | None, path: Path) -> None:
        super().__init__(message)
        self.op = op
        self.errno = err.errno if err is not None else None
        self.path = path


def os_error_text(err: OSError) -> str:
    """The OSError's reason, for a one-line message."""
    return err.strerror or str(err)


class RawFile:
    """An unbuffered file: every write() puts all its bytes in the kernel or raises.

    The sink writes whole records (a finished chunk with its message indexes
    in one call), so Python-level buffering gains nothing, and without it the
    bytes on disk after an error are exactly those the kernel accepted: a
    failed file is closed without any buffered data being written later.
    """

    def __init__(self, fd: int) -> None:
        self.fd = fd

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self.fd, view)  # a short count on a full disk: the next call raises
            view = view[n:]

    def flush(self) -> None:
        """Nothing to do: write() leaves nothing in this process."""

    def fileno(self) -> int:
        return self.fd

    def close(self) -> None:
        if self.fd >= 0:
            fd, self.fd = self.fd, -1
            os.close(fd)


def fsync_dir(path: Path) -> None:
    """fsync a directory (makes the creations, renames and deletions in it durable)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def moved_error(out_dir: str | Path, device: Place | None) -> SinkIOError | None:
    """None while ``out_dir`` is at ``device`` (:func:`~cmsensord.sinks.log_dir.off_device`; None:
    anywhere); else the error of opening a file there (``op="open"``, ENODEV): its file system is gone."""
    why = off_device(out_dir, device)
    if why is None:
        return None
    return SinkIOError(f"{out_dir}: {why}", op="open", err=OSError(errno.ENODEV, why), path=Path(out_dir))


def make_dirs(path: Path) -> list[Path]:
    """``mkdir -p path``: the directories it created, outermost first (OSError as mkdir's).
    Their parents are to be fsynced (:func:`fsync_dir`) for the new names to survive a power cut."""
    missing = []
    at = path
    while not at.exists() and at != at.parent:
        missing.append(at)
        at = at.parent
    path.mkdir(parents=True, exist_ok=True)
    return missing[::-1]


# ---------------------------------------------------------------------------
# The file
# ---------------------------------------------------------------------------


class McapSink:
    """Writes messages to one MCAP file; schemas and channels registered lazily per topic.

    Args:
        out_dir: directory of the file, created (with parents) if needed.
        prefix: file name prefix.
        compression: ``"zstd"``, ``"lz4"`` or ``"none"``.
        flush_s: finish and write the current chunk when this many seconds (by
            ``clock``) have passed since the last flush.
        clock: monotonic seconds, injectable for tests.
        metadata: written as an MCAP Metadata record named ``"cmsensord"``.
        wall_clock: Unix seconds used for the file name (injectable for tests).
        chunk_size: uncompressed bytes after which a chunk is finished anyway.
        reorder_s: the longest a message is held to write the file in log-time order
            (:class:`~cmsensord.sinks.reorder.ReorderWindow`; 0: nothing held, a late
            message gets the newest log time written).
        reorder_horizon_ns: the window's horizon to start with (the previous file's).
        device: the device and mount ``out_dir`` must be on (None: any); elsewhere nothing is made and
            the file is not opened (:func:`moved_error`).

    Raises:
        SinkError: an argument is invalid; :class:`SinkIOError` (a SinkError,
            ``op="open"``) when the directory cannot be created or the file
            and its header cannot be written (one-line message naming it).

    Errors while writing: every OSError becomes a :class:`SinkIOError` naming
    the operation, and the file is then *failed*: nothing more is written to
    it (a failed fsync is never retried, since the kernel may already have
    dropped the dirty pages), :meth:`close` only closes the descriptor and
    keeps the ``.part`` file, whose complete chunks
    :func:`~cmsensord.sinks.mcap_salvage.salvage` recovers. The ``.part``
    file is locked (``flock``) while this sink has it open, so a salvage by
    another process never touches a file being written.
    """

    def __init__(
        self,
        out_dir: str | Path,
        *,
        prefix: str = "cmsensord",
        compression: str = "zstd",
        flush_s: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
        metadata: dict[str, str] | None = None,
        wall_clock: Callable[[], float] = time.time,
        chunk_size: int = 1024 * 1024,
        reorder_s: float = MAX_S,
        reorder_horizon_ns: int = 0,
        device: Place | None = None,
    ) -> None:
        if compression not in _COMPRESSION:
            raise SinkError(
                f"unknown MCAP compression {compression!r} (one of {', '.join(_COMPRESSION)})"
            )
        if not flush_s > 0:
            raise SinkError(f"flush_s must be > 0 (got {flush_s!r})")
        self.out_dir = Path(out_dir)
        self._clock = clock
        self._flush_s = float(flush_s)
        self.messages_written = 0
        self.batch_at = 0  # write_many(): the index of the message being written
        self._synced = 0  # persisted messages at the last successful fsync
        self._closed = False
        self._failed = False

        moved = moved_error(self.out_dir, device)
        if moved is not None:
            raise moved
        try:
            created = make_dirs(self.out_dir)
        except OSError as err:
            why = "it is a file, not a directory" if self.out_dir.exists() and not self.out_dir.is_dir() \
                else os_error_text(err)
            raise SinkIOError(f"{self.out_dir}: cannot create output directory: {why}",
                              op="open", err=err, path=self.out_dir) from None
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(wall_clock()))
        self._fh = self._open_unique(prefix, stamp)

        try:
            self._writer = ChunkWriter(self._fh, _COMPRESSION[compression], chunk_size)
            self._writer.start(library=f"cmsensord/{__version__}")
            if metadata:
                self._writer.add_metadata("cmsensord", {str(k): str(v) for k, v in metadata.items()})
        except (OSError, SinkError) as err:
            self._fh.close()
            with contextlib.suppress(OSError):
                self.part_path.unlink(missing_ok=True)  # a header alone holds nothing to keep
            if isinstance(err, SinkError):
                raise
            raise SinkIOError(
                f"{self.part_path}: cannot write: {os_error_text(err)}", op="open", err=err,
                path=self.part_path,
            ) from None
        #: the directory fsync after creating the ``.part`` failed (the file is written all the
        #: same; its name may not survive a power cut until the directory is fsynced again)
        self.dir_sync_error: SinkIOError | None = None
        try:
            for new in created:         # a directory made here: its name durable in its parent
                fsync_dir(new.parent)
            fsync_dir(self.out_dir)     # the new name durable before any data fsynced into it
        except OSError as err:
            self.dir_sync_error = SinkIOError(
                f"{self.out_dir}: directory fsync failed after creating {self.part_path.name}: "
                f"{os_error_text(err)}", op="fsync", err=err, path=self.part_path)
        self.reorder = ReorderWindow(reorder_s, horizon_ns=reorder_horizon_ns)
        self._registry = ChannelRegistry(self._writer)
        # topic -> (channel id, kind): the registry's map while the file takes messages, an
        # empty one once it is closed or failed (write() then calls _register(), which refuses)
        self._channels = self._registry.channels
        self.opened_at = clock()
        self._last_flush = self.opened_at

    def _open_unique(self, prefix: str, stamp: str) -> RawFile:
        flags = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
                 | getattr(os, "O_CLOEXEC", 0))
        stamp, first = next_name(self.out_dir, prefix, stamp)   # never before a name already there
        for k in range(first, first + 1000):
            base = f"{prefix}-{stamp}" + (f"-{k}" if k else "")
            final = self.out_dir / f"{base}.mcap"
            part = self.out_dir / f"{base}.mcap.part"
            if final.exists():
                continue
            try:
                fd = os.open(part, flags, 0o644)  # exclusive: never clobber another writer's file
            except FileExistsError:
                continue
            except OSError as err:
                raise SinkIOError(
                    f"{self.out_dir}: cannot write in output directory: {os_error_text(err)}",
                    op="open", err=err, path=part,
                ) from None
            with contextlib.suppress(OSError):  # no flock on this file system: salvage runs only at start anyway
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # salvage skips locked files
            self.path = final
            self.part_path = part
            return RawFile(fd)
        raise SinkError(f"{self.out_dir}: no free file name for {prefix}-{stamp}.mcap")

    def _fail(self, op: str, err: OSError) -> SinkIOError:
        """Mark the file failed (nothing more is written to it); the error to raise."""
        self._failed = True
        self._channels = {}  # every later write() goes through _register(), which refuses
        verb = {"write": "write failed", "fsync": "fsync failed", "close": "cannot finish MCAP file"}
        return SinkIOError(
            f"{self.part_path}: {verb.get(op, op + ' failed')}: {os_error_text(err)}",
            op=op, err=err, path=self.part_path,
        )

    # -- hot path ----------------------------------------------------------

    def write(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> None:
        """Append one message.

        ``schema`` is the kind key ("severity", "akf", "event", "diagnostics",
        "orders"); a topic's kind is fixed by its first message. A
        ``"timestamp": {"sec", "nsec"}`` field is added from ``stamp_ns`` unless
        ``msg`` has one; ``msg`` itself is not modified. publish_time =
        ``stamp_ns``; log_time too, unless the message comes after later ones were
        written (then the newest log time written: :mod:`cmsensord.sinks.reorder`).
        """
        channel_id, stamp_ns, data = self._encoded(topic, schema, stamp_ns, msg)
        self.messages_written += 1  # before: if its chunk cannot be written it is lost
        self._put(self.reorder.push(stamp_ns, channel_id, data))

    def _encoded(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> tuple[int, int, bytes]:
        """A message's channel id (registered at its first message), stamp as an int, and
        encoded bytes; SinkError for a negative stamp."""
        entry = self._channels.get(topic)
        if entry is None or entry[1] != schema:
            entry = self._register(topic, schema)
        if type(stamp_ns) is not int:
            stamp_ns = int(stamp_ns)
        if stamp_ns < 0:
            raise SinkError(f"{topic}: negative timestamp {stamp_ns} ns")
        template = TEMPLATES.get(schema)          # a decision's messages: the same bytes, formatted
        body = None if template is None else template(stamp_ns, msg)
        if body is not None:
            return entry[0], stamp_ns, body.encode()
        return entry[0], stamp_ns, encode_message(topic, stamp_ns, msg, REPEATED.get(schema))

    def write_many(self, messages: Sequence[tuple[str, str, int, dict]], start: int = 0) -> int:
        """:meth:`write` of ``messages[start:]`` in turn, in one call, up to and including the
        first one after which a chunk went to the file (a flush, or a full chunk); returns the
        index after the last one written, so that a caller sees the file between chunks
        (:meth:`~cmsensord.sinks.rotating.RotatingSink.write_many` rotates there).

        The bytes are those of one write() per message; only the clock is read after the
        first message and the last (write() reads it after each): a flush falling due during
        the call comes at its end, the call's microseconds late, and at the same message as
        write()'s when the clock does not move during the call. :attr:`batch_at`: the index
        of the message being written (after an exception, the one that failed)."""
        n = len(messages)
        k = start
        writer, push, passes = self._writer, self.reorder.push, self.reorder.passes
        channels, templates = self._channels, TEMPLATES
        pos = writer.pos
        while k < n:
            self.batch_at = k
            topic, schema, stamp_ns, msg = messages[k]
            entry = channels.get(topic)         # _encoded's way for a decision's message, inline
            template = templates.get(schema)
            body = template(stamp_ns, msg) if (template is not None and entry is not None and entry[1] == schema
                                               and type(stamp_ns) is int and stamp_ns >= 0) else None
            if body is None:
                channel_id, stamp_ns, data = self._encoded(topic, schema, stamp_ns, msg)
            else:
                channel_id, data = entry[0], body.encode()   # type: ignore[index]
            self.messages_written += 1
            try:
                if passes(stamp_ns):                    # what push() would give, without a list
                    writer.add_message(channel_id, stamp_ns, data, stamp_ns)
                else:
                    self._add(push(stamp_ns, channel_id, data))
            except OSError as err:
                raise self._fail("write", err) from None
            k += 1
            if k == start + 1 or k == n or writer.pos != pos:
                if self._clock() - self._last_flush >= self._flush_s:
                    self.flush()
                if writer.pos != pos:
                    break
        return k

    def write_group(self, messages: list[tuple[str, str, int, dict]]) -> None:
        """Append messages ``(topic, schema, stamp_ns, msg)`` that are whole or absent after a
        crash (a capture's waveform and spectra): they are held in the reorder window as one
        entry (stamped with the first one's stamp) and written as a chunk of their own
        (:meth:`~cmsensord.sinks.mcap_chunks.ChunkWriter.add_group`), all with that log time."""
        if not messages:
            return
        encoded = []
        for m in messages:
            channel_id, _stamp, data = self._encoded(*m)
            encoded.append((channel_id, data))
        self.messages_written += len(encoded)
        self._put(self.reorder.push(int(messages[0][2]), GROUP, tuple(encoded)))

    def release_held(self) -> None:
        """Every message the reorder window holds into the chunk writer (the stream paused:
        messages that come later than them are written with a clamped log time)."""
        self._put(self.reorder.drain())

    def _put(self, released: list[tuple[int, int, int, Payload]]) -> None:
        """Messages (and groups) released by the reorder window into the chunk writer."""
        try:
            self._add(released)
        except OSError as err:  # a chunk got full and could not be written
            raise self._fail("write", err) from None
        if self._clock() - self._last_flush >= self._flush_s:
            self.flush()

    def _add(self, released: list[tuple[int, int, int, Payload]]) -> None:
        writer = self._writer
        for log_time, publish_time, channel_id, body in released:
            if isinstance(body, bytes):
                writer.add_message(channel_id, log_time, body, publish_time)
            else:
                writer.add_group(body, log_time, publish_time)

    def _register(self, topic: str, kind: str) -> tuple[int, str]:
        if self._failed:
            raise SinkIOError(
                f"{self.part_path}: write to a file abandoned after an error", op="write",
                err=None, path=self.part_path,
            )
        if self._closed:
            raise SinkError(f"{self.path}: write after close")
        return self._registry.register(topic, kind)

    # -- durability --------------------------------------------------------

    @property
    def bytes_written(self) -> int:
        """Bytes in the file so far (flushed chunks; the open chunk is not counted)."""
        return self._writer.pos

    @property
    def persisted(self) -> int:
        """Messages in chunks written completely to the file (on a kill -9 they survive)."""
        return self._writer.persisted

    @property
    def unpersisted(self) -> int:
        """Messages accepted by write() but not (or not completely) in the file."""
        return self.messages_written - self._writer.persisted

    @property
    def unsynced(self) -> int:
        """Messages in the file but written after the last successful fsync: after a
        failed fsync they may not be on the disk (the kernel may have dropped them)."""
        return self._writer.persisted - self._synced

    @property
    def last_flush(self) -> float:
        """Clock time of the last flush (or of opening the file)."""
        return self._last_flush

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def failed(self) -> bool:
        """An operation on the file failed: nothing more is written to it."""
        return self._failed

    def fileno(self) -> int:
        """The file descriptor of the ``.part`` file (-1 once closed)."""
        return self._fh.fileno()

    def flush(self) -> None:
        """Finish the chunk in progress and write it (no fsync).

        Raises SinkIOError (and the file is failed) if the write fails.
        """
        self._last_flush = self._clock()
        if self._closed:
            return
        if self._failed:
            raise SinkIOError(f"{self.part_path}: write to a file abandoned after an error",
                              op="write", err=None, path=self.part_path)
        try:
            self._writer.finish_chunk()
        except OSError as err:
            raise self._fail("write", err) from None

    def sync(self) -> None:
        """flush() and fsync the file (call every ``fsync_s``).

        A failed fsync fails the file: it is never fsynced (or written) again.
        """
        self.flush()
        if self._closed:
            return
        try:
            os.fsync(self._fh.fileno())
        except OSError as err:
            raise self._fail("fsync", err) from None
        self._synced = self._writer.persisted

    def abandon(self) -> Path:
        """Close the descriptor without writing anything more; the ``.part`` file stays.

        Returns the ``.part`` path. For a failed file (or at any time: the
        flushed chunks are a valid prefix that
        :func:`~cmsensord.sinks.mcap_salvage.salvage` recovers).
        """
        if not self._closed:
            self._closed = True
            self._failed = True
            self._channels = {}
            self.path = self.part_path
            with contextlib.suppress(OSError):  # the file is given up: nothing to report beyond the first error
                self._fh.close()
        return self.part_path

    def close(self) -> Path:
        """Write summary and footer, fsync, rename .part -> .mcap, fsync the directory.

        Idempotent; returns the final path. If finishing fails (or the file
        failed earlier), the ``.part`` file is kept (its flushed chunks are
        readable and salvageable) and SinkIOError is raised.
        """
        if self._closed:
            return self.path
        if self._failed:
            self.abandon()
            raise SinkIOError(f"{self.part_path}: not finished: abandoned after an earlier error",
                              op="close", err=None, path=self.part_path)
        self._closed = True
        self._channels = {}  # any later write() goes through _register(), which refuses
        op = "close"
        try:
            self._add(self.reorder.drain())
            self._writer.finish()
            op = "fsync"
            os.fsync(self._fh.fileno())
        except OSError as err:
            error = self._fail(op, err)
            self.path = self.part_path
            with contextlib.suppress(OSError):  # already failing; the first error is the one to report
                self._fh.close()
            raise error from None
        try:
            os.replace(self.part_path, self.path)  # still open and locked: no salvage can interfere
        except OSError as err:
            self.path = self.part_path
            with contextlib.suppress(OSError):
                self._fh.close()
            raise SinkIOError(f"{self.part_path}: cannot close: {os_error_text(err)}", op="close",
                              err=err, path=self.part_path) from None
        with contextlib.suppress(OSError):  # everything is written and fsynced; close has nothing left to lose
            self._fh.close()
        try:
            fsync_dir(self.out_dir)
        except OSError as err:  # finished and renamed; only the rename may not be durable
            raise SinkIOError(f"{self.out_dir}: directory fsync failed after finishing "
                              f"{self.path.name}: {os_error_text(err)}", op="fsync", err=err,
                              path=self.path) from None
        return self.path

    def __enter__(self) -> McapSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
