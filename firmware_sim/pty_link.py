"""The board's serial port, played by a pseudo-terminal.

Owns the link end of the simulated board: :class:`PtyEndpoint` opens a pty
(``os.openpty``), puts the slave in raw mode and keeps the slave fd open (so
the pty never hangs up between readers), and publishes the slave's device
path (``path``) for the daemon to open like ``/dev/ttyACM0``.
:meth:`PtyEndpoint.run` writes each block's bytes to the master at
``speed`` x real time, each block at its absolute deadline from a monotonic
clock (no accumulated sleep drift). The master is non-blocking: when a write
would block (the reader is slow or absent and the pty's buffer is full) the
bytes that did not fit are dropped and counted, like a UART without flow
control; the endpoint itself never blocks.  With ``flow_control`` (hardware
handshake, RTS/CTS) it waits for the reader instead, never dropping a byte:
the stream slows down, the time waited is counted (``stalled_s``) and the
following blocks keep the pace from where the reader let it go on.
"""

from __future__ import annotations

import errno
import math
import os
import select
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import asdict, dataclass

from .board import Board

__all__ = ["LinkStats", "PtyEndpoint"]


@dataclass
class LinkStats:
    """What :meth:`PtyEndpoint.run` did (cumulative over runs)."""

    blocks: int = 0  # block periods sent (or attempted)
    frames: int = 0
    bytes_offered: int = 0
    bytes_written: int = 0
    dropped_bytes: int = 0  # did not fit in the pty (reader slow or absent)
    dropped_blocks: int = 0  # blocks that lost at least one byte
    elapsed_s: float = 0.0  # wall time spent in run()
    max_lag_s: float = 0.0  # worst lateness of a block behind its deadline
    stalled_s: float = 0.0  # flow control: time spent waiting for the reader

    def as_dict(self) -> dict:
        return asdict(self)


class PtyEndpoint:
    """A pty whose slave is the simulated board's serial port."""

    def __init__(self, *, link: str | None = None,
                 injector: Callable[[bytes], bytes] | None = None, flow_control: bool = False) -> None:
        """``link``: also publish the port as this symlink (a stable name, like a udev rule
        gives a USB board; replaced atomically, removed on close). ``injector``: line
        noise applied to every block's bytes (:class:`firmware_sim.faults.StreamInjector`).
        ``flow_control``: wait for the reader when the pty is full instead of dropping."""
        self.flow_control = flow_control
        self.master, self.slave = os.openpty()
        try:
            tty.setraw(self.slave)
            os.set_blocking(self.master, False)
            self.path = os.ttyname(self.slave)
        except BaseException:
            os.close(self.master)
            os.close(self.slave)
            raise
        self.stats = LinkStats()
        self._closed = False
        self.injector = injector
        self.link = link
        if link is not None:
            tmp = f"{link}.{os.getpid()}.tmp"
            try:
                os.symlink(self.path, tmp)
                os.replace(tmp, link)
            except OSError:
                self.close()
                raise

    def write_block(self, data: bytes, stop: threading.Event | None = None) -> int:
        """Write what fits now (with flow control: all of it, waiting for the reader unless
        ``stop`` is set); returns the number of bytes written (the rest is dropped)."""
        view = memoryview(data)
        written = 0
        while written < len(view):
            try:
                n = os.write(self.master, view[written:])
            except BlockingIOError:
                if self.flow_control and self._wait_writable(stop):
                    continue
                break
            except OSError as exc:  # EIO: no slave side (cannot happen while we hold it)
                if exc.errno == errno.EIO:
                    break
                raise
            if n <= 0:
                break
            written += n
        s = self.stats
        s.bytes_offered += len(view)
        s.bytes_written += written
        if written < len(view):
            s.dropped_bytes += len(view) - written
            s.dropped_blocks += 1
        return written

    def _wait_writable(self, stop: threading.Event | None) -> bool:
        """Flow control: wait until the pty takes bytes again; False when ``stop`` is set."""
        t = time.monotonic()
        poller = select.poll()
        poller.register(self.master, select.POLLOUT)
        try:
            while not (stop is not None and stop.is_set()):
                if poller.poll(100):
                    return True
            return False
        finally:
            self.stats.stalled_s += time.monotonic() - t

    def run(self, board: Board, *, speed: float = 1.0, duration_s: float | None = None,
            stop: threading.Event | None = None) -> LinkStats:
        """Stream ``board`` for ``duration_s`` (None: until ``stop``) at ``speed`` x real time.

        speed 0 or inf: as fast as possible. Returns :attr:`stats`.
        """
        if self._closed:
            raise ValueError("the pty endpoint is closed")
        if not (speed >= 0):
            raise ValueError(f"speed must be >= 0 (0 or inf: as fast as possible), got {speed!r}")
        stop = stop if stop is not None else threading.Event()
        paced = speed > 0 and math.isfinite(speed)
        period = board.block_len / board.fs / speed if paced else 0.0
        n_blocks = board.n_blocks_for(duration_s) if duration_s is not None else None
        s = self.stats
        t_start = time.monotonic()
        try:
            for i, (data, n_frames) in enumerate(board.iter_blocks(n_blocks)):
                if stop.is_set():
                    break
                if paced:
                    # block i is complete (and sent) at the end of its period
                    deadline = t_start + (i + 1) * period
                    wait = deadline - time.monotonic()
                    if wait > 0:
                        if stop.wait(wait):
                            break
                    else:
                        s.max_lag_s = max(s.max_lag_s, -wait)
                stalled = s.stalled_s
                self.write_block(data if self.injector is None else self.injector(data), stop)
                t_start += s.stalled_s - stalled     # the reader held the line: the pace goes on from here
                s.blocks += 1
                s.frames += n_frames
        finally:
            s.elapsed_s += time.monotonic() - t_start
        return s

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self.link is not None:
                try:
                    if os.path.realpath(self.link) == self.path:   # still ours: unplugged
                        os.unlink(self.link)
                except OSError:
                    pass
            os.close(self.master)
            os.close(self.slave)

    def __enter__(self) -> PtyEndpoint:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        try:  # noqa: SIM105 - no contextlib here: __del__ may run at exit, when module globals are gone
            self.close()
        except Exception:
            pass
