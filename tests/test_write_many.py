"""Messages written in runs: ``write_many`` of the MCAP file and of the rotating
sink, and a severity message's ``r`` encoded from a cache, give the bytes of one ``write``
per message with the plain encoder: the same files, byte for byte, with flushes, full
chunks, rotations by time and size, late messages held by the reorder window, events,
non-finite values and a message that cannot be encoded; the Processor writing a capture
through them gives the same files as through a sink that takes one message at a time."""

from __future__ import annotations

import dataclasses
import math
import random

import numpy as np
import pytest

from cmsensord.config import OutputConfig
from cmsensord.errors import SinkError
from cmsensord.sinks import mcap_encoding
from cmsensord.sinks.mcap_encoding import encode_message
from cmsensord.sinks.mcap_file import McapSink
from cmsensord.sinks.mcap_sink import read_messages
from cmsensord.sinks.rotating import RotatingSink
from fakes import FakeClock, replay_ticking

WALL = 1_790_000_000.0          # the files' names


def message(rnd: random.Random, k: int, stamp: int) -> tuple[str, str, int, dict]:
    """A message of one of the daemon's kinds, now and then with values JSON cannot carry."""
    kind = rnd.choice(["severity", "severity", "indicators", "event", "diagnostics"])
    ch = f"ch{rnd.randrange(3)}"
    if kind == "severity":
        r = rnd.choice([[0.0166, 0.0292, 0.0418], [0.5, 1.25], [1.0, 2.0], [0.0, -0.0, 0.3],
                        [0.1, math.nan], [0.1, math.inf], [1, 2.5], [True, 0.5], [0.25]])
        return (f"/cm/{ch}/severity", "severity", stamp, {
            "channel": ch, "severity_index": rnd.choice([0.0, 0.3, 1.0, math.nan]), "level": 0,
            "anomaly": [rnd.randrange(2) for _ in range(3)], "outliers": [rnd.randrange(40) for _ in range(3)],
            "f_r": 28.66, "r": list(r), "failure": False, "missing": 0, "transient": k < 3})
    if kind == "indicators":
        return (f"/cm/{ch}/indicators", "indicators", stamp, {
            "channel": ch, "mode": "rms", "interval_s": 1.0, "missing_fraction": 0.0,
            "accel_rms": rnd.choice([rnd.random(), math.nan]), "unavailable": ["kurtosis"]})
    if kind == "event":
        return ("/cm/events", "event", stamp, {"kind": "config", "channel": None, "message": f"event {k}"})
    return ("/cm/diagnostics", "diagnostics", stamp, {"link": {"frames_lost": k}, "queue_depth": 0,
                                                       "queue_drops": 0, "lag_s": 0.0, "observations": k,
                                                       "uptime_s": 1.5})


def runs(seed: int, n_runs: int = 120) -> list[tuple[float, list]]:
    """Runs of messages, each with the seconds the clock moved before it; stamps mostly in
    order, some seconds late (the reorder window holds them)."""
    rnd = random.Random(seed)
    out, stamp, k = [], 5_000_000_000, 0
    for _ in range(n_runs):
        run = []
        for _ in range(rnd.choice([1, 2, 5, 9, 9, 30])):
            stamp += rnd.randrange(1, 200_000_000)
            late = rnd.random() < 0.05
            run.append(message(rnd, k, stamp - (rnd.randrange(1, 3_000_000_000) if late else 0)))
            k += 1
        out.append((rnd.choice([0.0, 0.01, 0.3, 1.2]), run))
    return out


def files(path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(path.iterdir())}


@pytest.mark.parametrize("seed", range(6))
def test_mcap_file_write_many_writes_the_bytes_of_one_write_per_message(tmp_path, seed):
    sinks, clocks = [], []
    for name in ("one", "many"):
        clocks.append(FakeClock())
        sinks.append(McapSink(tmp_path / name, compression="none", flush_s=1.0, clock=clocks[-1],
                              chunk_size=rnd_chunk(seed), wall_clock=lambda: WALL))
    for dt, run in runs(seed):
        for c in clocks:
            c.t += dt
        for m in run:
            sinks[0].write(*m)
        k = 0
        while k < len(run):                     # up to each chunk written, as the rotating sink calls it
            k = sinks[1].write_many(run, k)
    assert sinks[0].messages_written == sinks[1].messages_written
    assert sinks[0].persisted == sinks[1].persisted and sinks[1].persisted > 0     # chunks were written
    for s in sinks:
        s.close()
    assert files(tmp_path / "one") == files(tmp_path / "many")


