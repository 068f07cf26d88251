"""Frame sources: where decoded frames come from, behind one small interface.

A source is an iterable of frame batches (``list[Frame]``, possibly empty) and
a context manager.  Every consumer — the daemon's live loop, ``replay``,
``record``, ``vkf``, the calibration tool, the tests and the benchmarks —
reads frames this way, so they all decode bytes the same way:

* :class:`ByteStreamSource` — any iterable of byte chunks through one
  :class:`~cmsensord.protocol.Decoder`, flushed at the end (with ``batches``, each
  batch a :class:`~cmsensord.frame_batch.FrameBatch`: the frames as columns);
* :class:`CaptureSource` — a capture file (docs/PROTOCOL.md, "A captured
  serial log"), read in chunks; a missing or unreadable file raises
  :class:`~cmsensord.errors.LinkError` when the source is made;
* :class:`SerialSource` — the serial port: a reader thread (reconnecting with
  back-off) and a bounded :class:`~cmsensord.frame_queue.FrameQueue`; iteration
  yields what is queued every ``timeout`` seconds, or as soon as ``batch_frames``
  wait or the block the loop named (``wake_at``) is in (empty batches included,
  so the loop can do its periodic work; while that block is still to come, frames wait
  for it up to ``hold_s``), until :meth:`SerialSource.stop`, then what is left, then ends;
* :class:`Paced` — wraps any source and paces it at ``speed`` times the
  board's clock (the frames' own t0, each time segment from its first frame: a board
  reset starts one), with an injectable clock and sleep.

``counters`` (the decoder's :class:`~cmsensord.protocol.LinkCounters`) is on
every source.
"""

from __future__ import annotations

import os
import stat
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import BinaryIO

from cmsensord.errors import LinkError, bad_link, file_kind
from cmsensord.frame_queue import FrameQueue
from cmsensord.link import SerialReader
from cmsensord.monitor.clock import DEFAULT_BLOCK_LEN, DEFAULT_FS, is_reset
from cmsensord.protocol import MAX_FRAME, Decoder, Frame, FrameType, LinkCounters, decode_status
from cmsensord.sinks.mcap_chunks import MAGIC as MCAP_MAGIC

__all__ = ["FrameSource", "ByteStreamSource", "CaptureSource", "SerialSource", "Paced", "require_frames"]

Batch = Sequence[Frame]

#: the live loop's batching: the queued frames as soon as the block completing the next /orders
#: block or decision is in (FrameQueue.wake_at), as soon as BATCH_FRAMES wait (the Processor's
#: MAX_BATCH: a fast board is not held back), or every WAKE_S seconds (the loop's longest sleep,
#: for the watchdog, the status line, the sink's flush and a signal; an RMS stream's decision
#: comes once a second, and ten empty wake-ups a second cost as much as its processing);
#: BATCH_S: the board time of one Processor call (live.output_parts)
WAKE_S = 0.5
BATCH_S = 0.1
BATCH_FRAMES = 1000
#: ... but while the block the Processor waits for (its next /orders block or decision) is still
#: to come, frames wait for it up to HOLD_S (RMS mode: one call per decision, not per BATCH_S)
HOLD_S = 1.5
#: with a block named (:meth:`SerialSource.wake_at`) that is due in more than WAKE_S (RMS mode's
#: next decision, a second off), the loop sleeps until WAKE_S / 2 after it is due, at most
#: FAR_WAKE_S: it wakes once a decision, not also at a timeout that falls about when the
#: decision comes (two wake-ups a second instead of one)
FAR_WAKE_S = 1.5


