"""The event log: one place for event records, where they go and their journal level.

An event is written to ``/cm/events`` (schema ``event``) and, as a ``foxglove.Log``
record at its journal level, to ``/cm/log`` (Foxglove's Log panel), kept among the recent
ones (status line, exit summary), counted by kind, logged to the journal at the
level of its kind, and handed to ``on_event`` when one is given.  A producer
that knows better (the sink about its own routine work) passes ``log_level``.

Repeated events of one kind on one channel are rate-limited
(:mod:`cmsensord.monitor.event_rate`): at most ``RATE_BURST`` in an interval of ``RATE_S``
of event time starting at the first (and, in the journal, at most ``LONG_BURST`` lines in
``LONG_S``, the per-second summaries among them: a fault or a flood that never stops is a few
lines each ten minutes); the ones after them within an interval are counted (their ``count``
fields summed) and written as one summary event of that kind when it ends.  The limit
of ``/cm/events`` and ``/cm/log`` is applied as the records are written, in stamp order (a
stamp's records in the order of kind, channel and message), so which events are written one
by one and what the summaries say depend on the stream only, not on how it was read (live
and replay write the same); a summary is written where its interval ends (before the first
record stamped past it), or at the end of the run or a step back of the wall clock (a board
reset does not end it: the stamps of the next segment go on from the newest).  The journal, the recent
list and ``on_event`` get the events as they come, limited in that order (their summaries
with the next event of the kind after the interval, or at the end of the run:
:meth:`EventLog.summarise`).  Every occurrence stays in :attr:`EventLog.counts`.  Kinds in
``UNLIMITED`` (start and stop, the severity chain's paired onsets and clears, failures and
decisions' notes, the alarm manager's transitions, and the captures written, which their
budget bounds) are never held back from ``/cm/events``; the alarm transitions
(``JOURNAL_LIMITED``) are limited in the journal all the same, per alarm: a rule without
delays on a value hovering at its level changes each second.

``/cm/events`` goes forward in time: an event carries the stamp of what it is
about (a frame, a tacho edge, a decision), and parts of the chain report late
(the tacho, the order tracker), so records wait in a reorder buffer and are
written in stamp order once a decision is ``HOLD_S`` past them
(:meth:`EventLog.release`, called before each decision is written, so where
they land among the other messages depends on the stream only), the oldest
when more than ``MAX_PENDING`` wait, and all at a board reset and at the end
of the run.  Events of the wall clock, not of the stream (``WALL_KINDS``: start
and stop, the link, the reader, the queue, the disk) are written at once.  A
record that still comes after a later one was written (or stamped before its
time segment started) is written at the newest stamp instead.  The journal,
the recent list and ``on_event`` get the events they are told at once; ``watch`` (the
captures' triggers) gets the records as they are written, in stamp order, after ``settle``
has taken the stream's own triggers up to their stamp, and nothing is released at or
after a stamp a part of the chain still ``owed`` (a capture in progress).
"""

from __future__ import annotations

import heapq
import logging
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from cmsensord.journal import VERBOSE
from cmsensord.monitor import messages
from cmsensord.monitor.event_rate import ALARM_KINDS, RateLimit, RateLimits, Summary

log = logging.getLogger("cmsensord")

#: how events go to the log (the journal): per-AKF flags are detail (VERBOSE: -v), the
#: severity index and everything about the link or the disk is news.
LOG_LEVEL = {
    "anomaly_onset": VERBOSE, "anomaly_clear": VERBOSE,
    "failure": logging.WARNING, "frames_lost": logging.WARNING, "frames_repeated": logging.WARNING,
    "link_lost": logging.WARNING,
    "decode_error": logging.WARNING, "queue_overflow": logging.WARNING,
    "disk_error": logging.ERROR, "retention": logging.INFO, "link_stalled": logging.WARNING,
    "decision_rule": logging.WARNING, "time_base": logging.WARNING, "anomaly_held": logging.WARNING,
    "alarm_alert": logging.WARNING, "alarm_danger": logging.ERROR, "alarm_clear": logging.WARNING,
    "alarm_ack": logging.WARNING, "alarm_no_baseline": logging.WARNING,
    "alarm_restored": logging.WARNING, "alarm_not_restored": logging.WARNING,
    "alarm_state_error": logging.WARNING, "signal_lost": logging.WARNING, "signal_back": logging.WARNING,
    "lines_unresolved": logging.WARNING, "line_harmonics": logging.WARNING, "band_above_nyquist": logging.WARNING,
    "band_too_narrow": logging.WARNING, "flat_blocks": logging.WARNING,
}

