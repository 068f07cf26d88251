"""Opening the MCAP sink of a run, and where its events go."""

from __future__ import annotations

from cmsensord.config import Config
from cmsensord.sinks.rotating import RotatingSink


def open_sink(cfg: Config, metadata: dict[str, str]) -> RotatingSink:
    """The rotating MCAP sink of ``cfg.output``; SinkError if the directory is unusable."""
    return RotatingSink(cfg.output, metadata=metadata)


def route_sink_events(sink: RotatingSink, proc) -> None:
    """The sink's events (salvage, disk errors, retention) become the Processor's events:
    /cm/events, proc.events and the journal. Queued ones (salvage at start) go now."""
    sink.on_event = lambda kind, message, **fields: proc.event(kind, None, message, **fields)
