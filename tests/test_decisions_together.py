"""A replay's decisions of one release go to the sink together (`Processor._release_decisions`:
up to events, which go to the log first, or a release that writes some): the same files, byte
for byte, as one run of messages per decision, on a damaged faulty capture with anomalies,
failures, held flags and lost frames, through the AKF bank's flags-only kernel and the
sink's templates; with alarms watching the messages each decision still goes out alone."""

from __future__ import annotations

import dataclasses
import random

import pytest

from cmsensord.config import OutputConfig
from cmsensord.monitor.events import EventLog
from cmsensord.sinks.mcap_sink import read_messages
from cmsensord.sinks.rotating import RotatingSink
from fakes import FakeClock, replay_ticking

WALL = 1_790_000_000.0


def damaged(path, seconds: float, seed: int) -> None:
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    Board(make_scenario("faulty", n_channels=4, duration_s=seconds, seed=2), BoardConfig(n_channels=4)) \
        .write_capture(path, seconds)
    data = bytearray(path.read_bytes())
    rnd = random.Random(seed)
    for _ in range(25):                                     # line noise: flipped bits
        data[rnd.randrange(len(data))] ^= 1 << rnd.randrange(8)
    path.write_bytes(bytes(data))


def replay(cap, out_dir, cfg) -> tuple[RotatingSink, list[int]]:
    """The capture through the Processor into a rotating sink; the sizes of its write_many runs."""
    from cmsensord.monitor.processor import Processor

    out = dataclasses.replace(OutputConfig(), dir=str(out_dir), rotate_mb=0.05, flush_s=1.0,
                              compression="none", retain_mb=0.0, min_free_mb=0.0)
    clock = FakeClock()
    sink = RotatingSink(out, clock=clock, wall_clock=lambda: WALL, salvage=False)
    sizes: list[int] = []
    write_many = sink.write_many
    sink.write_many = lambda messages: (sizes.append(len(messages)), write_many(messages))[1]  # type: ignore[method-assign]
    replay_ticking(cap, lambda source: Processor(cfg, sink, clock_ns=lambda: 1_790_000_000 * 10**9,
                                                 link_counters=source.counters.as_dict), sink, clock, 0.3)
    return sink, sizes


def files(path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(path.iterdir())}


@pytest.mark.parametrize("alarms", [False, True])
def test_decisions_written_together_give_the_files_of_one_run_per_decision(tmp_path, monkeypatch, alarms):
    from cmsensord.config.loading import default_config
    from cmsensord.monitor import diagnostics

    monkeypatch.setattr(diagnostics, "time", type("T", (), {"monotonic": staticmethod(lambda: 5.0)}))
    cap = tmp_path / "cap.bin"
    damaged(cap, 240.0, seed=5)
    cfg = default_config(4)
    if alarms:      # the alarm manager reads the indicator records: each decision goes out alone
        from cmsensord.config.alarms import AlarmRuleConfig

        rule = AlarmRuleConfig(name="rms", indicator="accel_rms", alert=0.7, danger=2.0)
        cfg = dataclasses.replace(cfg, alarms=dataclasses.replace(cfg.alarms, rules=(rule,)))
    together, sizes = replay(cap, tmp_path / "together", cfg)
    with monkeypatch.context() as m:        # the plain path: every decision's messages alone
        m.setattr(EventLog, "due", lambda self, processed_ns: True)
        alone, alone_sizes = replay(cap, tmp_path / "alone", cfg)
    assert together.messages_written == alone.messages_written > 2000
    assert len(together.paths) >= 3                         # rotated within runs
    assert files(tmp_path / "together") == files(tmp_path / "alone")
    kinds = {m["kind"] for p in together.paths for t, _, m in read_messages(p) if t == "/cm/events"}
    assert {"anomaly_onset", "failure", "frames_lost"} <= kinds
    assert bool({"alarm_alert", "alarm_danger"} & kinds) == alarms
    if alarms:
        assert sizes == alone_sizes
    else:
        assert max(sizes) >= 5 * 9 and len(sizes) < len(alone_sizes) / 3    # many decisions per run
