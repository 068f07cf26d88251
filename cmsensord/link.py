"""The serial port at the edge: the reader thread (reconnect with back-off).

Bytes read from the port go into the push decoder of ``protocol``; frames come
out and go, through a bounded :class:`~cmsensord.frame_queue.FrameQueue`, to the processing loop
(wrapped as :class:`cmsensord.source.SerialSource`).  The reader can tee the
bytes to a capture file (docs/PROTOCOL.md, "A captured serial log").
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import select
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from typing import BinaryIO

import serial

try:                                    # the port class of pyserial on Linux, macOS, BSD
    from serial.serialposix import Serial as PosixSerial
except ImportError:                     # pragma: no cover - Windows
    PosixSerial = None

from cmsensord.frame_queue import FrameQueue
from cmsensord.protocol import HEADER_LEN, Decoder
from cmsensord.read_pace import ReadPace
from cmsensord.serial_port import PORT_ERRORS, cannot_open, is_held, open_serial, why

log = logging.getLogger("cmsensord")

#: how often the reader looks for a port's device to come back while it waits to reconnect
REAPPEAR_POLL_S = 0.1
#: the longest wait for bytes of a port opened without a timeout
READ_WAIT_S = 0.05
#: the most one read of a tty returns (its line discipline's buffer): a read this long may have
#: left more behind, though the port shows none waiting yet
TTY_READ_MAX = 4095
#: after a read that emptied a full tty buffer, how long the reader waits for the rest of the burst
TTY_REFILL_S = 0.005
#: the most bytes one step of the reader takes from the port before decoding them
STEP_BYTES = 1 << 16
#: the module of pyserial's POSIX read: a port whose read is from elsewhere (wrapped) is read by it
_POSIX_READ = "serial.serialposix"
#: while bytes come, the ``--capture`` file's buffer is flushed at least this often (seconds); it is
#: flushed at once when the link goes quiet
CAPTURE_FLUSH_S = 1.0
#: errors of a read of a non-blocking descriptor that mean "no bytes now" (pyserial's read ignores them)
_NO_BYTES_NOW = (errno.EAGAIN, errno.EALREADY, errno.EWOULDBLOCK, errno.EINPROGRESS, errno.EINTR)


#: the longest wait between two reopens of a port that stays open and silent
REOPEN_MAX_S = 3600.0


class SerialReader(threading.Thread):
    """Reads the port, feeds the decoder, queues frames; reconnects with back-off.

    Between reads it waits as :class:`~cmsensord.read_pace.ReadPace` allows (bytes gather
    in the port's buffer until the loop wants them), so a slow link costs a few reads a
    second, not one per block.

    Link events (``link_lost``, ``link_restored``, ``reader_error``, ``reader_recovered``) are queued in ``events`` as
    (wall_ns, kind, message) for the processing loop to emit: only the loop
    writes to the sink.

    The port is opened exclusively (:func:`~cmsensord.serial_port.open_serial`, also when it is
    opened again): one another process holds (``cmsensord record``) is a port that does not open,
    retried with the back-off; its ``link_lost`` event names the holder, and one more comes
    when the reason an open fails turns to, or from, the port being held.

    When no byte comes, the capture file's buffered bytes are written out, and after ``give_up_s``
    without one (0: never) an incomplete candidate frame the decoder holds is given up
    (:meth:`~cmsensord.protocol.Decoder.give_up`): the frames that came behind it are queued then,
    not when the board sends again.
    """

    def __init__(self, port: str, *, baud: int, read_size: int, queue: FrameQueue,
                 decoder: Decoder | None = None, capture: BinaryIO | None = None,
                 reconnect_min_s: float = 0.5, reconnect_max_s: float = 5.0,
                 open_port: Callable[..., serial.Serial] | None = None):
        super().__init__(name="cmsensord-reader", daemon=True)
        self.port, self.baud, self.read_size = port, baud, read_size
        self.queue = queue
        self.decoder = decoder or Decoder()
        self.capture = capture
        self.reconnect_min_s, self.reconnect_max_s = reconnect_min_s, reconnect_max_s
        self._open_port = open_port or (lambda: open_serial(self.port, self.baud, timeout=0.05))
        self._stop_event = threading.Event()
        self.events: deque[tuple[int, str, str]] = deque(maxlen=1000)
        self.connected = threading.Event()
        self.ever_connected = False
        self.last_data = time.monotonic()
        self.opened_at = self.last_data       # when the port was last opened (monotonic)
        #: (t0_unwrapped, wall clock ns) of the newest frame read, when it was read
        self.newest: tuple[int, int] | None = None
        self.failures = 0
        self._held = False                    # the last open failed as another process holds the port
        self.errors = 0                       # unexpected exceptions since the last bytes read
        self.error: str | None = None         # the last one, as reported
        self.down: str | None = None          # why the port is not open now (None: it is)
        #: seconds without a byte on the open port before it is closed and opened again (0: never)
        self.reopen_s = 0.0
        self._reopen_wait = 0.0               # the wait now (doubles at each reopen; 0: reopen_s)
        self._reopened_at = 0.0
        self._reopens = 0                     # reopens of this silence (0: bytes came since)
        self._backoff = reconnect_min_s
        self.capture_error: str | None = None
        self._captured_at = 0.0               # when the capture file was last flushed (monotonic)
        self._capture_dirty = False           # bytes written to it since
        #: seconds without a byte before an incomplete candidate frame is given up (0: never)
        self.give_up_s = 0.0
        self.pace = ReadPace()
        self.waited = False     # the last read waited for its first byte (it timed the arrival)
        self._named_last: int | None = None     # the block named last, and the step to it
        self._named_step = 0

    def stop(self) -> None:
        self._stop_event.set()
        self.queue.named.set()

    def _event(self, kind: str, message: str) -> None:
        self.events.append((time.time_ns(), kind, message))

    def run(self) -> None:
        """Read until :meth:`stop`. A port error closes the port and reconnects with back-off;
        any other exception (a bug, a setting the driver refuses) is reported as a
        ``reader_error`` event, closes the port and is retried the same way, so the thread
        never ends before :meth:`stop`."""
        self._backoff = self.reconnect_min_s
        ser = None
        while not self._stop_event.is_set():
            try:
                ser = self._step(ser)
            except Exception as exc:  # noqa: BLE001 - a reader that died silently would look healthy
                self._unexpected(exc, ser)
                ser = None
        if ser is not None:
            _close_quietly(ser)
        self.queue.put(self.decoder.flush())

    def _step(self, ser):
        """Open the port if it is closed, then one read fed to the decoder: the port (None
        when it is closed or lost)."""
        if ser is None:
            try:
                ser = self._open_port()
            except PORT_ERRORS as exc:
                self.down = f"{self.port}: {cannot_open(self.port, exc)}; retrying"
                if self.failures == 0 or is_held(exc) != self._held:
                    self._event("link_lost", self.down)
                self._held = is_held(exc)
                self.failures += 1
                self._wait_backoff()
                return None
            if (self.ever_connected or self.failures) and not self.errors and not self._reopens:
                self._event("link_restored", f"{self.port} open again")
            self.ever_connected = True
            self.last_data = self.opened_at = time.monotonic()   # silence is counted from the open
            self.failures, self._held = 0, False
            self._backoff = self.reconnect_min_s
            self.down = None
            self.connected.set()
        try:
            data, more = self._read(ser)
            if not data:
                return self._quiet(ser)
        except PORT_ERRORS as exc:
            self._event("link_lost", f"{self.port}: {why(exc)}; reconnecting")
            self.down = f"{self.port}: {why(exc)}; reconnecting"
            self.connected.clear()
            self.failures = 1
            _close_quietly(ser)
            return None
        now = self.last_data = time.monotonic()
        self._reopen_wait = 0.0
        if self._reopens:
            self._event("link_restored", f"{self.port}: bytes again after {self._reopens} reopen(s)")
            self._reopens = 0
        self._tee(data, now)
        frames = self.decoder.feed(data)
        if frames:
            self.newest = (frames[-1].t0_unwrapped, time.time_ns())
        self.pace.arrived(now, len(data), frames[-1].t0_unwrapped if frames else None, exact=self.waited)
        self.queue.named.clear()                # a wake_at from now on ends a named_wait
        # the pause is planned before the loop gets the frames (it wakes on them, and would wait
        # for the interpreter while the reader planned), never while bytes wait (a backlog)
        pause = (0.0, False) if more else self._plan(now)
        self.queue.put(frames)
        if self.errors:
            self._event("reader_recovered", f"{self.port}: reading again after {self.errors} "
                        "reader error(s)")
            self.errors, self.error = 0, None
        self._pause(*pause)
        return ser

    def _quiet(self, ser):
        """The open port gave no byte: after ``reopen_s`` of that (a hung USB device keeps the
        port open and silent) it is closed, to be opened again at the next step; each reopen
        doubles the wait, up to :data:`REOPEN_MAX_S`, until bytes come. The first of a silence is a
        ``link_lost`` event, the next ones an INFO line; ``link_restored`` when bytes come."""
        wait = self._reopen_wait or self.reopen_s
        now = time.monotonic()
        self._idle(now)
        if not wait or now - max(self.last_data, self._reopened_at) < wait:
            return ser
        self._reopen_wait = min(2 * wait, REOPEN_MAX_S)
        self._reopened_at = now
        self._reopens += 1
        if self._reopens == 1:
            self._event("link_lost", f"{self.port}: no byte for {wait:g} s on the open port; closing it to "
                        "open it again (a hung USB device or board?)")
        else:
            log.info("link: %s: still no byte, %g s after reopen %d; opening it again", self.port, wait,
                     self._reopens - 1)
        self.connected.clear()
        _close_quietly(ser)
        return None

    def _tee(self, data: bytes, now: float) -> None:
        """``data`` to the capture file (if any), flushed when that was ``CAPTURE_FLUSH_S`` ago."""
        if self.capture is None or self.capture_error is not None:
            return
        try:
            self.capture.write(data)
        except OSError as exc:
            self._capture_failed(exc)
            return
        self._capture_dirty = True
        if now - self._captured_at >= CAPTURE_FLUSH_S:
            self._flush_capture(now)

    def _flush_capture(self, now: float) -> None:
        """The bytes the capture file buffers since its last flush, to it."""
        if not self._capture_dirty or self.capture is None or self.capture_error is not None:
            return
        self._capture_dirty, self._captured_at = False, now
        try:
            self.capture.flush()
        except OSError as exc:
            self._capture_failed(exc)

    def _capture_failed(self, exc: OSError) -> None:
        self.capture_error = f"capture file: {exc.strerror or exc}"
        self._event("disk_error", self.capture_error + "; capture stopped")

    def _idle(self, now: float) -> None:
        """A read brought no byte: the capture file's buffered bytes go to it, and after ``give_up_s``
        without a byte the decoder's incomplete candidate is given up, the frames behind it queued."""
        self._flush_capture(now)
        if self.give_up_s and now - self.last_data >= self.give_up_s and self.decoder.buffered() >= HEADER_LEN:
            self.queue.put(self.decoder.give_up())

    def _plan(self, now: float) -> tuple[float, bool]:
        """How long to wait as the pace allows (bytes gather in the port's buffer meanwhile),
        and whether :meth:`stop` alone ends the wait (False) or the loop's naming a block does
        too (True): until shortly before the block the loop waits for is due, or, when it is
        in, until the loop names the next, or until the next it expects is due when the loop
        names that one (see :class:`FrameQueue`)."""
        hint = self.queue.hint
        hold = self.pace.hold(now, hint)
        if hold > 0.001:
            return hold, False
        wait = self.pace.named_wait(now, hint)
        if wait <= 0.001:
            return 0.0, False
        expect = self._expected(hint)
        until = self.pace.hold(now, expect) if expect is not None else 0.0
        if until > 0.001:                       # named as expected, it is read when it is due
            wait = until
            self.queue.expect = expect
        return wait, True

    def _pause(self, wait: float, named: bool) -> None:
        """Wait as :meth:`_plan` said; :meth:`stop` ends the wait, and with ``named`` the loop's
        naming a block it did not expect: then until shortly before that block is due."""
        if not named:
            if wait > 0.001:
                self._stop_event.wait(wait)
            return
        if self.queue.named.wait(wait) and not self._stop_event.is_set():
            hold = self.pace.hold(time.monotonic(), self.queue.hint)    # the block named now
            if hold > 0.001:
                self._stop_event.wait(hold)

    def _expected(self, hint: int | None) -> int | None:
        """The block the loop will name after ``hint`` (named last), by the step between the
        last two named: the next /orders block of a steady stream (None before a step is known)."""
        if hint is None:
            return None
        last = self._named_last
        if hint != last:
            if last is not None and hint > last:
                self._named_step = hint - last
            self._named_last = hint
        return hint + self._named_step if self._named_step else None

    def _read(self, ser) -> tuple[bytes, bool]:
        """What the port has, waiting up to the port's timeout for the first byte (b"" if
        nothing came), and whether more may wait.  One result per arrival, so the decoder is
        fed once.  A port with a file descriptor (a real one) is waited on with ``select``,
        then read as :meth:`_burst` says, not its first byte and then the rest."""
        n = ser.in_waiting
        self.waited = not n
        if not n:
            fileno = getattr(ser, "fileno", None)
            if fileno is None:
                data = ser.read(1)
                if data and len(data) < self.read_size and ser.in_waiting:
                    data += ser.read(min(self.read_size - len(data), ser.in_waiting))
                return data, len(data) >= min(self.read_size, TTY_READ_MAX) or bool(ser.in_waiting)
            timeout = ser.timeout
            if not select.select([fileno()], [], [], READ_WAIT_S if timeout is None else timeout)[0]:
                return b"", False
            n = ser.in_waiting or 1
        data = take(ser, min(self.read_size, n))
        return self._burst(ser, data) if data else (data, False)

    def _burst(self, ser, first: bytes) -> tuple[bytes, bool]:
        """``first`` (a read) and the rest of its burst, and whether more may wait: read while
        the port shows bytes waiting (``read_size`` at a time, a tty's 4 kB at most, up to
        ``STEP_BYTES``), and when it shows none, as :meth:`_refilled` says.  Each read asks for
        the bytes the port shows, never more (pyserial's read of more than come waits the
        port's timeout for them, for ever on a port opened without one).  A port that fails
        after ``first`` (unplugged, hung up, read by another process too) ends the burst with
        the bytes read and more=True: they are decoded and captured, and the next read meets
        the error (link_lost)."""
        chunks, size, last = [first], len(first), len(first)
        full = min(self.read_size, TTY_READ_MAX)
        try:
            while size < STEP_BYTES:
                n = ser.in_waiting
                if not n:
                    n = self._refilled(ser, TTY_REFILL_S if last >= full else 0.0)
                if not n:
                    break
                chunk = take(ser, min(self.read_size, n))
                if not chunk:                   # shown but gone (another reader): not waited for
                    last = 0
                    break
                chunks.append(chunk)
                size, last = size + len(chunk), len(chunk)
        except PORT_ERRORS:
            return b"".join(chunks), True
        return b"".join(chunks) if len(chunks) > 1 else first, last >= full or size >= STEP_BYTES

    @staticmethod
    def _refilled(ser, wait: float) -> int:
        """The bytes the port shows once some come within ``wait`` seconds (0: none came).
        ``select`` on a tty first lets it move into its buffer what it holds already (the
        kernel's buffer work, pending while a writer hands a long write over 2 kB at a time);
        so with no wait, after a read that emptied the port, it finds the rest of a write
        that is in, not bytes still on the line.  After a read that emptied a full tty buffer
        it waits ``TTY_REFILL_S`` (the rest of a burst comes as the buffer drains, ~0.2 ms
        later on a pty: one read and one decoder call for the burst, not two steps of the
        reader); none by then (a board that stopped mid-burst, a flow-control stall): the
        reader reads again at once, without its pause."""
        fileno = getattr(ser, "fileno", None)
        if fileno is None or not select.select([fileno()], [], [], wait)[0]:
            return 0
        return ser.in_waiting

    def _unexpected(self, exc: Exception, ser) -> None:
        """An exception that is not a port error: report it (once while it repeats), close the
        port, wait the back-off; the caller reopens."""
        self.connected.clear()
        self.errors += 1
        text = _one_line_error(exc)
        if text != self.error:
            self.error = text
            self._event("reader_error", f"{self.port}: reader failed: {text}; closing the port, "
                        f"retrying every {self.reconnect_min_s:g}..{self.reconnect_max_s:g} s")
        if ser is not None:
            with contextlib.suppress(Exception):
                ser.close()
        self._wait_backoff()
        return None

    def _wait_backoff(self) -> None:
        """Wait the back-off (doubling up to ``reconnect_max_s``) before the next attempt; when
        the port's device is gone, only until it is there again (checked every
        ``REAPPEAR_POLL_S``): a board plugged back in is reopened at once, not seconds later."""
        gone = not os.path.exists(self.port)
        end = time.monotonic() + self._backoff
        while not self._stop_event.is_set():
            left = end - time.monotonic()
            if left <= 0 or self._stop_event.wait(min(left, REAPPEAR_POLL_S) if gone else left):
                break
            if gone and os.path.exists(self.port):
                break
        self._backoff = min(self._backoff * 2, self.reconnect_max_s)


def take(ser, n: int) -> bytes:
    """A read of ``n`` bytes the port shows waiting (``in_waiting``).  A pyserial POSIX port's
    own read waits on the descriptor with ``select`` and keeps a timeout before its one
    ``os.read``: here the descriptor is read at once (the bytes are there), with the errors
    pyserial's read raises (``read failed: ...``; a port that is readable and reads none, hung
    up); none there after all and not readable (another reader took them): b"", not waited
    for.  Any other port: its ``read``."""
    read = getattr(type(ser), "read", None)
    if (PosixSerial is None or not isinstance(ser, PosixSerial) or ser.fd is None
            or getattr(read, "__module__", None) != _POSIX_READ):
        return ser.read(n)              # not pyserial's own read (another port, or one wrapped)
    try:
        data = os.read(ser.fd, n)
        if not data and not select.select([ser.fd], [], [], 0)[0]:
            return b""                  # a tty read with nothing there returns none (VMIN 0)
    except OSError as exc:
        if exc.errno in _NO_BYTES_NOW:
            return b""
        raise serial.SerialException(f"read failed: {exc}") from None
    if not data:
        raise serial.SerialException("device reports readiness to read but returned no data "
                                     "(device disconnected or multiple access on port?)")
    return data


def _one_line_error(exc: BaseException) -> str:
    """``Type: message (at file.py:line)``, on one line: where the exception was raised."""
    text = " ".join(str(exc).split())
    frames = traceback.extract_tb(exc.__traceback__)
    where = f" (at {os.path.basename(frames[-1].filename)}:{frames[-1].lineno})" if frames else ""
    return f"{type(exc).__name__}{': ' + text if text else ''}{where}"


def _close_quietly(ser) -> None:
    with contextlib.suppress(*PORT_ERRORS):
        ser.close()

