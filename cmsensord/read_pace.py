"""How long the serial reader may wait between reads: fewer, larger reads on a slow link.

The board sends a block's frames every 10 ms; read as they come, that is ~100 thread
wake-ups, reads and decoder calls a second, which cost more than processing an RMS
stream.  The live loop takes the frames only when the block completing the
next /orders block or decision is in (:meth:`FrameQueue.wake_at`), so the reader may let
bytes gather in the port's kernel buffer meanwhile:

* with a block to wake at (``wake_t0``), until ``-margin_s`` (2 ms) after that block is
  due: its arrival time extrapolated from the earliest arrival of the last
  ``recent_s`` (a read after a wait comes late; the one waiting for the next block does not)
  at the board's rate as measured (board samples per wall second between reads
  ``window_s`` to twice that apart, from the frames' t0 and arrival times).  A block that
  comes by then is read with the backlog before it, in one read (one wake-up of the reader
  per /orders block at 1x, not two), at most 2 ms after it came at its earliest;
  one that comes later is waited for in the read after the backlog's, so the orders are
  not delayed by more than those 2 ms.  Only a read that waited for its bytes tells when a
  block arrived (``exact``): one after such a hold found them waiting, and taken as arrivals
  they would put the due time later at every read.  So when no read has waited for ``probe_s``,
  or when more than half of ``buffer_bytes`` come between the newest read and that block (a
  fast stream, RAW 4 channels: the port's buffer overflowed with the later read), the hold
  ends ``probe_margin_s`` (5 ms) before the block is due instead: the backlog is read, then
  the block as it comes, which measures its arrival.  The earliest
  of a short span, not of the whole window: on a loaded machine the arrivals jitter by
  tens of ms, and a rare early one long ago would make every block look late ever after
  (the newest exact arrival is kept however old);
* when that block is already in (the loop has not named the next yet), not at all
  (:meth:`named_wait`: until the loop names the next), unless it was read towards in far
  holds (below) and the two before it were as far apart as it is from the one before: then
  as for the block that far after it (the next decision: the reader does not wake when the
  loop names it);
* not while behind: when the newest frame read came more than ``behind_s`` after it was
  due, the read took only part of a backlog (a read returns at most ``read_size`` bytes,
  and a tty's input buffer shows only part of what waits), and the rest is read at once;
* with the block to wake at more than ``2 MAX_HOLD_S`` off (RMS mode's next decision), as
  for a late block, until ``-margin_s`` after it is due, at most ``far_hold_s``
  (``FAR_HOLD_S``): the decision's bytes and its block in one read (one wake-up of the reader
  a decision; a block that came later than that is waited for in the read after the
  backlog's, which measures its arrival); unless no read has waited for ``far_probe_s``
  (``FAR_PROBE_S``): then not at all (the probe: that read waits for the next frame, which
  measures the arrival times, and the hold for the block follows it);
* with no block to wake at (no output chain yet), ``idle_hold_s``;
* never longer than ``buffer_bytes`` take to arrive at the measured byte rate (a fast
  link, a sped-up simulator: the kernel's buffer must not fill), and not before the
  rates are measured (``min_span_s`` of arrivals).

Pure arithmetic over the times and counts it is given (:meth:`arrived`, :meth:`hold`,
:meth:`named_wait`).
"""

from __future__ import annotations

from collections import deque

#: the longest wait for a block to wake at (the live loop's period)
MAX_HOLD_S = 0.1
#: ... when that block is more than 2 MAX_HOLD_S off (a decision, RMS mode: once a second), the
#: longest wait for it, held for as a late block (a 1-s decision's bytes and its block in one
#: read); the daemon makes it no longer than half the link's stall_s (a hold must not
#: look like a silent link)
FAR_HOLD_S = 1.0
#: ... while a read waited for its bytes in the last FAR_PROBE_S; else the read is at once, the
#: probe, which waits for the next frame (so the due time cannot drift off unmeasured), and the
#: hold follows it: a probe every third 1-s decision, one more read then, not at each
FAR_PROBE_S = 2.5