#: kinds never rate-limited: made once, in pairs, or at most once per decision period
UNLIMITED = frozenset({"start", "stop", "anomaly_onset", "anomaly_clear", "failure",
                       "decision_rule", "anomaly_held", "severity_change",
                       "alarm_alert", "alarm_danger", "alarm_clear", "alarm_ack", "alarm_no_baseline",
                       "alarm_restored", "alarm_not_restored", "capture", "signal_lost", "signal_back"})
#: kinds of UNLIMITED that the journal limits all the same: an alarm's transitions (each is in
#: /cm/events and /cm/alarms), keyed by the alarm; a rule without delays on a value hovering at
#: its level makes one a second (a chattering alarm)
JOURNAL_LIMITED = ALARM_KINDS
#: records wait until the processed stream is this far past them (events reported late; the
#: sink's log-time window learns this lateness, so it is also what a kill -9 may cost the log)
HOLD_S = 1.0
#: events of the daemon and its surroundings, stamped by the wall clock: written at once
WALL_KINDS = frozenset({"start", "stop", "link_lost", "link_restored", "link_stalled", "reader_error",
                        "reader_recovered", "reader_died", "queue_overflow", "disk_error", "retention",
                        "salvage", "mqtt_link", "mqtt_queue"})
#: most records waiting (a stream with no decisions)
MAX_PENDING = 1000
#: a record stamped further than this past the processed stream waits as if stamped there
AHEAD_S = 600.0


@dataclass
class Event:
    """One event record made by a part of the chain: kind, channel, message, stamp, extra fields."""

    kind: str
    channel: str | None
    message: str
    stamp_ns: int | None = None
    fields: dict[str, Any] = field(default_factory=dict)


