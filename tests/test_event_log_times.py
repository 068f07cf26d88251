"""A replay writes every event at its own stamp (MCAP log time = its ``timestamp`` field), which
is where Foxglove plots it: also the first event, and an alarm transition made after the last
decision, which the end of the run writes after the last records (events wait in the event log
until a decision is ``events.HOLD_S`` past them, so they reach the sink up to a decision period
and HOLD_S behind the newest message)."""

from __future__ import annotations

import json

import numpy as np
from mcap.reader import make_reader

from processes import run_module

FS = 25600
N = FS // 10                    # 0.1-s snapshots: one indicator record each, stamped at its end
SNAPSHOTS = 33                  # 3.3 s of board time: decisions at 1, 2 and 3 s
LOUD_FROM = 20                  # its record ends at 2.1 s: after the decision at 3 s - HOLD_S


def test_every_event_of_a_replay_is_logged_at_its_own_stamp(tmp_path):
    x = np.random.default_rng(5).standard_normal((SNAPSHOTS, N, 1))
    x[LOUD_FROM:] *= 10
    np.save(tmp_path / "s.npy", x)
    p = run_module("cmsensord", "import", str(tmp_path / "s.npy"), "--fs", str(FS), "--unit", "m/s2",
                   "--snapshot-interval", "10", "--out", str(tmp_path / "s.bin"))
    assert p.returncode == 0, p.stderr
    (tmp_path / "a.yaml").write_text("alarms:\n  rules:\n    - {name: loud, indicator: accel_rms, alert: 5}\n")
    p = run_module("cmsensord", "replay", str(tmp_path / "s.bin"), "--config", str(tmp_path / "a.yaml"),
                   "--out", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    with open(next((tmp_path / "logs").glob("*.mcap")), "rb") as f:
        rows = [(c.topic, m.log_time, json.loads(m.data)) for _, c, m in make_reader(f).iter_messages()]
    t0 = min(d["timestamp"]["sec"] * 10**9 + d["timestamp"]["nsec"] for _, _, d in rows)
    events = [(d["kind"], round((at - t0) / 1e9, 3), round((d["timestamp"]["sec"] * 10**9 + d["timestamp"]["nsec"]
                                                             - t0) / 1e9, 3))
              for topic, at, d in rows if topic == "/cm/events"]
    kinds = [k for k, _, _ in events]
    assert kinds[0] == "config" and "alarm_alert" in kinds, events
    alert = next(stamp for k, _, stamp in events if k == "alarm_alert")
    assert alert == (LOUD_FROM + 1) * N / FS, events
    assert [(k, stamp) for k, at, stamp in events if at != stamp] == [], events
    late = [(topic, at, d["timestamp"]) for topic, at, d in rows
            if at != d["timestamp"]["sec"] * 10**9 + d["timestamp"]["nsec"]]
    assert late == []
