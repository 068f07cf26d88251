"""MCAP rotation by time and size: every message lands in exactly one finished file."""

from __future__ import annotations

import dataclasses

from cmsensord.config import OutputConfig
from cmsensord.sinks.mcap_sink import read_messages
from cmsensord.sinks.rotating import RotatingSink


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def event(i):
    return {"kind": "config", "channel": None, "message": f"message {i}"}


def test_rotation_by_time_keeps_every_message(tmp_path):
    clock = FakeClock()
    out = dataclasses.replace(OutputConfig(), dir=str(tmp_path), rotate_s=10.0)
    sink = RotatingSink(out, clock=clock)
    for i in range(100):
        sink.write("/cm/events", "event", 1_000_000_000 * (i + 1), event(i))
        clock.t += 0.5                      # 50 s of messages: a new file every 10 s
    sink.close()
    assert len(sink.paths) == 5
    assert sorted(tmp_path.glob("*.mcap")) == sorted(sink.paths)
    assert not list(tmp_path.glob("*.part"))
    got = [m["message"] for p in sink.paths for _, _, m in read_messages(p)]
    assert got == [f"message {i}" for i in range(100)]


def test_rotation_by_size(tmp_path):
    clock = FakeClock()
    out = dataclasses.replace(OutputConfig(), dir=str(tmp_path), rotate_mb=0.002, flush_s=1.0,
                              compression="none")
    sink = RotatingSink(out, clock=clock)
    for i in range(300):
        sink.write("/cm/events", "event", 1_000_000_000 * (i + 1), event(i))
        clock.t += 0.25                     # a chunk is flushed every 4 messages
    sink.close()
    assert len(sink.paths) >= 3
    assert all(p.stat().st_size < 6000 for p in sink.paths)
    got = [m["message"] for p in sink.paths for _, _, m in read_messages(p)]
    assert got == [f"message {i}" for i in range(300)]
