"""An alarm's on-delay counts the time the value is at or above the level, without a break:
one spike over the alert level followed by values just under it (inside the deadband) raises
nothing, however long they last; the same values over the level for the delay raise the alert,
on a record whose value reached the level. Through ``cmsensord import`` and ``replay``."""

from __future__ import annotations

import re

import numpy as np

from processes import run_module

FS = 25600
LEVEL = 2.0


def _snapshots() -> np.ndarray:
    """0.1-s snapshots of white noise at these RMS levels [m/s2]: healthy, one spike over the
    level, ten just under it (in the 5 % deadband), healthy, then six over it."""
    rms = [1.0] * 20 + [2.2] + [1.95] * 10 + [1.0] * 10 + [2.2] * 6 + [1.0] * 5
    rng = np.random.default_rng(1)
    out = []
    for r in rms:
        x = rng.standard_normal(FS // 10)
        out.append(r * x / np.sqrt(np.mean(x * x)))
    return np.array(out)[:, :, None]


def test_a_spike_then_values_in_the_deadband_raise_nothing_a_sustained_exceedance_does(tmp_path):
    np.save(tmp_path / "s.npy", _snapshots())
    cap = tmp_path / "s.bin"
    p = run_module("cmsensord", "import", str(tmp_path / "s.npy"), "--fs", str(FS), "--unit", "m/s2",
                   "--snapshot-interval", "0.1", "--out", str(cap))
    assert p.returncode == 0, p.stderr
    (tmp_path / "a.yaml").write_text("alarms:\n  rules:\n    - {name: rms, indicator: accel_rms, "
                                     f"alert: {LEVEL}, on_delay_s: 0.3}}\n")
    p = run_module("cmsensord", "replay", str(cap), "--config", str(tmp_path / "a.yaml"),
                   "--out", str(tmp_path / "o"))
    assert p.returncode == 0, p.stderr
    raised = [line for line in p.stderr.splitlines() if " alarm_alert: " in line]
    assert len(raised) == 1, p.stderr[-3000:]
    value = float(re.search(r"accel_rms ([0-9.]+) m/s² \(acceleration RMS\) reached the alert level",
                            raised[0]).group(1))
    assert value >= LEVEL, raised[0]
