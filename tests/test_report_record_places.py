"""``cmsensord report`` of a replayed import of snapshots places each indicator record, and the alarm
transitions it raised, at its snapshot's start: where the import's sidecar (``pct_of_record``,
``source_time_s``) and the replay's summary put that snapshot, not at its end (its record's stamp),
which without times is the next snapshot's start and with them a moment after its own."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from processes import run_module
from tests.test_report_recording_time import event_rows

pytest.importorskip("matplotlib", reason="the report extra")

LOUD = (0, 1)                   # the snapshots over the alarm's level: alert at the first, clear at the third


@pytest.mark.parametrize("fs, n, times", [
    (25600, 2560, ()),                                  # 0.1-s snapshots without times: % of the record
    (20480, 2050, ("--snapshot-interval", "600")),      # 10 blocks of 205 (0.10009766 s), 10 min apart: hours
])
def test_records_and_their_alarms_are_at_their_snapshots_start(tmp_path, fs, n, times):
    x = np.random.default_rng(6).standard_normal((6, n, 1))
    x[list(LOUD)] *= 10
    np.save(tmp_path / "s.npy", x)
    p = run_module("cmsensord", "import", str(tmp_path / "s.npy"), "--fs", str(fs), "--unit", "m/s2", *times,
                   "--out", str(tmp_path / "s.bin"))
    assert p.returncode == 0, p.stderr
    snaps = json.loads((tmp_path / "s.bin.json").read_text())["snapshots"]
    pct = [s["pct_of_record"] for s in snaps]
    (tmp_path / "a.yaml").write_text("alarms:\n  rules:\n    - {name: loud, indicator: accel_rms, alert: 5}\n")
    p = run_module("cmsensord", "replay", str(tmp_path / "s.bin"), "--config", str(tmp_path / "a.yaml"),
                   "--out", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    assert f"  alarm loud/ch: in the recording: alert at s.npy[0] ({pct[0]:.1f} % of the record" in p.stderr
    p = run_module("cmsensord", "report", str(tmp_path / "logs"), "--out", str(tmp_path / "r.html"))
    assert p.returncode == 0, p.stderr
    page = (tmp_path / "r.html").read_text(encoding="utf-8")
    # each snapshot's start as the page writes a time: % of the record, or hours into the recording
    place = [f"{v:.3f} %" for v in pct] if not times else [f"{s['source_time_s'] / 3600:.5f} h" for s in snaps]
    x0, x1 = (pct[0], pct[-1]) if not times else (snaps[0]["source_time_s"] / 3600, snaps[-1]["source_time_s"] / 3600)
    alarms = [(kind, t) for kind, t in event_rows(page) if kind.startswith("alarm_")]
    assert alarms == [("alarm_alert", place[LOUD[0]]), ("alarm_clear", place[LOUD[-1] + 1])]
    metas = {m["id"]: m for m in json.loads(re.search(
        r'<script type="application/json" id="figures">(.*?)</script>', page, re.S).group(1))}
    axes = metas["ch-indicators"]["axes"]
    assert axes[-1]["xlabel"] == ("hours into the recording" if times else
                                  "% of the record (snapshots end to end; the import has no times)")
    lo, hi = axes[0]["xlim"]                    # matplotlib's margins: 5 % of the data's span each side
    span = (hi - lo) / 1.1
    assert (lo + 0.05 * span, hi - 0.05 * span) == pytest.approx((x0, x1), abs=1e-5 * (x1 - x0))
