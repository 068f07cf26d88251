"""A replay of an import of snapshots says how much of the recording its alarm delays span:
they count the capture's seconds, and the snapshots lie end to end there (0.1-s snapshots every
10 s: one second of the capture is 100 s of the recording, so a 3-s delay spans 300 s)."""

from __future__ import annotations

import numpy as np

from processes import run_module

FS = 25600


def _import(tmp_path, interval: str) -> str:
    rng = np.random.default_rng(0)
    np.save(tmp_path / "s.npy", rng.standard_normal((200, FS // 10, 1)))
    cap = tmp_path / f"s{interval}.bin"
    p = run_module("cmsensord", "import", str(tmp_path / "s.npy"), "--fs", str(FS), "--unit", "m/s2",
                   "--snapshot-interval", interval, "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return str(cap)


def _replay(tmp_path, cap: str, delay: float) -> str:
    cfg = tmp_path / f"a{delay}.yaml"
    cfg.write_text("alarms:\n  rules:\n    - {name: rms, indicator: accel_rms, alert: 100, "
                   f"on_delay_s: {delay}}}\n")
    p = run_module("cmsensord", "replay", cap, "--config", str(cfg), "--out", str(tmp_path / f"o{delay}"))
    assert p.returncode == 0, p.stderr
    return p.stderr


def test_the_delays_of_a_replay_of_snapshots_are_told_in_the_recordings_seconds(tmp_path):
    err = _replay(tmp_path, _import(tmp_path, "10"), 3)
    assert ("  alarm delays count the capture's seconds, one of which is 100 s of the recording here (its "
            "snapshots end to end): a delay of 3 s spans 300 s of it\n") in err, err


def test_no_line_without_delays_or_for_a_continuous_recording(tmp_path):
    cap = _import(tmp_path, "10")
    assert "alarm delays" not in _replay(tmp_path, cap, 0)
    assert "alarm delays" not in _replay(tmp_path, _import(tmp_path, "0.1"), 3)
