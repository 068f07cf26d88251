"""The bounded frame queue between the serial reader thread and the processing loop: the oldest
RAW frames shed first when the loop falls behind, batches by time, and a wake-up as soon as the
block completing the next output is in (:meth:`FrameQueue.wake_at`)."""

from __future__ import annotations

import threading
import time
from collections import deque

from cmsensord.protocol import Frame, FrameType

__all__ = ["FrameQueue"]


class FrameQueue:
    """Bounded FIFO of frames between the reader thread and the loop.

    When the loop falls behind and the queue is full, the oldest RAW frames
    go first (they are most of the bytes, and a lost RAW block is a missing
    observation the filters handle); RMS, STATUS and TACHO frames are dropped
    only when no RAW frame is left to drop (then the oldest), so the severity
    chain and the shaft speed keep their data as long as possible.  Every drop
    is counted (``drops``, ``raw_drops``); memory stays bounded by ``maxlen``.

    :meth:`get` batches by time: it returns once ``enough`` frames wait or its
    ``timeout`` has passed, so the loop can hand the Processor many frames per call
    (its cost is mostly per call, not per frame) while waking at a steady pace; and
    as soon as the frames of the block :meth:`wake_at` names are in (the block that
    completes the next output: batching adds no latency to it).  While that block is still
    to come, a ``get`` given ``hold_s`` keeps the queued frames at its timeout (it returns
    none, for the loop's periodic work) until the oldest has waited ``hold_s``: a board whose
    block comes a little late is not handled in two calls, and the loop can wake at its
    pace for its timers while the Processor is called once per output.

    ``named`` is set by every :meth:`wake_at` (the reader waits for it when the block named
    last is in: the loop names the next one once it has handled that block), but one naming the
    block the reader said it expects next (``expect``): the reader then sleeps until that block
    is due, and a naming that tells it nothing new does not wake it (one wake-up of the reader
    per /orders block less at 1x).
    """

    def __init__(self, maxlen: int):
        self.maxlen = int(maxlen)
        self._q: deque[Frame] = deque()
        self._cond = threading.Condition()
        self.drops = 0          # frames dropped, all types
        self.raw_drops = 0      # of which RAW
        self.closed = False
        self._enough = 1        # frames the waiting get() wants before it returns early
        self._wake_t0: int | None = None    # get() returns once this block's frames are in
        self.hint: int | None = None        # the last wake_at() block, kept after the get (reader)
        self.expect: int | None = None      # the block the reader expects named next (used once)
        self._woken = False
        self._since = 0.0                   # monotonic time the oldest queued frame came
        self.named = threading.Event()

    def put(self, frames: list[Frame]) -> None:
        if not frames:
            return
        with self._cond:
            if not self._q:
                self._since = time.monotonic()
            self._q.extend(frames)
            over = len(self._q) - self.maxlen
            if over > 0:
                self._shed(over)
            if self._wake_t0 is not None and _completes(frames[-1], self._wake_t0):
                self._woken = True
            if self._woken or len(self._q) >= self._enough:
                self._cond.notify()

    def _shed(self, over: int) -> None:
        """Drop ``over`` frames: the oldest RAW ones, then the oldest of any type."""
        raw = FrameType.RAW
        n_raw = sum(1 for f in self._q if f.type == raw)
        k = min(over, n_raw)
        if k:
            kept: deque[Frame] = deque()
            left = k
            for f in self._q:
                if left and f.type == raw:
                    left -= 1
                    continue
                kept.append(f)
            self._q = kept
            self.raw_drops += k
        for _ in range(over - k):
            self._q.popleft()
        self.drops += over

    def wake_at(self, t0: int | None) -> None:
        """The next :meth:`get` returns as soon as the block starting at board sample ``t0``
        is in: its TACHO frame (the last of a block), its RMS frame (the whole of an RMS block
        without a tacho), or any frame of a later block.  None:
        no such wish.  Used once: a get clears it."""
        with self._cond:
            self._wake_t0 = self.hint = t0
            self._woken = t0 is not None and bool(self._q) and _completes(self._q[-1], t0)
            expected = t0 is not None and t0 == self.expect
            self.expect = None
        if not expected:
            self.named.set()

    def poke(self) -> None:
        """The waiting :meth:`get` returns now (something besides frames wants the loop)."""
        with self._cond:
            self._woken = True
            self._cond.notify()

    def get(self, timeout: float, enough: int = 1, hold_s: float = 0.0) -> list[Frame]:
        """All queued frames, once at least ``enough`` wait (at once if they already do),
        the block of :meth:`wake_at` is in, ``timeout`` seconds have passed (then possibly
        none) or the queue is closed.  At the timeout, with a block of :meth:`wake_at` still
        to come and the oldest frame queued less than ``hold_s`` ago: none (they stay)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            self._enough = max(1, min(enough, self.maxlen))
            try:
                while len(self._q) < self._enough and not self._woken and not self.closed:
                    now = time.monotonic()
                    left = deadline - now
                    if left <= 0:
                        if self._wake_t0 is not None and self._q and now - self._since < hold_s:
                            return []
                        break
                    self._cond.wait(left)
            finally:
                self._enough = 1
                self._wake_t0, self._woken = None, False
            out = list(self._q)
            self._q.clear()
            return out

    def close(self) -> None:
        with self._cond:
            self.closed = True
            self._cond.notify_all()

    def __len__(self) -> int:
        return len(self._q)


def _completes(f: Frame, t0: int) -> bool:
    """``f`` shows the block at ``t0`` is in: its TACHO frame (the last of a block), its RMS
    frame (the whole of an RMS block without a tacho), or a frame of a later block."""
    return f.t0_unwrapped > t0 or (f.t0_unwrapped == t0 and f.type in _LAST)


_LAST = (FrameType.TACHO, FrameType.RMS)
