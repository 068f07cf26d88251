"""Test helper: run a byte stream through the daemon's Processor, as a replay does."""

from __future__ import annotations

from cmsensord.pipeline import ListSink, Processor
from cmsensord.protocol import Decoder


def run_processor(data: bytes, cfg, *, chunk: int = 40_000, clock_ns=lambda: 0):
    """Feed ``data`` in reads of ``chunk`` bytes; returns (sink, processor, decoder)."""
    sink = ListSink()
    proc = Processor(cfg, sink, clock_ns=clock_ns)
    dec = Decoder()
    for k in range(0, len(data), chunk):
        proc.handle(dec.feed(data[k:k + chunk]))
    proc.handle(dec.flush())
    proc.finish()
    return sink, proc, dec