def rnd_chunk(seed: int) -> int:
    return [600, 2000, 1 << 20][seed % 3]      # full chunks inside runs, or only flushes


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("files_by", ["size", "time"])
def test_rotating_write_many_writes_the_files_of_one_write_per_message(tmp_path, seed, files_by):
    """Rotations by size (flushed chunks) and by time (rotate_s shorter than flush_s)."""
    by = {"size": {"rotate_mb": 0.004, "rotate_s": 7.0, "flush_s": 1.0, "fsync_s": 2.0},
          "time": {"rotate_s": 2.0, "flush_s": 30.0, "fsync_s": 60.0}}[files_by]
    out = dataclasses.replace(OutputConfig(), **by, compression="none", retain_mb=0.0, min_free_mb=0.0)
    sinks, clocks = [], []
    for name in ("one", "many"):
        clocks.append(FakeClock())
        sinks.append(RotatingSink(dataclasses.replace(out, dir=str(tmp_path / name)), clock=clocks[-1],
                                  wall_clock=lambda: WALL, salvage=False))
    for dt, run in runs(seed):
        for c in clocks:
            c.t += dt
        for m in run:
            sinks[0].write(*m)
        sinks[1].write_many(run)
        assert sinks[0]._event_dirty == sinks[1]._event_dirty     # the next tick fsyncs alike
        for s in sinks:
            s.tick()
    assert sinks[0].messages_written == sinks[1].messages_written == sum(len(r) for _, r in runs(seed))
    for s in sinks:
        s.close()
    assert len(sinks[0].paths) >= 3                                # rotated by size and time
    assert files(tmp_path / "one") == files(tmp_path / "many")


def test_a_message_that_cannot_be_encoded_fails_the_run_where_write_would(tmp_path):
    clocks = [FakeClock(), FakeClock()]
    out = dataclasses.replace(OutputConfig(), compression="none", retain_mb=0.0, min_free_mb=0.0)
    sinks = [RotatingSink(dataclasses.replace(out, dir=str(tmp_path / n)), clock=c, wall_clock=lambda: WALL,
                          salvage=False) for n, c in zip(("one", "many"), clocks)]
    rnd = random.Random(1)
    good = [message(rnd, k, 10**9 * (k + 1)) for k in range(6)]
    bad = ("/cm/events", "event", 10**9 * 7, {"kind": "config", "channel": None, "message": object()})
    urgent = ("/cm/events", "event", 10**9 * 4, {"kind": "failure", "channel": "ch0", "message": "failure"})
    run = good[:3] + [urgent, bad] + good[3:]
    with pytest.raises(SinkError, match="cannot be encoded"):
        for m in run:
            sinks[0].write(*m)
    with pytest.raises(SinkError, match="cannot be encoded"):
        sinks[1].write_many(run)
    assert sinks[0].messages_written == sinks[1].messages_written == 5
    assert sinks[0]._event_dirty and sinks[1]._event_dirty
    for s in sinks:
        s.close()
    assert files(tmp_path / "one") == files(tmp_path / "many")


def test_a_long_message_encodes_whole_as_the_json_module_does():
    """The C encoder built once returns a long text in pieces: all of them are written
    (a capture's waveform, 500,000 values)."""
    import json

    msg = {"channel": "ch0", "samples": np.random.default_rng(0).standard_normal(500_000).round(6).tolist()}
    body = encode_message("/cm/ch0/capture", 10**9, msg)
    assert json.loads(body)["samples"] == msg["samples"]
    assert body == json.dumps({"timestamp": {"sec": 1, "nsec": 0}, **msg}, separators=(",", ":")).encode()


def plain(topic: str, stamp: int, msg: dict) -> bytes | str:
    try:
        return encode_message(topic, stamp, msg)
    except SinkError as err:
        return str(err)


def test_a_repeated_field_from_the_cache_encodes_as_the_plain_encoder(monkeypatch):
    monkeypatch.setattr(mcap_encoding, "_repeat_json", {})
    rnd = random.Random(5)
    values = [0.0166, 0.0292, -0.5, 1e-300, 2.0, 3, 0.0, -0.0, math.nan, math.inf, True, None,
              np.float64(0.75), "x", mcap_encoding._MARK]
    cached = 0
    for k in range(3000):
        r = [rnd.choice(values) for _ in range(rnd.randrange(0, 4))]
        msg = {"channel": rnd.choice(["ch0", mcap_encoding._MARK]), "r": r, "level": rnd.choice([0, None])}
        if rnd.random() < 0.1:
            msg = {"timestamp": {"sec": 1, "nsec": 2}, **msg}
        if rnd.random() < 0.05:
            msg["r"] = tuple(r)
        try:
            got: bytes | str = encode_message("/cm/ch0/severity", 10**9 + k, msg, "r")
        except SinkError as err:
            got = str(err)
        assert got == plain("/cm/ch0/severity", 10**9 + k, msg)
        cached += tuple(r) in mcap_encoding._repeat_json
    assert cached > 300                         # the cache served many of them


