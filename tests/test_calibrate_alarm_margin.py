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
            "18.31 (5.69 x baseline), in runs of up to 1 of the 4 in a row its on_delay_s 0.3 needs (as independent "
            "values, 2e+03 such runs a year): only the delay kept it quiet, and a healthy day with a longer run "
            "raises it; set the level above the healthy period's highest (alert_x_baseline 5.7 or more); 200 healthy "
            "values cannot show the level 4 in a row needs (reached by under 0.42 % of them, for under 0.1 false "
            "alarms a year): a longer healthy period shows it, or a longer on_delay_s\n") in out
    assert "alarm rms/de" not in out              # its level stays above every healthy record
    out = _calibrate(tmp_path, rough, 5.8)        # the level it gave: quiet
    assert "thin margin" not in out and "alarm crest/de" not in out


@pytest.fixture(scope="module")
def pair(tmp_path_factory) -> Path:
    """Two channels of 200 snapshots as in ``rough``, ``de`` three times as loud as ``fe``: one in
    twenty snapshots with an impact on both, one in forty with one more on ``de`` alone."""
    d = tmp_path_factory.mktemp("pair")
    rng = np.random.default_rng(7)
    x = 0.2 * rng.standard_normal((200, 512, 2))
    x[:, :, 0] *= 3.0
    x[7::20, 100, :] += 6.0
    x[17::40, 300, 0] += 18.0
    np.savez(d / "snaps.npz", acc_g=x.astype(np.float32), fs=5120.0)
    cap = d / "snaps.bin"
    p = cmsensord("import", str(d / "snaps.npz"), "--names", "de,fe", "--block-len", "64", "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return cap


def test_a_voting_alarm_is_judged_on_its_channels_together_each_against_its_own_baseline(pair, tmp_path):
    """A vote-2 alarm's values are judged as it judges them: each channel against the level of its
    own baseline, and the level reached where two channels reach it at once.  ``rms``: ``de``'s
    records reach its level alone, ``fe``'s never with them: no warning (not ``de``'s values
    against ``fe``'s baseline, half the healthy values).  ``crest``: both channels' impacts."""
    base = tmp_path / "base.yaml"
    base.write_text("alarms:\n  rules:\n"
                    "    - {name: rms, indicator: accel_rms, alert_x_baseline: 1.5, on_delay_s: 0.3, vote: 2}\n"
                    "    - {name: crest, indicator: crest_factor, alert_x_baseline: 1.5, on_delay_s: 0.3, vote: 2}\n")
    p = cmsensord("calibrate", str(pair), "--rpm", "1800", "--config", str(base), "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 0, p.stderr
    warned = [ln for ln in p.stdout.splitlines() if ln.startswith("alarm ")]
    assert warned == [
        "alarm crest: warning: thin margin: its alert level (1.5 x each channel's baseline), reached on 2 of its "
        "channels at once, is within the healthy period's scatter (more than 1 % of its times reach it): 10 of 200 "
        "time(s) there (5.0 %), the highest 3.04 x baseline, in runs of up to 1 of the 4 in a row its on_delay_s 0.3 "
        "needs (as independent values, 2e+03 such runs a year): only the delay kept it quiet, and a healthy day "
        "with a longer run raises it; set the level above the healthy period's highest (alert_x_baseline 3.1 or "
        "more); 200 healthy times cannot show the level 4 in a row needs (reached by under 0.42 % of them, for "
        "under 0.1 false alarms a year): a longer healthy period shows it, or a longer on_delay_s"], p.stdout