class EventLog:
    """Events -> the sink, the recent list, the counts and the journal.

    ``default_stamp`` gives the stamp of an event that brings none (the end of the
    newest observation, or the wall clock before there is one); ``segment_start``
    the first stamp of the current time segment (0: none yet).
    """

    def __init__(self, sink, default_stamp: Callable[[], int],
                 on_event: Callable[[dict], None] | None = None,
                 segment_start: Callable[[], int] = lambda: 0):
        self.sink = sink
        self.default_stamp = default_stamp
        self.on_event = on_event
        self.segment_start = segment_start
        self.hold = True                  # False: records are written at once (after the run)
        self._pending: list[tuple[int, int, messages.Message, int]] = []
        self._n = 0
        #: called with (kind, channel, message, stamp_ns, fields) of every event written, in the
        #: order written (captures: their triggers)
        self.watch: Callable[[str, str | None, str, int, dict], None] | None = None
        #: the earliest stamp of events a part of the chain still owes (a capture in progress is
        #: stamped at its trigger): :meth:`release` writes none at or after it
        self.owed: Callable[[], int | None] = lambda: None
        #: called with a stamp (None: all) before records from it on are written: the triggers
        #: of the stream up to it are taken (captures' periodic ticks), in order with the events
        self.settle: Callable[[int | None], None] = lambda upto_ns: None
        self.recent: deque[dict] = deque(maxlen=1000)
        self.counts: dict[str, int] = {}
        self._newest = 0                  # stamp of the newest event written
        self._told = RateLimits()         # as events come: the journal, recent, on_event, WALL_KINDS
        self._written = RateLimits((RateLimit(),))   # as records are written, in stamp order: /cm/events
        self._wall = RateLimits((RateLimit(),))      # WALL_KINDS as they come: /cm/events

    def emit(self, kind: str, channel: str | None, message: str, stamp_ns: int | None = None, *,
             log_level: int | None = None, **extra: Any) -> None:
        self._write(kind, channel, message, stamp_ns, extra, log_level)

    def add(self, events) -> None:
        """Emit :class:`Event` records made by a part of the chain, in order."""
        for ev in events:
            self._write(ev.kind, ev.channel, ev.message, ev.stamp_ns, ev.fields, None)

    def summarise(self, now_ns: int | None = None, *, final: bool = False) -> None:
        """The journal's summaries of the intervals over at ``now_ns`` (the default stamp), or of
        all (``final``: the end of the run), and those of the wall-clock kinds on /cm/events; the
        stream's records get theirs as they are written."""
        now = self.default_stamp() if now_ns is None else now_ns
        for s in self._told.close_all() if final else self._told.over(now):
            self._tell_summary(s)
        for s in self._wall.close_all() if final else self._wall.over(now):
            self._put_summary(s)

    def _write(self, kind: str, channel: str | None, message: str, stamp_ns: int | None,
               extra: dict[str, Any], log_level: int | None) -> None:
        stamp = self.default_stamp() if stamp_ns is None else stamp_ns
        self.counts[kind] = self.counts.get(kind, 0) + 1
        told = written = True
        count = int(extra.get("count", 0) or 0)
        level = LOG_LEVEL.get(kind, logging.INFO) if log_level is None else log_level
        if kind not in UNLIMITED or kind in JOURNAL_LIMITED:
            key = extra.get("alarm", channel) if kind in JOURNAL_LIMITED else channel
            closed, told = self._told.admit(kind, key, stamp, count, level)
            for s in closed:
                self._tell_summary(s)
        if kind not in UNLIMITED and kind in WALL_KINDS:
            closed, written = self._wall.admit(kind, channel, stamp, count, level)
            for s in closed:
                self._put_summary(s)
        m = messages.event(stamp, kind, channel, message, extra)
        if kind in WALL_KINDS:
            if written:
                self._put(m, m.stamp_ns, level)
        else:
            self._hold(m, level)
        if told:
            self._tell(m, level)

    def _tell_summary(self, s: Summary) -> None:
        """A summary of the events not told: to the journal at the highest level among them (a
        WALL_KINDS kind's to the sink are its own limit's)."""
        m = messages.event(s.last_ns, s.kind, s.channel, s.message(), s.fields())
        self._tell(m, _summary_level(s))

    def _hold(self, m: messages.Message, level: int) -> None:
        """A record of the stream into the reorder buffer (written at once after the run)."""
        self._n += 1
        key = min(m.stamp_ns, self.default_stamp() + int(AHEAD_S * 1e9))
        heapq.heappush(self._pending, (key, self._n, m, level))
        if not self.hold:
            self.flush()
        elif len(self._pending) > MAX_PENDING:
            self._write_upto(self._pending[0][0])

    def _tell(self, m: messages.Message, level: int) -> None:
        ev = m.msg
        self.recent.append(ev)
        log.log(level, "%s: %s", ev["kind"], ev["message"])
        if self.on_event is not None:
            self.on_event(ev)

    def release(self, processed_ns: int) -> None:
        """Write the records at least ``HOLD_S`` before ``processed_ns`` (a decision's
        stamp; live, the wall clock while no frames come) and before what is :attr:`owed`,
        in stamp order."""
        self._write_upto(processed_ns - int(HOLD_S * 1e9), floored=True)

    def due(self, processed_ns: int) -> bool:
        """Whether :meth:`release` at ``processed_ns`` would write a record."""
        return bool(self._pending) and self._pending[0][0] <= self._floor(processed_ns - int(HOLD_S * 1e9))

    def _floor(self, upto_ns: int) -> int:
        owed = self.owed()
        return upto_ns if owed is None else min(upto_ns, owed - 1)

    def flush(self, *, summaries: bool = True) -> None:
        """Write every waiting record, in stamp order, and with ``summaries`` end the intervals of
        the rate limit of ``/cm/events`` (their summaries written).  A board reset writes the records
        only: the next segment's stamps go on from the newest, and so does the limit (a t0 stepping
        back every frame is 5 time_base records a second, not one a frame)."""
        self._write_upto(None)
        if summaries:
            for s in self._written.close_all():
                self._put_summary(s)

    def went_back(self) -> None:
        """The time base went back (the wall clock stepped back): every waiting record is
        written, every interval of the rate limits ends (its summary written), and the records
        after may be stamped before them."""
        self.flush()
        self.summarise(final=True)
        self._newest = 0

    def _write_upto(self, upto_ns: int | None, floored: bool = False) -> None:
        """The records up to ``upto_ns`` (None: all), in stamp order, the stream's triggers before
        each settled first; ``floored``: none at or after what is :attr:`owed`."""
        pending = self._pending
        while True:
            limit = self._floor(upto_ns) if floored and upto_ns is not None else upto_ns
            if not pending or (limit is not None and pending[0][0] > limit):
                self.settle(limit)
                break
            key = pending[0][0]
            self.settle(key)
            if floored and upto_ns is not None and key > self._floor(upto_ns):
                continue                        # a trigger before it started a capture: owed
            group = [heapq.heappop(pending)]
            while pending and pending[0][0] == key:
                group.append(heapq.heappop(pending))
            self._write_group(key, group)

    def _write_group(self, key: int, group: list[tuple[int, int, messages.Message, int]]) -> None:
        """The records of one stamp, in the order they came; which of the rate-limited ones are
        written is decided in the order of kind, channel and message (the stream's, not the reads'),
        by the stamp they are written at (:meth:`_put`): the limit holds in the log's time, whatever
        the stamps the records were made with (one stamped ahead of the stream holds the ones after
        it at its stamp, and they count in its second)."""
        at = self._written_at(key)
        for s in self._written.over(at):
            self._put_summary(s)
        skip = set()
        for _, n, m, level in sorted(group, key=_by_content):
            ev = m.msg
            if ev["kind"] not in UNLIMITED:
                closed, ok = self._written.admit(ev["kind"], ev["channel"], at, int(ev.get("count", 0) or 0),
                                                 level)
                for s in closed:
                    self._put_summary(s)
                if not ok:
                    skip.add(n)
        for _, n, m, level in group:
            if n not in skip:
                self._put(m, key, level)

    def _put_summary(self, s: Summary) -> None:
        self._put(messages.event(s.last_ns, s.kind, s.channel, s.message(), s.fields()), s.last_ns,
                  _summary_level(s))

    def _written_at(self, stamp: int) -> int:
        """The stamp a record of ``stamp`` is written at: never before the newest written, nor
        before the current segment's start."""
        return max(stamp, self._newest, self.segment_start())

    def _put(self, m: messages.Message, stamp: int, level: int) -> None:
        """The event at ``stamp`` (or the newest stamp written), and its foxglove.Log copy."""
        at = self._written_at(stamp)
        self.sink.write(*(m if at == m.stamp_ns else m._replace(stamp_ns=at)))
        ev = m.msg
        self.sink.write(*messages.log(at, level, ev["kind"], ev.get("channel"), ev["message"]))
        self._newest = at
        if self.watch is not None:
            extra = {k: v for k, v in ev.items() if k not in ("kind", "channel", "message")}
            self.watch(ev["kind"], ev["channel"], ev["message"], m.stamp_ns, extra)


def _summary_level(s: Summary) -> int:
    """The journal level of a summary: the highest among the events it counts (a summary of
    routine INFO lines of a kind is no ERROR), the kind's when it does not say."""
    return s.level or LOG_LEVEL.get(s.kind, logging.INFO)


def _by_content(entry: tuple[int, int, messages.Message, int]) -> tuple[str, str, str]:
    ev = entry[2].msg
    return ev["kind"], ev["channel"] or "", ev["message"]
