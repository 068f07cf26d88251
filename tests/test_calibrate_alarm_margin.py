"""`cmsensord calibrate` says an alarm whose level the healthy period reaches again and again,
each time for less than its on-delay: its level is inside the machine's healthy scatter, and
only the delay kept it quiet there."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from processes import cmsensord


@pytest.fixture(scope="module")
def rough(tmp_path_factory) -> Path:
    """200 snapshots of 0.1 s (512 samples at 5120 Hz) of noise, one in twenty with an impact
    alone: the crest factor of 5 % of the records is several times the others'."""
    d = tmp_path_factory.mktemp("rough")
    rng = np.random.default_rng(7)
    x = 0.2 * rng.standard_normal((200, 512, 1))
    x[7::20, 100, 0] += 6.0
    np.savez(d / "snaps.npz", acc_g=x.astype(np.float32), fs=5120.0)
    cap = d / "snaps.bin"
    p = cmsensord("import", str(d / "snaps.npz"), "--names", "de", "--block-len", "64", "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return cap


def _calibrate(tmp_path: Path, capture: Path, crest_x: float) -> str:
    base = tmp_path / "base.yaml"
    base.write_text("alarms:\n  rules:\n"
                    f"    - {{name: crest, indicator: crest_factor, alert_x_baseline: {crest_x}, on_delay_s: 0.3}}\n"
                    "    - {name: rms, indicator: accel_rms, alert_x_baseline: 3, on_delay_s: 0.3}\n")
    p = cmsensord("calibrate", str(capture), "--rpm", "1800", "--config", str(base), "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 0, p.stderr
    return p.stdout


def test_a_level_inside_the_healthy_scatter_held_back_by_the_delay_alone_is_said(rough, tmp_path):
    out = _calibrate(tmp_path, rough, 1.5)
    assert "alarms: none of the 2 rule(s) shown within the healthy period (replayed with the site file)\n" in out
    assert ("alarm crest/de: warning: thin margin: its alert level 4.825 (1.5 x baseline) is within the healthy "
            "period's scatter (more than 1 % of its values reach it): 10 of 200 value(s) there (5.0 %), the highest "
            "18.31 (5.69 x baseline), in runs of up to 1 of the 3 in a row its on_delay_s 0.3 needs: only the delay "
            "kept it quiet, and a healthy day with a longer run raises it; set the level above 99 % of the healthy "
            "values (alert_x_baseline 5.7 or more), or a longer on_delay_s\n") in out
    assert "alarm rms/de" not in out              # its level stays above every healthy record
    out = _calibrate(tmp_path, rough, 5.8)        # the level it gave: quiet
    assert "thin margin" not in out and "alarm crest/de" not in out
