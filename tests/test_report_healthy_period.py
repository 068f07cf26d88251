"""The healthy period the baselines were learned from, from calibrate to the report: ``calibrate
--to 50%`` writes it into the site file's ``commissioned`` section (board seconds, beside the
capture's real path), a replay of that capture (however its path is spelled) writes it into its
log's metadata, and ``cmsensord report`` shades it on the recording's time figures, over the
recording's own time; a replay of another capture with the same site file has none. A period
that is none is refused in one line."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from cmsensord.report.fast_read import head_metadata
from processes import cmsensord

pytest.importorskip("matplotlib", reason="the report extra")

#: six 2-s snapshots at 2560 Hz, 10 minutes apart, one channel: 12 board seconds, 50 % of them the
#: first three snapshots, which end 1202 s (0.334 h) into the recording
IMPORT = ("--fs", "2560", "--block-len", "32", "--unit", "g", "--names", "bearing")
HEALTHY_H = [0.0, 1202 / 3600]
LEGEND = "healthy period (baselines)"


def _import(work: Path, name: str, seed: int) -> None:
    acc = 0.05 * np.random.default_rng(seed).standard_normal((6, 2 * 2560, 1))
    np.savez(work / f"{name}.npz", acc=acc, fs_hz=np.array(2560.0), t_s=np.arange(6) * 600.0)
    p = cmsensord("import", f"{name}.npz", *IMPORT, "--out", f"{name}.bin", cwd=work)
    assert p.returncode == 0, p.stderr


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """r.bin calibrated on its first half (site.yaml); o.bin another recording like it."""
    d = tmp_path_factory.mktemp("healthy_period")
    _import(d, "r", 1)
    _import(d, "o", 2)
    p = cmsensord("calibrate", "r.bin", "--to", "50%", "--out", "site.yaml", cwd=d)
    assert p.returncode == 0, p.stderr
    return d


def _replay(work: Path, capture: str, site: str, out: str) -> Path:
    """``cmsensord replay CAPTURE --config SITE --out OUT`` in ``work``: the log it wrote."""
    before = set((work / out).glob("*.mcap"))
    p = cmsensord("replay", capture, "--config", site, "--out", out, cwd=work)
    assert p.returncode == 0, p.stderr
    (log,) = set((work / out).glob("*.mcap")) - before
    return log


def _figures(work: Path, logs: str) -> dict[str, dict]:
    """The figures' metadata by id of ``cmsensord report LOGS``."""
    p = cmsensord("report", logs, "--out", f"{logs}.html", cwd=work)
    assert p.returncode == 0, p.stderr
    page = (work / f"{logs}.html").read_text(encoding="utf-8")
    metas = json.loads(re.search(r'<script type="application/json" id="figures">(.*?)</script>', page, re.S)[1])
    return {m["id"]: m for m in metas}


def test_calibrate_writes_the_healthy_period_beside_the_captures_real_path(work):
    assert yaml.safe_load((work / "site.yaml").read_text())["commissioned"] == {
        "capture": os.path.realpath(work / "r.bin"), "fs_hz": 2560, "block_len": 32, "from_s": 0.0, "to_s": 6.0}


def test_the_report_shades_the_healthy_period_of_its_capture_and_no_other(work):
    """r.bin replayed by another spelling of its path, and o.bin, with r.bin's site file into one
    directory: r.bin's severity and indicator figures shade the first three snapshots (0 to 0.334 h
    into the recording), on every axes with its legend entry; o.bin's shade nothing."""
    mine = _replay(work, f"{work}/./r.bin", "site.yaml", "logs")
    assert json.loads(head_metadata(mine)["cmsensord"]["healthy_period"]) == {"from_s": 0.0, "to_s": 6.0}
    other = _replay(work, "o.bin", "site.yaml", "logs")
    assert "healthy_period" not in head_metadata(other)["cmsensord"]
    metas = _figures(work, "logs")
    assert set(metas) == {f"{rec}-bearing-{kind}" for rec in ("r.bin", "o.bin") for kind in ("severity", "indicators")}
    for kind in ("severity", "indicators"):
        shaded = metas[f"r.bin-bearing-{kind}"]
        assert shaded["healthy_period"] == pytest.approx(HEALTHY_H, abs=1e-6), kind
        assert shaded["healthy_period_shown"] == ["0.000 h", "0.334 h"]
        assert shaded["axes"][-1]["xlabel"] == "hours into the recording"
        assert all(ax["legend"][0] == LEGEND for ax in shaded["axes"]), kind
        plain = metas[f"o.bin-bearing-{kind}"]
        assert "healthy_period" not in plain and not any(LEGEND in ax["legend"] for ax in plain["axes"]), kind


def test_the_summary_says_the_healthy_period_in_one_line(work):
    """`cmsensord summary` of r.bin's replay: the healthy period as a line of board seconds and of
    the recording (where the report shades it), not left in the metadata as JSON."""
    log = _replay(work, "r.bin", "site.yaml", "summary_logs")
    p = cmsensord("summary", str(log), cwd=work)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    assert lines[-1] == ("  healthy period (baselines): 0.0-6.0 board s of the capture, 0.000 h to 0.334 h in the "
                         "recording (the site file's commissioned section)"), lines
    assert lines[-2].startswith("  cmsensord: {'source': ") and "'healthy_period'" not in lines[-2], lines


@pytest.mark.parametrize("period, message", [
    ("from_s: 6.0\n  to_s: 2.0", "commissioned.to_s: must be greater than from_s = 6.0 (got 2.0)"),
    ("to_s: 6.0", "commissioned.to_s: the healthy period needs from_s too (its two ends, as calibrate writes "
                  "them) (got 6.0)"),
    ("from_s: -1\n  to_s: 6.0", "commissioned.from_s: must be >= 0 (got -1)"),
    ("from_s: 0\n  to_s: .inf", "commissioned.to_s: expected a finite number (got inf)"),
], ids=["reversed", "one-end", "negative", "infinite"])
def test_a_healthy_period_that_is_none_is_refused_in_one_line(work, tmp_path, period, message):
    site = tmp_path / "bad.yaml"
    site.write_text(f"commissioned:\n  capture: r.bin\n  {period}\n")
    p = cmsensord("replay", "r.bin", "--config", str(site), "--out", str(tmp_path / "logs"), cwd=work)
    assert (p.returncode, p.stderr.strip()) == (78, f"cmsensord: configuration error: {site}: {message}")
