"""Rate limits of repeated events: at most ``RATE_BURST`` of a kind on a channel in ``RATE_S``,
and at most ``LONG_BURST`` in ``LONG_S`` (a fault that never stops: one frame lost every few
seconds is a few lines in ten minutes, not 50,000 a day in the journal).

A :class:`RateLimit` is fed events one by one (:meth:`RateLimit.admit`).  The first event of
a (kind, channel) opens an interval of ``rate_s`` of event time at its stamp; events stamped
before its end (before its start too: a stamp that jumps back, a board reset, a late report,
opens no interval of its own) are admitted while fewer than ``burst`` were, and the rest are
held back: counted, their ``count`` fields summed, and handed back as one :class:`Summary` when
the interval is closed, by the next event of the (kind, channel) stamped at or past its end, by
:meth:`RateLimit.over` (the intervals a stamp is past the end of) or :meth:`RateLimit.close_all`.
:class:`RateLimits` chains limits, with the same methods: an event the first admits goes on to
the next, and so does a summary a limit hands back (a line of its own, standing for the
events it counts): a later limit that holds it back adds its events and counts to its own
summary.  So the last limit bounds every line, summaries included: under a flood that never
stops, ``LONG_BURST`` lines (events or per-second summaries) in each ``LONG_S`` and one summary
of the rest, and each event is either admitted or counted in exactly one summary handed back.
Fed the same events in the same order, a limit admits and summarises the same ones.

A summary's message names what its counts count: the events held back, and the sum of their
``count`` fields in the unit :data:`COUNT_UNITS` gives the kind (frames, pulses, messages).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["ALARM_KINDS", "COUNT_UNITS", "RATE_S", "RATE_BURST", "LONG_S", "LONG_BURST", "RateLimit", "RateLimits",
           "Summary"]

#: the alarm transitions, limited per alarm and in the journal only (:mod:`.events`)
ALARM_KINDS = frozenset({"alarm_alert", "alarm_danger", "alarm_clear"})
#: at most RATE_BURST events of a kind per channel in RATE_S seconds of event time; then a summary
RATE_S = 1.0
RATE_BURST = 5
#: ... and at most LONG_BURST lines in LONG_S: events the first limit admits and its summaries
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
    level: int = 0          # the highest journal level among them (their line's level)

    def message(self) -> str:
        """``n`` events held back, and the sum of their ``count`` fields in the kind's unit."""
        unit = COUNT_UNITS.get(self.kind)
        counted = (f" ({self.count} {unit}(s) between them)" if unit is not None
                   else f" (their counts add up to {self.count})")
        text = (f"{self.n} more {self.kind} event(s) in {(self.last_ns - self.since_ns) / 1e9:.3g} s"
                + (counted if self.count else "")
                + f": at most {self.burst} per {self.rate_s:g} s are written one by one")
        if self.kind in ALARM_KINDS:        # keyed by the alarm, limited in the journal alone
            return (f"{self.channel}: {text} in the journal, all in /cm/events; an alarm that changes this "
                    "often chatters: an on_delay_s or off_delay_s on its rule steadies it")
        return text

    def fields(self) -> dict[str, Any]:
        return {"summarised": self.n, **({"count": self.count} if self.count else {})}


@dataclass
class _Interval:
    since_ns: int
    last_ns: int
    admitted: int = 1
    n: int = 0
    count: int = 0
    level: int = 0


class RateLimit:
    """Which events of the rate-limited kinds are written one by one, and the summaries of the rest."""

    def __init__(self, rate_s: float = RATE_S, burst: int = RATE_BURST) -> None:
        self.rate_s, self.burst = rate_s, burst
        self._rate_ns = int(rate_s * 1e9)
        self._open: dict[tuple[str, str | None], _Interval] = {}

    def admit(self, kind: str, channel: str | None, stamp_ns: int, count: int,
              n: int = 1, level: int = 0) -> tuple[Summary | None, bool]:
        """Whether the line (an event, or a summary of ``n`` events) of journal ``level`` is
        written, and the summary of an interval it closes; held back, its ``n`` events and
        ``count`` go to the summary, whose level is the highest of the lines it stands for."""
        key = (kind, channel)
        h = self._open.get(key)
        if h is not None and stamp_ns - h.since_ns < self._rate_ns:
            h.last_ns = max(h.last_ns, stamp_ns)
            if h.admitted < self.burst:
                h.admitted += 1
                return None, True
            h.n += n
            h.count += count
            h.level = max(h.level, level)
            return None, False
        closed = self._close(key) if h is not None else None
        self._open[key] = _Interval(stamp_ns, stamp_ns)
        return closed, True

    def over(self, now_ns: int) -> list[Summary]:
        """The summaries of the intervals ``now_ns`` is at or past the end of (closed)."""
        return [s for key, h in list(self._open.items())
                if now_ns - h.since_ns >= self._rate_ns and (s := self._close(key)) is not None]

    def close_all(self) -> list[Summary]:
        """The summaries of every interval (all closed)."""
        return [s for key in list(self._open) if (s := self._close(key)) is not None]

    def _close(self, key: tuple[str, str | None]) -> Summary | None:
        h = self._open.pop(key)
        return (Summary(key[0], key[1], h.since_ns, h.last_ns, h.n, h.count, self.rate_s, self.burst, h.level)
                if h.n else None)


class RateLimits:
    """Limits in a chain (by default RATE_BURST in RATE_S, then LONG_BURST in LONG_S): an event is
    written one by one when every limit admits it; a limit's summary is written when every later
    limit admits it, and is otherwise counted in the summary of the limit that held it back."""

    def __init__(self, limits: tuple[RateLimit, ...] | None = None) -> None:
        self.limits = limits or (RateLimit(), RateLimit(LONG_S, LONG_BURST))

    def admit(self, kind: str, channel: str | None, stamp_ns: int, count: int,
              level: int = 0) -> tuple[list[Summary], bool]:
        """Whether the event (of journal ``level``) is written one by one, and the summaries to
        write of the intervals it closes (oldest first)."""
        closed: list[Summary] = []
        for i, limit in enumerate(self.limits):
            summary, ok = limit.admit(kind, channel, stamp_ns, count, level=level)
            if summary is not None:
                closed += self._onward(summary, i + 1)
            if not ok:
                return closed, False
        return closed, True

    def over(self, now_ns: int) -> list[Summary]:
        """The summaries to write of the intervals ``now_ns`` is past, in every limit."""
        return [t for i, limit in enumerate(self.limits) for s in limit.over(now_ns)
                for t in self._onward(s, i + 1)]

    def close_all(self) -> list[Summary]:
        """The summaries to write of every interval of every limit."""
        return [t for i, limit in enumerate(self.limits) for s in limit.close_all()
                for t in self._onward(s, i + 1)]

    def _onward(self, s: Summary, first: int) -> list[Summary]:
        """A summary through the limits from index ``first``: [] when one holds it back (its
        events counted there), else [it], after the summaries of the intervals it closes."""
        closed: list[Summary] = []
        for i in range(first, len(self.limits)):
            summary, ok = self.limits[i].admit(s.kind, s.channel, s.last_ns, s.count, s.n, s.level)
            if summary is not None:
                closed += self._onward(summary, i + 1)
            if not ok:
                return closed
        return closed + [s]