class FrameSource:
    """Base of the sources: an iterable of frame batches and a context manager."""

    decoder: Decoder

    @property
    def counters(self) -> LinkCounters:
        return self.decoder.counters

    @property
    def link_down(self) -> str | None:
        """Why a live port is not open now (None: open, or not a port)."""
        return None

    def __iter__(self) -> Iterator[Batch]:  # pragma: no cover - abstract
        raise NotImplementedError

    def close(self) -> None:
        """Release what the source holds (file, port); iteration ends."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class ByteStreamSource(FrameSource):
    """Byte chunks -> one decoder -> one batch per chunk, and the decoder's flush at the end.

    ``bytes_read`` counts the bytes decoded so far.
    """

    def __init__(self, chunks: Iterable[bytes], decoder: Decoder | None = None, batches: bool = False):
        self._chunks = chunks
        self.decoder = decoder or Decoder()
        self.batches = batches
        self.bytes_read = 0

    @classmethod
    def of(cls, data: bytes, chunk: int) -> ByteStreamSource:
        """``data`` in reads of ``chunk`` bytes (tests: chunk-split invariance)."""
        return cls(data[k:k + chunk] for k in range(0, len(data), chunk))

    def __iter__(self) -> Iterator[Batch]:
        dec = self.decoder
        for data in self._chunks:
            self.bytes_read += len(data)
            yield dec.feed_batch(data) if self.batches else dec.feed(data)
        yield dec.flush_batch() if self.batches else dec.flush()


class CaptureSource(ByteStreamSource):
    """The frames of a capture file, read ``chunk`` bytes at a time (flushed at the end).

    Opening happens here: a missing, unreadable or directory path raises LinkError
    with a one-line reason before the caller creates any output.
    """

    def __init__(self, path: str | Path, chunk: int = 1 << 16, decoder: Decoder | None = None,
                 batches: bool = False):
        self.path = Path(path)
        self.size = self.path.stat().st_size if self.path.is_file() else 0
        self._file = _open_capture(self.path)
        self.chunk = chunk
        super().__init__(self._read(), decoder, batches)

    def _read(self) -> Iterator[bytes]:
        f = self._file
        while not f.closed:
            try:
                data = f.read(self.chunk)
            except OSError as exc:
                raise LinkError(f"{self.path}: read error: {exc.strerror or exc}") from None
            if not data:
                return
            yield data

    def close(self) -> None:
        self._file.close()


def require_frames(path: str | Path, command: str) -> None:
    """LinkError (one line, naming ``command`` and the file) when the capture at ``path`` holds no
    frame the decoder takes: the wrong file given (a YAML file, a sidecar, a WAV), or a capture
    whose every frame fails its CRC check (said so, with their count).  The file is scanned up to
    its first good frame (in its first 64 KB read, for a capture), before the command makes any output."""
    chunk = 1 << 16
    with CaptureSource(path, chunk=chunk, decoder=Decoder(max_buffer=chunk + MAX_FRAME), batches=True) as scan:
        for _ in scan:
            if any(scan.counters.frames.values()):
                return
        counters = scan.counters
    head = f"{command}: no frame in {path} ({counters.bytes_received} bytes)"
    if counters.crc_failures:
        raise LinkError(f"{head}: all {counters.crc_failures} frame(s) in it failed their CRC check: a damaged "
                        "capture (copied as text?): copy or record it again")
    raise LinkError(f"{head}: not a capture of the board's serial stream? (`cmsensord import` makes one from "
                    "other recordings)")


def _open_capture(p: Path) -> BinaryIO:
    """The capture file open for reading; LinkError for one that is not there, not readable, no
    regular file (a FIFO is refused, never waited on) or an MCAP log."""
    try:
        f = open(os.open(p, os.O_RDONLY | os.O_NONBLOCK), "rb")
        mode = os.fstat(f.fileno()).st_mode
        if not stat.S_ISREG(mode):
            f.close()
            if stat.S_ISDIR(mode):
                raise IsADirectoryError
            raise LinkError(f"{p}: not a regular file (a {file_kind(mode)}): replay, calibrate and vkf read a "
                            "capture file (`--capture`, `cmsensord record`, `cmsensord import`)")
        os.set_blocking(f.fileno(), True)
        if f.peek(len(MCAP_MAGIC))[:len(MCAP_MAGIC)] == MCAP_MAGIC:
            f.close()
            raise LinkError(f"{p}: an MCAP log (cmsensord's output), not a capture of the board's serial stream: "
                            "`cmsensord summary` and `cmsensord report` read it; replay, calibrate and vkf read a "
                            "capture (`--capture`, `cmsensord record`, `cmsensord import`)")
        return f
    except FileNotFoundError:
        raise LinkError(f"{p}: {bad_link(p, 'the capture') or 'capture file not found'}") from None
    except IsADirectoryError:
        raise LinkError(_directory_text(p)) from None
    except OSError as exc:
        raise LinkError(f"{p}: {bad_link(p, 'the capture') or f'cannot read capture: {exc.strerror or exc}'}") from None


def _directory_text(p: Path) -> str:
    """The line refusing the directory ``p`` given as a capture: one of MCAP logs (what reads
    them), or another (what replay, calibrate and vkf read)."""
    readers = "replay, calibrate and vkf read a capture file (`--capture`, `cmsensord record`, `cmsensord import`)"
    try:
        logs = any(n.endswith((".mcap", ".mcap.part")) for n in os.listdir(p))
    except OSError:
        logs = False
    if logs:
        return (f"{p}: a directory of MCAP logs (cmsensord's output), not a capture file: `cmsensord summary` "
                f"and `cmsensord report` read it; {readers}")
    return f"{p}: is a directory, not a capture file: {readers}"


class SerialSource(FrameSource):
    """The serial port: :class:`~cmsensord.link.SerialReader` thread -> bounded queue.

    Entering starts the reader thread.  Iteration yields the queued frames every
    ``timeout`` seconds (an empty batch when none came), or sooner once ``batch_frames``
    wait or the block named by ``queue.wake_at`` is in, until :meth:`stop`; then it yields
    the frames still queued once and ends.  While a named block is still to come, frames
    stay queued (empty batches) until it is in or the oldest has waited ``hold_s``.
    Batching by time is what keeps the live daemon's cost near a replay's: the
    Processor's work is mostly per call, and one call per 10-ms block costs ~3x the
    work of its frames.  ``batch_frames=1`` yields as soon as any frame is
    queued.  The loop names the block it waits for with :meth:`wake_at` (one far off, RMS
    mode's next decision: the wait lasts until just after it is due, one wake-up a decision)
    and leaves the frames past an output's block for the next batch with :meth:`keep`.
    ``events`` holds the reader's link events as (wall_ns, kind, message); ``capture`` tees
    the bytes to a file.
    """

    def __init__(self, port: str, *, baud: int, read_size: int = 4096, queue_frames: int = 20000,
                 capture: BinaryIO | None = None, reconnect_min_s: float = 0.5,
                 reconnect_max_s: float = 5.0, open_port: Callable | None = None,
                 timeout: float = WAKE_S, batch_frames: int = BATCH_FRAMES, hold_s: float = HOLD_S):
        self.queue = FrameQueue(queue_frames)
        self.reader = SerialReader(port, baud=baud, read_size=read_size, queue=self.queue,
                                   capture=capture, reconnect_min_s=reconnect_min_s,
                                   reconnect_max_s=reconnect_max_s, open_port=open_port)
        self.decoder = self.reader.decoder
        self.timeout = timeout
        self.batch_frames = batch_frames
        self.hold_s = hold_s
        self._stopped = False
        self._kept: list[Frame] = []         # frames the loop left for the next output (keep)
        self._kept_at = 0.0
        self.far_timeout = FAR_WAKE_S
        self._due: float | None = None       # when the far block named last is due (monotonic)
        self._far: int | None = None          # ... and its t0
        self._newest: tuple[float, int] | None = None   # (when, t0) of the newest frame yielded

    @classmethod
    def from_link(cls, link, capture: BinaryIO | None = None,
                  open_port: Callable | None = None) -> SerialSource:
        """A source on the port of a :class:`~cmsensord.config.LinkConfig` (``open_port``:
        how to open it, default pyserial's ``Serial``)."""
        source = cls(link.port, baud=link.baud, read_size=link.read_size, queue_frames=link.queue_frames,
                     capture=capture, reconnect_min_s=link.reconnect_min_s,
                     reconnect_max_s=link.reconnect_max_s, open_port=open_port)
        source.reader.reopen_s = link.reopen_s
        source.reader.give_up_s = link.stall_s / 2      # the frames behind it are in before link_stalled
        pace = source.reader.pace           # a hold must not look like a silent link (link_stalled)
        pace.far_hold_s = min(pace.far_hold_s, link.stall_s / 2)
        return source

    @property
    def events(self):
        return self.reader.events

    @property
    def link_down(self) -> str | None:
        return self.reader.down

    def __enter__(self):
        self.reader.start()
        return self

    def __iter__(self) -> Iterator[list[Frame]]:
        while not self._stopped:
            timeout, hold_s = self.timeout, self.hold_s
            if self._due is not None:           # a named block far off: sleep until just after it is due
                until = self._due - time.monotonic() + self.timeout / 2
                timeout = max(timeout, min(self.far_timeout, until))
                if until <= timeout:            # it is overdue when the wait ends (the board
                    hold_s = 0.0                # stopped?): what came waits no longer
            got = self.queue.get(timeout=timeout, enough=self.batch_frames, hold_s=hold_s)
            now = time.monotonic()
            if got:
                self._newest = (now, got[-1].t0_unwrapped)
            if self._kept and (got or self.queue.hint is None or now - self._kept_at >= hold_s):
                got, self._kept = self._kept + got, []
            yield got
        got, self._kept = self._kept + self.queue.get(timeout=0), []
        yield got

    def wake_at(self, t0: int | None, fs: float) -> None:
        """The next batch comes as soon as the block at board sample ``t0`` is in
        (:meth:`FrameQueue.wake_at`); when it is due more than ``timeout`` after the newest frame
        yielded (at ``fs`` samples a second), the wait for it is not cut short by ``timeout``
        but lasts until ``timeout / 2`` after it is due (``far_timeout`` at most), and when it
        is overdue then, the frames that came are yielded (not held for ``hold_s``)."""
        self.queue.wake_at(t0)
        if t0 == self._far:                 # named again (not in yet): as it was due then
            return
        newest, self._due, self._far = self._newest, None, None
        if t0 is not None and newest is not None and fs > 0:
            due = newest[0] + (t0 - newest[1]) / fs
            if due - time.monotonic() > self.timeout:
                self._due, self._far = due, t0

    def keep(self, frames: list[Frame]) -> None:
        """``frames`` (taken from the last batch, not handled) come first in the next batch
        that has frames, and wait for it as queued frames wait (``hold_s`` at most, and only
        while the loop names a block to wake at): the frames past the block that completed an
        output, when the next output is far off (RMS mode's decisions), are handled with the
        block completing that one, in one Processor call, not in a call of their own."""
        if frames:
            self._kept, self._kept_at = frames + self._kept, time.monotonic()

    @property
    def last_bytes(self) -> float:
        """When the newest bytes came (monotonic), at the latest: the reader's last read that got
        any, less how late that read came for its newest frame (a hold lets bytes wait in the
        port: a stream that stopped during one stopped when its last frame came, not when it
        was read)."""
        return self.reader.last_data - max(0.0, self.reader.pace.late_s)

    @property
    def waiting(self) -> int:
        """Frames waiting: queued, and kept by :meth:`keep`."""
        return len(self.queue) + len(self._kept)

    def stop(self) -> None:
        """Stop the reader thread (waits up to 2 s for it); iteration then drains and ends."""
        if not self._stopped:
            self._stopped = True
            self.reader.stop()
            if self.reader.is_alive():
                self.reader.join(timeout=2.0)

    def close(self) -> None:
        self.stop()


#: a paced frame is handed on at most this long (s, wall clock) before it is due
SLICE_S = 0.02


class Paced(FrameSource):
    """``source`` at ``speed`` times the board's clock (1: real time).

    The board's time of a batch is the t0 of its last frame over fs (fs and the block
    length from the STATUS frames seen, 25 kHz and 250 before one), counted from the
    first frame of its time segment, plus the board time of the segments before it: a
    board reset (:func:`~cmsensord.monitor.clock.is_reset`, as the daemon's segments
    decide one) starts a segment, paced from its own first frame (a board up for days
    that resets is not slept through the days its t0 goes back or on).  A frame is handed
    on once ``clock()`` is within ``SLICE_S`` of the start time plus its board time / speed:
    a batch (a read of the file: seconds of an RMS board) is handed on in slices, each when
    its first frame is due, the wrapper sleeping between them, and after the last slice until
    the batch's last frame is due.  ``clock`` and ``sleep`` are injectable.
    """

    def __init__(self, source: FrameSource, speed: float, *,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, fs: int = DEFAULT_FS):
        if not speed > 0:
            raise ValueError(f"speed must be positive, got {speed}")
        self.source = source
        self.speed = speed
        self.clock = clock
        self.sleep = sleep
        self.fs = fs
        self.block_len = DEFAULT_BLOCK_LEN

    def __getattr__(self, name: str):
        return getattr(self.source, name)      # counters, bytes_read, size, events ...

    def __iter__(self) -> Iterator[Batch]:
        t_start = self.clock()
        done_s = 0.0                        # board seconds of the segments before the current one
        first = last = 0                    # t0_unwrapped of the segment's first frame, of the newest
        seen = False
        for frames in self.source:
            start = 0                       # the first frame of the batch not handed on yet
            for i, f in enumerate(frames):
                t = f.t0_unwrapped
                if not seen or is_reset(t, last, self.fs, self.block_len):
                    done_s += (last - first) / self.fs
                    first, seen = t, True
                last = t
                wait = t_start + (done_s + (t - first) / self.fs) / self.speed - self.clock()
                if wait > SLICE_S and i > start:    # due later: the frames before it go now
                    yield frames[start:i]
                    start = i
                    wait = t_start + (done_s + (t - first) / self.fs) / self.speed - self.clock()
                if wait > SLICE_S:
                    self.sleep(wait)
                if f.type == FrameType.STATUS:      # after its own check, as the daemon takes it
                    self._status(f.payload)
            yield frames[start:]
            wait = t_start + (done_s + (last - first) / self.fs) / self.speed - self.clock() if frames else 0.0
            if wait > 0:                    # the batch's last frame is due: the run ends on time
                self.sleep(wait)

    def _status(self, payload: bytes) -> None:
        """The fs and block length a STATUS frame names (none when it is malformed or names 0)."""
        try:
            st = decode_status(payload)
        except ValueError:
            return
        if st.fs > 0:
            self.fs = st.fs
        if st.block_len > 0:
            self.block_len = st.block_len

    def close(self) -> None:
        self.source.close()

    def __enter__(self):
        self.source.__enter__()
        return self
