"""Rate limits of repeated events: at most ``RATE_BURST`` of a kind on a channel in ``RATE_S``,
and at most ``LONG_BURST`` in ``LONG_S`` (a fault that never stops: one frame lost every few
seconds is a few lines in ten minutes, not 50,000 a day in the journal).

A :class:`RateLimit` is fed events one by one (:meth:`RateLimit.admit`).  The first event of
a (kind, channel) opens an interval of ``rate_s`` of event time at its stamp; events stamped
within it are admitted while fewer than ``burst`` were, and the rest are held back:
counted, their ``count`` fields summed, and handed back as one :class:`Summary` when the
interval is closed, by the next event of the (kind, channel) stamped outside it, by
:meth:`RateLimit.over` (the intervals a stamp is past) or :meth:`RateLimit.close_all`.
:class:`RateLimits` chains limits (an event the first admits goes on to the next), with the
same methods. Fed the same events in the same order, a limit admits and summarises the same ones.

A summary's message names what its counts count: the events held back, and the sum of their
``count`` fields in the unit :data:`COUNT_UNITS` gives the kind (frames, pulses, messages).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["COUNT_UNITS", "RATE_S", "RATE_BURST", "LONG_S", "LONG_BURST", "RateLimit", "RateLimits",
           "Summary"]

#: at most RATE_BURST events of a kind per channel in RATE_S seconds of event time; then a summary
RATE_S = 1.0
RATE_BURST = 5
#: ... and at most LONG_BURST of those in LONG_S
LONG_S = 600.0
LONG_BURST = 10
#: what the ``count`` field of an event of a kind counts, where every event of it that has one
#: counts the same thing; a summary of another kind writes the sum as "their counts add up to"
COUNT_UNITS = {"frames_lost": "frame", "frames_repeated": "frame", "channels": "frame",
               "queue_overflow": "frame", "tacho_extra_pulse": "pulse", "tacho_missed_pulse": "pulse",
               "mqtt_queue": "message", "salvage": "message"}


@dataclass
class Summary:
    """The events of one (kind, channel) held back in the interval from ``since_ns``."""

    kind: str
    channel: str | None
    since_ns: int
    last_ns: int            # the newest stamp of the interval's events
    n: int                  # events held back
    count: int              # their ``count`` fields, summed
    rate_s: float = RATE_S  # the limit that held them back
    burst: int = RATE_BURST

    def message(self) -> str:
        """``n`` events held back, and the sum of their ``count`` fields in the kind's unit."""
        unit = COUNT_UNITS.get(self.kind)
        counted = (f" ({self.count} {unit}(s) between them)" if unit is not None
                   else f" (their counts add up to {self.count})")
        return (f"{self.n} more {self.kind} event(s) in {(self.last_ns - self.since_ns) / 1e9:.3g} s"
                + (counted if self.count else "")
                + f": at most {self.burst} per {self.rate_s:g} s are written one by one")

    def fields(self) -> dict[str, Any]:
        return {"summarised": self.n, **({"count": self.count} if self.count else {})}


@dataclass
class _Interval:
    since_ns: int
    last_ns: int
    admitted: int = 1
    n: int = 0
    count: int = 0


class RateLimit:
    """Which events of the rate-limited kinds are written one by one, and the summaries of the rest."""

    def __init__(self, rate_s: float = RATE_S, burst: int = RATE_BURST) -> None:
        self.rate_s, self.burst = rate_s, burst
        self._rate_ns = int(rate_s * 1e9)
        self._open: dict[tuple[str, str | None], _Interval] = {}

    def admit(self, kind: str, channel: str | None, stamp_ns: int, count: int) -> tuple[Summary | None, bool]:
        """Whether the event is written one by one, and the summary of an interval it closes."""
        key = (kind, channel)
        h = self._open.get(key)
        if h is not None and 0 <= stamp_ns - h.since_ns < self._rate_ns:
            h.last_ns = max(h.last_ns, stamp_ns)
            if h.admitted < self.burst:
                h.admitted += 1
                return None, True
            h.n += 1
            h.count += count
            return None, False
        closed = self._close(key) if h is not None else None
        self._open[key] = _Interval(stamp_ns, stamp_ns)
        return closed, True

    def over(self, now_ns: int) -> list[Summary]:
        """The summaries of the intervals ``now_ns`` is outside of (closed)."""
        return [s for key, h in list(self._open.items())
                if not 0 <= now_ns - h.since_ns < self._rate_ns and (s := self._close(key)) is not None]

    def close_all(self) -> list[Summary]:
        """The summaries of every interval (all closed)."""
        return [s for key in list(self._open) if (s := self._close(key)) is not None]

    def _close(self, key: tuple[str, str | None]) -> Summary | None:
        h = self._open.pop(key)
        return Summary(key[0], key[1], h.since_ns, h.last_ns, h.n, h.count, self.rate_s, self.burst) if h.n else None


class RateLimits:
    """Limits in a chain (by default RATE_BURST in RATE_S, then LONG_BURST in LONG_S): an event is
    written one by one when every limit admits it; each limit summarises what it held back."""

    def __init__(self, limits: tuple[RateLimit, ...] | None = None) -> None:
        self.limits = limits or (RateLimit(), RateLimit(LONG_S, LONG_BURST))

    def admit(self, kind: str, channel: str | None, stamp_ns: int, count: int) -> tuple[list[Summary], bool]:
        """Whether the event is written one by one, and the summaries of the intervals it closes."""
        closed: list[Summary] = []
        for limit in self.limits:
            summary, ok = limit.admit(kind, channel, stamp_ns, count)
            if summary is not None:
                closed.append(summary)
            if not ok:
                return closed, False
        return closed, True

    def over(self, now_ns: int) -> list[Summary]:
        """The summaries of the intervals ``now_ns`` is outside of, in every limit."""
        return [s for limit in self.limits for s in limit.over(now_ns)]

    def close_all(self) -> list[Summary]:
        """The summaries of every interval of every limit."""
        return [s for limit in self.limits for s in limit.close_all()]
