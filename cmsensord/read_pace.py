"""How long the serial reader may wait between reads: fewer, larger reads on a slow link.

The board sends a block's frames every 10 ms; read as they come, that is ~100 thread
wake-ups, reads and decoder calls a second, which cost more than processing an RMS
stream (issue 13).  The live loop takes the frames only when the block completing the
next /orders block or decision is in (:meth:`FrameQueue.wake_at`), so the reader may let
bytes gather in the port's kernel buffer meanwhile:

* with a block to wake at (``wake_t0``), until shortly (``margin_s``) before that
  block is due: its arrival time extrapolated from the board's clock as measured
  (board samples per wall second over the last ``window_s``, from the frames' t0 and
  arrival times; the earliest arrivals, as a read after a wait comes late), so the
  reader waits in its read when that block comes and the orders are not delayed;
* when that block is already in (the loop has not named the next yet), not at all
  (:meth:`named_wait`: until the loop names the next);
* not while behind: when the newest frame read came more than ``behind_s`` after it was
  due, the read took only part of a backlog (a read returns at most ``read_size`` bytes,
  and a tty's input buffer shows only part of what waits), and the rest is read at once;
* with no block to wake at (no output chain yet), ``idle_hold_s``;
* never longer than ``buffer_bytes`` take to arrive at the measured byte rate (a fast
  link, a sped-up simulator: the kernel's buffer must not fill), and not before the
  rates are measured (``min_span_s`` of arrivals).

Pure arithmetic over the times and counts it is given (:meth:`arrived`, :meth:`hold`,
:meth:`named_wait`).
"""

from __future__ import annotations

#: the longest wait for a block to wake at (the live loop's period)
MAX_HOLD_S = 0.1


class ReadPace:
    """The reader's wait before its next read (see module docstring)."""

    def __init__(self, *, buffer_bytes: int = 16384, idle_hold_s: float = 0.05, margin_s: float = 0.01,
                 window_s: float = 10.0, min_span_s: float = 1.0, behind_s: float = 0.02):
        self.buffer_bytes, self.idle_hold_s, self.margin_s = buffer_bytes, idle_hold_s, margin_s
        self.behind_s = behind_s
        self.window_s, self.min_span_s = window_s, min_span_s
        self._ref: tuple[float, int, int] | None = None     # (wall, t0, bytes so far) at the window's start
        self._bytes = 0
        self.last: tuple[float, int] | None = None           # (wall, t0) of the newest frame
        self.rate: float | None = None                       # board samples per wall second
        self.byte_rate: float | None = None
        self._base: float | None = None     # arrival of the window's first t0: the last window's
        self._win: float | None = None      # ... and this window's estimate
        self.late_s = 0.0                   # the newest frame came this long after it was due

    def arrived(self, now: float, nbytes: int, t0: int | None) -> None:
        """A read of ``nbytes`` at ``now``; ``t0``: the newest frame's t0_unwrapped (None: none)."""
        self._bytes += nbytes
        if t0 is None:
            return
        # how late it came, by the rates as they were (a late read's own arrival skews them)
        self.late_s = now - self._due(t0) if self._win is not None and self.rate else 0.0
        if self.last is not None and t0 < self.last[1]:     # the board's clock went back: start over
            self._ref, self.rate, self._base, self._win = None, None, None, None
        self.last = (now, t0)
        if self._ref is None:
            self._ref = (now, t0, self._bytes)
            return
        w0, t00, b0 = self._ref
        span = now - w0
        if span >= self.min_span_s:
            self.rate = (t0 - t00) / span if t0 > t00 else None
            self.byte_rate = (self._bytes - b0) / span
        if not self.rate:
            return
        # when the window's first t0 arrived, from the earliest arrival (a read after a wait
        # is late; the one waiting for the block to wake at is not): this window's and the
        # last one's, so an estimate is never older than two windows
        base = now - (t0 - t00) / self.rate
        self._win = base if self._win is None else min(self._win, base)
        if span >= self.window_s:
            shift = (t0 - t00) / self.rate
            self._ref = (now, t0, self._bytes)
            self._base, self._win = self._win + shift, now

    def hold(self, now: float, wake_t0: int | None) -> float:
        """Seconds the reader may wait before its next read (0: read now)."""
        if self.rate is None or self.last is None or not self.byte_rate:
            return 0.0
        if self._behind(now):
            return 0.0
        cap = self.buffer_bytes / self.byte_rate
        if wake_t0 is None:
            return min(cap, self.idle_hold_s)
        if wake_t0 <= self.last[1] or self._win is None:
            return 0.0
        return max(0.0, min(cap, MAX_HOLD_S, self._due(wake_t0) - self.margin_s - now))

    def named_wait(self, now: float, wake_t0: int | None) -> float:
        """Seconds the reader may wait for the loop to name its next block, when the block it
        named last is in (0 otherwise): the loop handles that block first, and no block it
        waits for comes meanwhile."""
        if (wake_t0 is None or self.rate is None or self.last is None or not self.byte_rate
                or wake_t0 > self.last[1] or self._behind(now)):
            return 0.0
        return min(self.buffer_bytes / self.byte_rate, MAX_HOLD_S)

    def _due(self, t0: int) -> float:
        """When board sample ``t0`` arrives at the earliest (the rates are measured)."""
        assert self._ref is not None and self._win is not None and self.rate
        base = self._win if self._base is None else min(self._base, self._win)
        return base + (t0 - self._ref[1]) / self.rate

    def _behind(self, now: float) -> bool:
        """The newest frame read came more than ``behind_s`` after it was due: more wait."""
        return self.late_s > self.behind_s