class OneAtATime:
    """A rotating sink without ``write_many`` (its ``__getattr__`` hands the rest on): the
    Processor writes one message per call to it."""

    def __init__(self, inner: RotatingSink) -> None:
        self.inner = inner

    def write(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> None:
        self.inner.write(topic, schema, stamp_ns, msg)

    def write_group(self, messages: list) -> None:
        self.inner.write_group(messages)

    def __getattr__(self, name: str):
        return getattr(self.inner, name)


def test_the_processor_writes_the_files_a_one_message_sink_gets(tmp_path, monkeypatch):
    """A damaged faulty RMS capture (anomalies, failures, held flags, lost frames) through
    the Processor: into the rotating sink, whose write_many takes a decision's messages in
    one call, and into one taking a message per call; byte for byte the same files."""
    from cmsensord.config.loading import default_config
    from cmsensord.monitor import diagnostics
    from cmsensord.monitor.processor import Processor
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    cap = tmp_path / "cap.bin"
    sc = make_scenario("faulty", n_channels=4, duration_s=120.0, seed=2)
    Board(sc, BoardConfig(n_channels=4)).write_capture(cap, 120.0)
    data = bytearray(cap.read_bytes())
    rnd = random.Random(3)
    for _ in range(20):                                     # line noise: flipped bits
        data[rnd.randrange(len(data))] ^= 1 << rnd.randrange(8)
    cap.write_bytes(bytes(data))
    monkeypatch.setattr(diagnostics, "time", type("T", (), {"monotonic": staticmethod(lambda: 5.0)}))
    out = dataclasses.replace(OutputConfig(), rotate_mb=0.02, flush_s=1.0, compression="none",
                              retain_mb=0.0, min_free_mb=0.0)
    sinks = []
    for name, wrap in (("one", OneAtATime), ("many", lambda s: s)):
        clock = FakeClock()
        sink = RotatingSink(dataclasses.replace(out, dir=str(tmp_path / name)), clock=clock,
                            wall_clock=lambda: WALL, salvage=False)
        sinks.append(sink)
        procs: list = []

        def proc_of(source, wrap=wrap, sink=sink, procs=procs):
            procs.append(Processor(default_config(4), wrap(sink), clock_ns=lambda: 1_790_000_000 * 10**9,
                                   link_counters=source.counters.as_dict))
            return procs[-1]

        replay_ticking(cap, proc_of, sink, clock, 0.4, chunk=1 << 15)
        assert (procs[0].output.write_many is None) == (name == "one")
    assert sinks[0].messages_written == sinks[1].messages_written > 1000
    assert len(sinks[1].paths) >= 3
    assert files(tmp_path / "one") == files(tmp_path / "many")
    kinds = {m["kind"] for p in sinks[1].paths for t, _, m in read_messages(p) if t == "/cm/events"}
    assert {"anomaly_onset", "failure", "frames_lost"} <= kinds


def test_a_message_passing_the_reorder_window_is_what_push_releases():
    """ReorderWindow.passes (write_many's way for a message in order) notes and releases
    what push would, message for message, on stamps late and in order."""
    from cmsensord.sinks.reorder import ReorderWindow

    rnd = random.Random(7)
    a, b = ReorderWindow(), ReorderWindow()
    stamp, passed = 10**9, 0
    for k in range(3000):
        stamp += rnd.randrange(0, 10**8)
        s = stamp - (rnd.randrange(1, 2 * 10**9) if k > 1000 and rnd.random() < 0.03 else 0)
        want = a.push(s, 1, b"%d" % k)
        if b.passes(s):
            got = [(s, s, 1, b"%d" % k)]
            passed += 1
        else:
            got = b.push(s, 1, b"%d" % k)
        assert got == want
        assert (b.newest_ns, b.horizon_ns, b.clamped, len(b)) == (a.newest_ns, a.horizon_ns, a.clamped, len(a))
    assert a.drain() == b.drain()
    assert 900 < passed < 3000                  # in order at first; held once the window learnt


def test_the_publishing_sink_writes_a_run_in_one_call_and_offers_every_message(tmp_path):
    """TeeSink.write_many: the MCAP sink's write_many (the same file as one write each),
    then each message offered to the publisher, in order; its events handed on after."""
    from collections import deque

    from cmsensord.sinks.tee import TeeSink

    class Publisher:
        def __init__(self) -> None:
            self.offered: list = []
            self.events: deque = deque()

        def offer(self, topic: str, stamp_ns: int, msg: dict) -> None:
            self.offered.append((topic, stamp_ns, msg))
            if len(self.offered) == 3:
                self.events.append(("mqtt_link", "connected", 20, {}))

        def close(self) -> None:
            """Nothing to send."""

    out = dataclasses.replace(OutputConfig(), compression="none", retain_mb=0.0, min_free_mb=0.0)
    sinks, publishers, told = [], [], []
    for name in ("one", "many"):
        inner = RotatingSink(dataclasses.replace(out, dir=str(tmp_path / name)), clock=FakeClock(),
                             wall_clock=lambda: WALL, salvage=False)
        publishers.append(Publisher())
        sinks.append(TeeSink(inner, publishers[-1]))
        sinks[-1].on_publisher_event = lambda *ev: told.append(ev)
    rnd = random.Random(2)
    run = [message(rnd, k, 10**9 * (k + 5)) for k in range(9)]
    for m in run:
        sinks[0].write(*m)
    sinks[1].write_many(run)
    assert publishers[0].offered == publishers[1].offered == [(t, s, m) for t, _, s, m in run]
    assert told == [("mqtt_link", "connected", 20, {})] * 2
    for s in sinks:
        s.close()
    assert files(tmp_path / "one") == files(tmp_path / "many")
