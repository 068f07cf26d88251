"""Rate limits of repeated events: at most ``RATE_BURST`` of a kind on a channel in ``RATE_S``.

A :class:`RateLimit` is fed events one by one (:meth:`RateLimit.admit`).  The first event of
a (kind, channel) opens an interval of ``RATE_S`` of event time at its stamp; events stamped
within it are admitted while fewer than ``RATE_BURST`` were, and the rest are held back:
counted, their ``count`` fields summed, and handed back as one :class:`Summary` when the
interval is closed, by the next event of the (kind, channel) stamped outside it, by
:meth:`RateLimit.over` (the intervals a stamp is past) or :meth:`RateLimit.close_all`.
Fed the same events in the same order, a limit admits and summarises the same ones.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["RATE_S", "RATE_BURST", "RateLimit", "Summary"]

#: at most RATE_BURST events of a kind per channel in RATE_S seconds of event time; then a summary
RATE_S = 1.0
RATE_BURST = 5
_RATE_NS = int(RATE_S * 1e9)


@dataclass
class Summary:
    """The events of one (kind, channel) held back in the interval from ``since_ns``."""

    kind: str
    channel: str | None
    since_ns: int
    last_ns: int            # the newest stamp of the interval's events
    n: int                  # events held back
    count: int              # their ``count`` fields, summed

    def message(self) -> str:
        return (f"{self.n} more {self.kind} event(s) in {(self.last_ns - self.since_ns) / 1e9:.3g} s"
                + (f" ({self.count} in all)" if self.count else "")
                + f": at most {RATE_BURST} per {RATE_S:g} s are written one by one")

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

    def __init__(self) -> None:
        self._open: dict[tuple[str, str | None], _Interval] = {}

    def admit(self, kind: str, channel: str | None, stamp_ns: int, count: int) -> tuple[Summary | None, bool]:
        """Whether the event is written one by one, and the summary of an interval it closes."""
        key = (kind, channel)
        h = self._open.get(key)
        if h is not None and 0 <= stamp_ns - h.since_ns < _RATE_NS:
            h.last_ns = max(h.last_ns, stamp_ns)
            if h.admitted < RATE_BURST:
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
                if not 0 <= now_ns - h.since_ns < _RATE_NS and (s := self._close(key)) is not None]

    def close_all(self) -> list[Summary]:
        """The summaries of every interval (all closed)."""
        return [s for key in list(self._open) if (s := self._close(key)) is not None]

    def _close(self, key: tuple[str, str | None]) -> Summary | None:
        h = self._open.pop(key)
        return Summary(key[0], key[1], h.since_ns, h.last_ns, h.n, h.count) if h.n else None
