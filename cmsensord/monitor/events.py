"""The event log: one place for event records, where they go and their journal level.

An event is written to ``/cm/events`` (schema ``event``), kept among the recent
ones (status line, exit summary), counted by kind, logged to the journal at the
level of its kind, and handed to ``on_event`` when one is given.  A producer
that knows better (the sink about its own routine work) passes ``log_level``.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from cmsensord.monitor import messages

log = logging.getLogger("cmsensord")

#: how events go to the log (the journal): per-AKF flags are detail, the
#: severity index and everything about the link or the disk is news.
LOG_LEVEL = {
    "anomaly_onset": logging.DEBUG, "anomaly_clear": logging.DEBUG,
    "failure": logging.WARNING, "frames_lost": logging.WARNING, "link_lost": logging.WARNING,
    "decode_error": logging.WARNING, "queue_overflow": logging.WARNING,
    "disk_error": logging.ERROR, "link_stalled": logging.WARNING,
    "decision_rule": logging.WARNING, "time_base": logging.WARNING, "anomaly_held": logging.WARNING,
}


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

    ``default_stamp`` gives the stamp of an event that brings none (the newest
    observation's, or the wall clock before there is one).
    """

    def __init__(self, sink, default_stamp: Callable[[], int],
                 on_event: Callable[[dict], None] | None = None):
        self.sink = sink
        self.default_stamp = default_stamp
        self.on_event = on_event
        self.recent: deque[dict] = deque(maxlen=1000)
        self.counts: dict[str, int] = {}

    def emit(self, kind: str, channel: str | None, message: str, stamp_ns: int | None = None, *,
             log_level: int | None = None, **extra: Any) -> None:
        self._write(kind, channel, message, stamp_ns, extra, log_level)

    def add(self, events) -> None:
        """Emit :class:`Event` records made by a part of the chain, in order."""
        for ev in events:
            self._write(ev.kind, ev.channel, ev.message, ev.stamp_ns, ev.fields, None)

    def _write(self, kind: str, channel: str | None, message: str, stamp_ns: int | None,
               extra: dict[str, Any], log_level: int | None) -> None:
        m = messages.event(self.default_stamp() if stamp_ns is None else stamp_ns, kind, channel,
                           message, extra)
        self.sink.write(*m)
        self.recent.append(m.msg)
        self.counts[kind] = self.counts.get(kind, 0) + 1
        log.log(LOG_LEVEL.get(kind, logging.INFO) if log_level is None else log_level, "%s: %s", kind, message)
        if self.on_event is not None:
            self.on_event(m.msg)
