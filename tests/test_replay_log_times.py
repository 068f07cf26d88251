"""A replay writes each message at its own stamp (log time = publish time), as a live run
does: with the AKF trace, and with captures and the events they hold back."""

from __future__ import annotations

import json
from datetime import datetime
from pathlib import Path

import pytest
from mcap.reader import make_reader

from processes import cmsensord, run_module

S = 1_000_000_000
#: the failures of the degrading scenario's two channels, and their clears (s into the run)
FAILURES = [("failure", "ch0", 202.0), ("failure", "ch1", 210.0),
            ("failure_clear", "ch1", 270.0), ("failure_clear", "ch0", 277.0)]


@pytest.fixture(scope="module")
def degrading(tmp_path_factory) -> Path:
    """300 s of a degrading machine, 2 channels in RMS mode, as firmware_sim writes it."""
    cap = tmp_path_factory.mktemp("log_times") / "rms2.bin"
    p = run_module("firmware_sim", "--scenario", "degrading", "--duration", "300", "--channels", "2",
                   "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return cap


def _replay(cap: Path, out: Path, *args: str) -> Path:
    p = cmsensord("replay", str(cap), "--out", str(out), *args)
    assert p.returncode == 0, p.stderr
    return next(out.glob("*.mcap"))


def _times(log: Path) -> tuple[int, list[tuple[str, float, float, dict]]]:
    """(first stamp, [(topic, stamp s, log time s after it, message)]) in file order."""
    with open(log, "rb") as f:
        msgs = [(c.topic, m.publish_time, m.log_time, json.loads(m.data))
                for _, c, m in make_reader(f).iter_messages(log_time_order=False)]
    t0 = min(pub for _, pub, _, _ in msgs)
    return t0, [(topic, (pub - t0) / S, (log - t0) / S, d) for topic, pub, log, d in msgs]


def _failures(rows) -> list[tuple[str, str, float]]:
    return [(d["kind"], d["channel"], t) for topic, t, _, d in rows
            if topic == "/cm/events" and d["kind"] in ("failure", "failure_clear")]


def _iso(ns: int) -> str:
    return datetime.fromtimestamp(ns / S).astimezone().isoformat(timespec="milliseconds")


def test_a_replay_with_the_akf_trace_writes_the_decisions_at_their_own_time(degrading, tmp_path):
    """The decisions come in their place among the trace: only the first event (before the sink
    learnt the events' lag of a second) has a clamped log time.  Guards against the trace of a
    read's 40 s going out before that read's decisions: 450 of 600 severity messages and the
    failures written up to 40 s after their stamp, and the summary saying both channels failed at
    +212.21 s."""
    log = _replay(degrading, tmp_path / "akf", "--akf-trace")
    t0, rows = _times(log)
    assert _failures(rows) == FAILURES
    clamped = [(topic, t, round(at, 2), d.get("kind")) for topic, t, at, d in rows if at != t]
    assert clamped == [("/cm/events", 0.0, 0.99, "config"), ("/cm/log", 0.0, 0.99, None)]
    assert sum(topic == "/cm/ch0/akf" for topic, *_ in rows) == 30000
    text = cmsensord("summary", str(log)).stdout
    for kind, channel, t in FAILURES:
        assert f"\n  {_iso(t0 + int(t * S))} {kind} {channel}: " in text


@pytest.mark.parametrize("post_s", [2, 10])
def test_a_replay_with_captures_writes_them_and_the_events_they_hold_at_their_own_time(degrading, tmp_path, post_s):
    """Captures (every 30 s and on severity changes and failures): the captures, and the events
    the event log holds back while a capture waits for its post_s, are written at their stamps
    (guards against 104 of 114 events up to 136 s late, every failure written at +290 s).  Their lag
    (post_s and 2 s, more than 10 s with the default post_s) is held in the replay's window."""
    cfg = tmp_path / "cap.yaml"
    cfg.write_text(f"capture:\n  triggers: [severity_change, failure]\n  every_s: 30\n  pre_s: 2\n"
                   f"  post_s: {post_s}\n  min_interval_s: 5\n")
    log = _replay(degrading, tmp_path / "cap", "--config", str(cfg))
    _, rows = _times(log)
    assert _failures(rows) == FAILURES
    assert [(topic, t, at) for topic, t, at, _ in rows if at != t] == []
    captured = [t for topic, t, _, d in rows if topic == "/cm/events" and d["kind"] == "capture"]
    assert captured[:4] == [30.0, 30.0, 60.0, 60.0] and len(captured) >= 16
