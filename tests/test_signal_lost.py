"""A channel whose level falls below ``monitor.signal_floor`` of its healthy baseline has no
signal (a dead sensor, a cut cable, or the machine stopped): one ``signal_lost`` event, its
severity and its alarms hold (before: the failure cleared and the alarms with it, a dead sensor
read as a healed machine); ``signal_back`` when the level returns.  Through `cmsensord import`,
`calibrate` and `replay`, as a commissioning engineer runs them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from cmsensord.sinks.mcap_sink import read_messages
from processes import cmsensord

FS, BLOCK = 5120, 64
RULES = ("alarms:\n  rules:\n    - {name: rms_trend, indicator: accel_rms, alert_x_baseline: 2, "
         "danger_x_baseline: 4}\n")


def _run(*args: str) -> str:
    p = cmsensord(*args)
    assert p.returncode == 0, p.stderr
    return p.stdout + p.stderr


def _capture(tmp_path: Path) -> Path:
    """20 s healthy, 6 s at 6x (a failure), 6 s at 1 % (a dead sensor), 6 s at 6x again."""
    rng = np.random.default_rng(3)
    amp = np.concatenate([np.full(20, 1.0), np.full(6, 6.0), np.full(6, 0.01), np.full(6, 6.0)])
    x = 0.5 * rng.standard_normal((amp.size, FS)) * amp[:, None]
    np.save(tmp_path / "m.npy", x.reshape(-1).astype(np.float32))
    _run("import", str(tmp_path / "m.npy"), "--fs", str(FS), "--block-len", str(BLOCK), "--unit", "m/s2",
         "--names", "de", "--out", str(tmp_path / "m.bin"))
    return tmp_path / "m.bin"


def test_a_dead_sensor_holds_the_severity_and_the_alarms(tmp_path):
    cap = _capture(tmp_path)
    (tmp_path / "base.yaml").write_text(RULES)
    _run("calibrate", str(cap), "--to", "20", "--rpm", "1500", "--config", str(tmp_path / "base.yaml"),
         "--out", str(tmp_path / "site.yaml"))
    assert yaml.safe_load((tmp_path / "site.yaml").read_text())["alarms"]["baselines"][0]["indicator"]
    out = _run("replay", str(cap), "--config", str(tmp_path / "site.yaml"), "--out", str(tmp_path / "logs"))
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    events = [m for t, _, m in msgs if t == "/cm/events"]
    kinds = [e["kind"] for e in events if e["kind"] in
             ("failure", "failure_clear", "signal_lost", "signal_back", "alarm_danger", "alarm_clear")]
    assert kinds == ["alarm_danger", "failure", "signal_lost", "signal_back"], (kinds, out)
    lost = next(e for e in events if e["kind"] == "signal_lost")
    head, _, tail = lost["message"].partition(" % of the healthy baseline")
    assert head.startswith("de: no signal: level ") and float(head.rsplit(" ", 1)[1]) < 5, lost
    assert tail == (" (below 5 %, monitor.signal_floor): a sensor, cable or ADC fault, or the machine "
                    "stopped; severity 1.00 and the channel's alarms held until it is back"), lost
    sev = [m for t, _, m in msgs if t == "/cm/de/severity"]
    dead = [m for m in sev if m.get("signal_lost")]
    assert 4 <= len(dead) <= 6 and all(m["severity_index"] == 1.0 for m in dead), dead
    assert all(m["level_ratio"] < 0.05 for m in dead)
    alarms = [m for t, _, m in msgs if t == "/cm/alarms"]
    assert alarms[-1]["alarms"][0]["level"] == "danger", alarms[-1]
    assert "WARNING signal_lost: de: no signal" in out