class ReadPace:
    """The reader's wait before its next read (see module docstring)."""

    def __init__(self, *, buffer_bytes: int = 16384, idle_hold_s: float = 0.05, margin_s: float = -0.002,
                 window_s: float = 10.0, min_span_s: float = 1.0, behind_s: float = 0.02,
                 recent_s: float = 1.0, probe_s: float = 0.5, probe_margin_s: float = 0.005):
        self.buffer_bytes, self.idle_hold_s, self.margin_s = buffer_bytes, idle_hold_s, margin_s
        self.behind_s, self.recent_s = behind_s, recent_s
        self.probe_s, self.probe_margin_s = probe_s, probe_margin_s
        self._exact_at: float | None = None                  # the newest read that waited for its bytes
        self.far_hold_s, self.far_probe_s = FAR_HOLD_S, FAR_PROBE_S
        self._far: int | None = None                         # the block last read towards in far holds
        self._step = self._far_step = 0     # the distance from the one before; twice the same: a period
        self.window_s, self.min_span_s = window_s, min_span_s
        self._refs: deque[tuple[float, int, int]] = deque()  # (wall, t0, bytes so far), window_s apart
        self._recent: deque[tuple[float, int]] = deque()     # (wall, t0) of the reads of the last recent_s
        self._earliest: tuple[float, int] | None = None      # the one of them that came earliest
        self._bytes = 0
        self.last: tuple[float, int] | None = None           # (wall, t0) of the newest frame
        self.rate: float | None = None                       # board samples per wall second
        self.byte_rate: float | None = None
        self.late_s = 0.0                   # the newest frame came this long after it was due

    def arrived(self, now: float, nbytes: int, t0: int | None, exact: bool = True) -> None:
        """A read of ``nbytes`` at ``now``; ``t0``: the newest frame's t0_unwrapped (None: none);
        ``exact``: the read waited for its bytes (so ``now`` is when the newest frame came),
        else they were waiting (it came before)."""
        self._bytes += nbytes
        if t0 is None:
            return
        if self.last is not None and t0 < self.last[1]:     # the board's clock went back: start over
            self._refs.clear()
            self._recent.clear()
            self.rate, self._earliest = None, None
        # how late it came, by the arrivals before it (a late read's own arrival skews them)
        self.late_s = now - self._due(t0) if self.rate and self._recent else 0.0
        self.last = (now, t0)
        recent = self._recent
        if exact or not recent:
            recent.append((now, t0))
            self._exact_at = now if exact else self._exact_at
        while len(recent) > 1 and now - recent[0][0] > self.recent_s:
            recent.popleft()
        self._earliest = None
        refs = self._refs
        if not refs or now - refs[-1][0] >= self.window_s:
            refs.append((now, t0, self._bytes))
            if len(refs) > 2:
                refs.popleft()
        w0, t00, b0 = refs[0]
        span = now - w0
        if span >= self.min_span_s:
            self.rate = (t0 - t00) / span if t0 > t00 else None
            self.byte_rate = (self._bytes - b0) / span

    def hold(self, now: float, wake_t0: int | None) -> float:
        """Seconds the reader may wait before its next read (0: read now)."""
        if self.rate is None or self.last is None or not self.byte_rate:
            return 0.0
        if self._behind(now):
            return 0.0
        cap = self.buffer_bytes / self.byte_rate
        if wake_t0 is None:
            return min(cap, self.idle_hold_s)
        if wake_t0 <= self.last[1]:
            if wake_t0 != self._far or not self._far_step:
                return 0.0
            wake_t0 += self._far_step       # a far block in: the next, one period on (no named_wait)
        due = self._due(wake_t0)
        if due - now > 2 * MAX_HOLD_S:
            if wake_t0 != self._far:        # the period: two far blocks the same distance apart
                step = wake_t0 - self._far if self._far is not None and wake_t0 > self._far else 0
                self._far_step = step if step == self._step else 0
                self._far, self._step = wake_t0, step
            if self._probe(now):
                return 0.0
            return min(cap, self.far_hold_s, due - self.margin_s - now)
        if wake_t0 == self._far:            # read towards in far holds: a probe is a read now
            if self._probe(now):
                return 0.0                  # (it waits for the next frame: an exact arrival)
            late = True
        else:
            late = (self._exact_at is not None and now - self._exact_at < self.probe_s
                    and (due - self.last[0]) * self.byte_rate <= self.buffer_bytes / 2)
        return max(0.0, min(cap, MAX_HOLD_S, due - (self.margin_s if late else self.probe_margin_s) - now))

    def _probe(self, now: float) -> bool:
        """No read has waited for its bytes in the last ``far_probe_s``: the next read is the
        probe (at once: it waits for the next frame, an exact arrival)."""
        return self._exact_at is None or now - self._exact_at >= self.far_probe_s

    def named_wait(self, now: float, wake_t0: int | None) -> float:
        """Seconds the reader may wait for the loop to name its next block, when the block it
        named last is in (0 otherwise): the loop handles that block first, and no block it
        waits for comes meanwhile."""
        if (wake_t0 is None or self.rate is None or self.last is None or not self.byte_rate
                or wake_t0 > self.last[1] or self._behind(now)):
            return 0.0
        return min(self.buffer_bytes / self.byte_rate, MAX_HOLD_S)

    def _due(self, t0: int) -> float:
        """When board sample ``t0`` arrives at the earliest, by the reads of the last
        ``recent_s`` (the rate is measured)."""
        rate = self.rate
        assert rate and self._recent
        if self._earliest is None:          # the read whose frame came earliest: once per read
            w1, t1 = self._recent[-1]
            self._earliest = min(self._recent, key=lambda a: a[0] - w1 + (t1 - a[1]) / rate)
        w, t = self._earliest
        return w + (t0 - t) / rate

    def _behind(self, now: float) -> bool:
        """The newest frame read came more than ``behind_s`` after it was due: more wait."""
        return self.late_s > self.behind_s
