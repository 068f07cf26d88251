"""When the live loop's tick must flush the open chunk so a kill -9 loses at most ``flush_s``.

A tick flushes when the time since the last flush plus a *margin* reaches ``flush_s``.
The margin covers what comes between now and the moment the chunk is on disk:

* the next tick may be late: twice the longest tick interval of the last ``flush_s``
  (each counted at most ``flush_s / 4``), so a live loop whose ticks alternate long and
  short, or a loaded machine's, still flushes in time;
* a message held in the reorder window (:mod:`cmsensord.sinks.reorder`) is not in the
  chunk yet: the window's horizon, turned into wall time at the rate stamps advanced over
  those ticks (10 s of stamps per second for a board at 10x), at most ``flush_s / 2``.
"""

from __future__ import annotations

import collections

from cmsensord.sinks.reorder import ReorderWindow

__all__ = ["FlushMargin"]


class FlushMargin:
    """The ticks of the last ``flush_s``: ``(time, interval before it, newest stamp)``."""

    def __init__(self, flush_s: float, now: float):
        self.flush_s = float(flush_s)
        self._ticks: collections.deque[tuple[float, float, int]] = collections.deque()
        self._ticks.append((now, 0.0, -1))

    def tick(self, now: float, window: ReorderWindow | None) -> None:
        """Note a tick at ``now`` (monotonic seconds) and the newest stamp in ``window``."""
        ticks = self._ticks
        ticks.append((now, now - ticks[-1][0], window.newest_ns if window is not None else -1))
        while now - ticks[0][0] > self.flush_s:
            ticks.popleft()

    def margin(self, window: ReorderWindow) -> float:
        """Seconds before ``flush_s`` after the last flush at which the last tick flushes."""
        ticks, quarter = self._ticks, self.flush_s / 4
        late = 2 * min(max(dt for _, dt, _ in ticks), quarter)
        (t0, _, stamp0), (now, _, newest) = ticks[0], ticks[-1]
        if not len(window) or now <= t0 or stamp0 < 0 or newest <= stamp0:
            return late
        rate = (newest - stamp0) / (now - t0)        # stamp ns per second
        return late + min(window.horizon_ns / rate, 2 * quarter)
