"""Bearing lines the envelope spectrum's bins cannot resolve are unavailable, not numbers.

FEMTO's set-up in small: snapshots of 0.1 s (10-Hz bins) at 25.6 kHz, 1800 rpm, a bearing of
13 balls of 3.5 mm on 25.6 mm (FTF 12.95, BPFO 168.3, BPFI 221.7, BSF 107.7 Hz).  Guards
against each line read as the largest bin within ±max(2 %, 1 bin): FTF's ±10 Hz is ±77 %, FTF
and 2 x FTF read the same bin, 2 x BSF and BPFI the 220-Hz one, and a rule on BPFO fires on noise.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from cmsensord.dsp.indicators.bearings import Geometry, defect_frequencies
from test_event_kinds import _validate
from test_import_records import _records, _run

FS = 25600
N = 2560                    # 0.1 s a snapshot
BASE = ("bearings:\n  - {name: tb, channel: ch, elements: 13, ball_diameter: 3.5, pitch_diameter: 25.6}\n"
        "alarms:\n  rules:\n"
        "    - {name: bpfi, indicator: tb.bpfi, alert: 1.0e-9}\n"         # any number would raise it
        "    - {name: bpfo, indicator: tb.bpfo, alert: 1.0e-9}\n")
FEMTO = Geometry(13, 3.5, 25.6)
UNRESOLVED = ["tb.ftf", "tb.ftf_2x", "tb.bpfi", "tb.bsf_2x"]


def _capture(tmp_path, snapshots: int = 30):
    """Snapshots of a noisy carrier modulated at BPFO, in an NPZ that gives 1800 rpm, imported."""
    rng = np.random.default_rng(3)
    t = np.arange(N) / FS
    bpfo = defect_frequencies(FEMTO, 30.0).bpfo
    x = [(1 + 0.3 * np.cos(2 * np.pi * bpfo * t)) * np.sin(2 * np.pi * 4000 * t) + rng.normal(0, 0.5, N)
         for _ in range(snapshots)]
    np.savez(tmp_path / "f.npz", acc=np.stack(x)[:, :, None], fs=float(FS), rpm=1800.0)
    _run("import", tmp_path / "f.npz", "--unit", "m/s2", "--names", "ch", "--out", tmp_path / "f.bin")
    (tmp_path / "base.yaml").write_text(BASE)
    return tmp_path / "f.bin"


def _said(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if "bearing tb on ch: line(s)" in ln]


def test_replay_lists_unresolved_lines_unavailable_says_so_once_and_rules_on_them_do_not_fire(tmp_path):
    cap = _capture(tmp_path)
    err = _run("replay", cap, "--config", tmp_path / "base.yaml", "--out", tmp_path / "out")
    recs = _records(tmp_path / "out")
    assert len(recs) == 30 and all(m["interval_s"] == 0.1 for m in recs)
    for m in recs:
        # not every line a number: ftf and ftf_2x (bsf_2x and bpfi) would often read the same bin
        assert m["unavailable"] == UNRESOLVED
        assert set(m["bearings"][0]["lines"]) == {"bpfo", "bpfo_2x", "bpfi_2x", "bsf"}
    said = _said(err)
    assert len(said) == 1, err
    line = said[0]
    assert line.startswith("WARNING lines_unresolved: bearing tb on ch: line(s) ftf 12.95 Hz, ftf_2x 25.9 Hz, "
                           "bpfi 221.7 Hz, bsf_2x 215.3 Hz not resolved by the envelope spectrum's 10-Hz bins "
                           "(records of 0.1 s)"), line
    assert "rule(s) bpfi on them do not fire" in line
    assert "records of at least 0.78 s resolve ftf, ftf_2x (indicators.interval_s" in line
    assert "bpfi, bsf_2x lie within the slip (±2 %) of another line of tb: no record length resolves them" in line
    problems, kinds = _validate(next((tmp_path / "out").glob("*.mcap")))    # against the schemas in the log
    assert problems == [] and kinds["lines_unresolved"] == 1
    # the resolved line's rule fires; the unresolved one's never (not alarm_alert bpfi/ch at once)
    assert "bpfo/ch: tb.bpfo" in err and "bpfi/ch:" not in err, err


def test_calibrate_says_so_once_and_learns_no_baseline_of_them(tmp_path):
    cap = _capture(tmp_path)
    site = tmp_path / "site.yaml"
    out = _run("calibrate", cap, "--config", tmp_path / "base.yaml", "--out", site)
    said = _said(out)
    assert len(said) == 1 and said[0].startswith("note: bearing tb on ch: line(s) ftf 12.95 Hz"), out
    learned = {b["indicator"] for b in yaml.safe_load(site.read_text())["alarms"]["baselines"]}
    # not a baseline of every line (FTF's of whichever bin within ±77 % wins)
    assert {"tb.bpfo", "tb.bsf"} <= learned and not learned & set(UNRESOLVED)


def test_longer_records_resolve_the_lines_the_bins_were_too_coarse_for():
    from cmsensord.dsp.indicators.resolution import line_freqs, record_s_to_resolve, unresolved

    lines = line_freqs(defect_frequencies(FEMTO, 30.0))
    assert unresolved(lines, 0.02, 10.0) == ("ftf", "ftf_2x", "bpfi", "bsf_2x")
    # the 0.78 s the message names: only the two within the slip of each other are left
    assert record_s_to_resolve("ftf", lines, 0.02) == pytest.approx(1 / (0.10 * 12.95), rel=1e-3)
    assert unresolved(lines, 0.02, 1 / 0.78) == ("bpfi", "bsf_2x")
    assert record_s_to_resolve("bpfi", lines, 0.02) is None
    # 2-Hz bins: FTF stands 6.5 bins up, its window still ±15 %
    assert unresolved(lines, 0.02, 2.0) == ("ftf", "bpfi", "bsf_2x")
