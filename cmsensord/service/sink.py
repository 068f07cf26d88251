"""Opening the MCAP sink of a run, and where its events go (with the journal level they deserve)."""

from __future__ import annotations

import logging

from cmsensord.config import Config
from cmsensord.monitor.events import EventLog
from cmsensord.sinks.rotating import RotatingSink

#: disk_error events that report routine work or a recovery (details.action): INFO in the journal
_DISK_NEWS = frozenset({"resumed", "retention", "salvaged"})


def open_sink(cfg: Config, metadata: dict[str, str], *, background_salvage: bool = False
              ) -> RotatingSink:
    """The rotating MCAP sink of ``cfg.output``; SinkError if the directory is unusable.
    ``background_salvage``: leftover ``.part`` files are salvaged by a thread (the daemon)."""
    return RotatingSink(cfg.output, metadata=metadata, background_salvage=background_salvage)


def sink_log_level(kind: str, fields: dict) -> int | None:
    """The journal level of a sink event: INFO for its routine work and recoveries (retention,
    logging resumed, salvage), None (the kind's level) otherwise."""
    if kind == "disk_error" and (fields.get("details") or {}).get("action") in _DISK_NEWS:
        return logging.INFO
    return None


def route_sink_events(sink: RotatingSink, log: EventLog) -> None:
    """The sink's events (salvage, disk errors, retention) go to the event log: /cm/events,
    the recent events and the journal. Queued ones (salvage at start) go now."""
    sink.on_event = lambda kind, message, **fields: log.emit(
        kind, None, message, log_level=sink_log_level(kind, fields), **fields)
