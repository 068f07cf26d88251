"""The RMS values a board can send, and the ones it cannot.

An RMS frame's value is the RMS of a block of ``(count - offset) * scale`` over 12-bit counts
(docs/PROTOCOL.md, RMS), so with the channel's STATUS scale and offset it is at least 0 and at
most ``max(|0 - offset|, |4095 - offset|) * |scale|`` m/s² (times ``1 + RMS_TOLERANCE``: the
board rounds to float32).  A value of a monitored channel that is not finite, negative or
above that bound (a firmware fault, a dead channel sending NaN, a value like 3e38 that would
blind the AKF bank for its window) is impossible: it becomes a missing observation, with a
``decode_error`` event stamped at its frame's t0 (rate-limited as any event), and is counted
per channel for the exit summary.  Before a STATUS, or for a channel the STATUS does not
describe, only finite and not negative is checked.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from cmsensord.config import ChannelConfig
from cmsensord.monitor.events import Event
from cmsensord.protocol import COUNT_MAX, Status

#: relative slack on the ADC's bound: a board's float32 RMS of a block at full scale may round above it
RMS_TOLERANCE = 1e-4
#: the bound of a channel no STATUS describes: a finite float32
_NO_BOUND = float(np.finfo(np.float32).max)


def rms_bounds(status: Status | None, n: int) -> np.ndarray:
    """The largest possible RMS value of each of ``n`` board channels (m/s², float64)."""
    out = np.full(n, _NO_BOUND)
    if status is not None:
        for i, (scale, offset) in enumerate(zip(status.scale[:n], status.offset[:n])):
            out[i] = max(abs(offset), abs(COUNT_MAX - offset)) * abs(scale) * (1 + RMS_TOLERANCE)
    return out


class RmsBounds:
    """Checks RMS frames' values against what the board can send (see module docstring);
    ``bad``: the impossible values so far, per monitored channel."""

    def __init__(self) -> None:
        self.bad: dict[str, int] = {}
        self._cached: tuple[Status | None, int, np.ndarray] | None = None

    def check(self, vals: np.ndarray, t0: np.ndarray, channels: Sequence[ChannelConfig], status: Status | None,
              stamp_ns: Callable[[int], int]) -> list[Event]:
        """``vals`` (blocks x board channels, the blocks starting at ``t0``) with the impossible
        values of the monitored ``channels`` set to NaN in place; a ``decode_error`` each."""
        n = vals.shape[1]
        cols = [ch.index for ch in channels if ch.index < n]
        if not cols:
            return []
        cached = self._cached
        if cached is None or cached[0] is not status or cached[1] != n:
            cached = self._cached = (status, n, rms_bounds(status, n))
        bound = cached[2][cols]
        sub = vals[:, cols]
        ok = (sub >= 0) & (sub <= bound)            # False for NaN
        if ok.all():
            return []
        names = {ch.index: ch.name for ch in channels}
        events = []
        for row, k in zip(*np.nonzero(~ok)):
            col, v, t = cols[k], float(sub[row, k]), int(t0[row])
            name = names[col]
            self.bad[name] = self.bad.get(name, 0) + 1
            events.append(Event("decode_error", name, f"RMS frame at t0 {t}: {name}'s value {v:.7g} m/s² is "
                                f"impossible ({_why(v, float(bound[k]))}): a missing observation", stamp_ns(t),
                                {"count": 1}))
            vals[row, col] = np.nan
        return events


def _why(v: float, bound: float) -> str:
    if not np.isfinite(v):
        return "not finite"
    if v < 0:
        return "negative"
    return f"above {bound:.6g} m/s², the most 12-bit counts give at its STATUS scale and offset"
