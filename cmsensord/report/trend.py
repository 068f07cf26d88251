"""A bounded time series for trend plots: any number of points in, at most ``2 * size`` kept.

:class:`Trend` keeps (time, value) pairs. When it holds ``2 * size`` points it
merges neighbours in pairs (the earlier time, the larger value: a peak hold, so
an alarm-level excursion is never averaged away) and from then on merges each
new pair of points the same way, so a week of 1-Hz records costs the memory of
a few thousand points and keeps its shape.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Trend"]


class Trend:
    """(time_ns, value) points, at most ``2 * size`` kept by pairwise peak-hold merging."""

    def __init__(self, size: int = 2000) -> None:
        self.size = size
        self.t: list[int] = []
        self.v: list[float] = []
        self.stride = 1             # input points per kept point
        self._pending: tuple[int, float, int] | None = None   # (t, max v, count) of a part-filled point
        self.count = 0              # points added

    def add(self, t_ns: int, value: float | None) -> None:
        """One point; ``None`` (a value the log wrote as null) is skipped."""
        if value is None:
            return
        self.count += 1
        pending = self._pending
        if pending is None:
            pending = (t_ns, value, 1)
        else:
            pending = (pending[0], value if value > pending[1] else pending[1], pending[2] + 1)
        if pending[2] == self.stride:
            self._keep(pending[0], pending[1])
            pending = None
        self._pending = pending

    def _keep(self, t_ns: int, value: float) -> None:
        self.t.append(t_ns)
        self.v.append(value)
        if len(self.t) >= 2 * self.size:
            n = len(self.t) // 2 * 2
            self.t = self.t[0:n:2]
            v = np.asarray(self.v[:n])
            self.v = np.maximum(v[0::2], v[1::2]).tolist()
            self.stride *= 2

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(times [ns] as int64, values) of the kept points, a part-filled last point included,
        in time order (points added out of it, as a log's clamped messages come, are put in it)."""
        t, v = list(self.t), list(self.v)
        if self._pending is not None:
            t.append(self._pending[0])
            v.append(self._pending[1])
        ta, va = np.asarray(t, dtype=np.int64), np.asarray(v, dtype=float)
        if ta.size > 1 and bool(np.any(ta[1:] < ta[:-1])):
            order = np.argsort(ta, kind="stable")
            ta, va = ta[order], va[order]
        return ta, va

    def __bool__(self) -> bool:
        return self.count > 0
