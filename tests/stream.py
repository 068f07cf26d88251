"""Test helper: run a byte stream through the daemon's Processor, as a replay does."""

from __future__ import annotations

from cmsensord.monitor.processor import Processor
from cmsensord.sinks.memory import ListSink
from cmsensord.source import ByteStreamSource


def run_processor(data: bytes, cfg, *, chunk: int = 40_000, clock_ns=lambda: 0):
    """Feed ``data`` in reads of ``chunk`` bytes; returns (sink, processor, decoder)."""
    sink = ListSink()
    proc = Processor(cfg, sink, clock_ns=clock_ns)
    source = ByteStreamSource.of(data, chunk)
    with source:
        for frames in source:
            proc.handle(frames)
    proc.finish()
    return sink, proc, source.decoder
