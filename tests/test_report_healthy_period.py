"""The healthy period the baselines were learned from, from calibrate to the report: ``calibrate
--to 50%`` writes it into the site file's ``commissioned`` section (board seconds, beside the
capture's real path), a replay of that capture (however its path is spelled) writes it into its
log's metadata, and ``cmsensord report`` shades it on the recording's time figures, over the
recording's own time; a replay of another capture with the same site file has none. The capture
moved since is known by its size and the digest of its ends; a replay that cannot know it says
why. A period that is none is refused in one line."""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
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


def _ends_sha256(path: Path) -> str:
    """SHA-256 of the first and last 64 KiB of ``path`` (the whole, when shorter than 64 KiB)."""
    data = path.read_bytes()
    return hashlib.sha256(data[:1 << 16] + data[max(1 << 16, len(data) - (1 << 16)):]).hexdigest()


def test_calibrate_writes_the_healthy_period_beside_the_captures_real_path(work):
    r = work / "r.bin"
    assert yaml.safe_load((work / "site.yaml").read_text())["commissioned"] == {
        "capture": os.path.realpath(r), "capture_bytes": r.stat().st_size, "capture_ends_sha256": _ends_sha256(r),
        "fs_hz": 2560, "block_len": 32, "from_s": 0.0, "to_s": 6.0}


def _moved(work: Path, tmp_path: Path) -> Path:
    """r.bin calibrated as a.bin in ``tmp_path`` (site.yaml there), then moved to moved/b.bin
    with its sidecar: the site file's ``commissioned.capture`` no longer exists."""
    for suffix in ("", ".json"):
        shutil.copy(work / f"r.bin{suffix}", tmp_path / f"a.bin{suffix}")
    p = cmsensord("calibrate", "a.bin", "--to", "50%", "--out", "site.yaml", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    (tmp_path / "moved").mkdir()
    for suffix in ("", ".json"):
        (tmp_path / f"a.bin{suffix}").rename(tmp_path / "moved" / f"b.bin{suffix}")
    return tmp_path / "site.yaml"


def test_a_capture_moved_since_calibrate_still_gets_its_healthy_period(work, tmp_path):
    """The commissioned capture moved and renamed: its replay is known by its size and ends and
    writes the healthy period, saying nothing of it; a replay of another capture with that site
    file says in one line why none is shaded (guards against a silent replay without it)."""
    site = _moved(work, tmp_path)
    mine = _replay(tmp_path, "moved/b.bin", str(site), "logs")
    assert json.loads(head_metadata(mine)["cmsensord"]["healthy_period"]) == {"from_s": 0.0, "to_s": 6.0}
    p = cmsensord("replay", str(work / "o.bin"), "--config", str(site), "--out", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    assert [ln for ln in p.stderr.splitlines() if "healthy period" in ln] == [
        f"  note: the healthy period is not shaded: its commissioned capture {tmp_path.resolve() / 'a.bin'} is not "
        "found, and o.bin is not it (other first or last bytes)"], p.stderr


def test_a_capture_appended_to_since_calibrate_is_still_it_and_another_at_its_path_is_not(work, tmp_path):
    """A capture a daemon's --capture went on appending to after calibrate read it, then moved, is
    the commissioned one (its first bytes are: it was 'another size' and lost its healthy period);
    another capture written to the commissioned path is not (it took the healthy period of the
    capture calibrate read, shading the wrong stretch of another recording)."""
    site = _moved(work, tmp_path)
    with open(tmp_path / "moved" / "b.bin", "ab") as f:
        f.write((work / "o.bin").read_bytes()[:100_000])
    mine = _replay(tmp_path, "moved/b.bin", str(site), "logs")
    assert json.loads(head_metadata(mine)["cmsensord"]["healthy_period"]) == {"from_s": 0.0, "to_s": 6.0}
    for suffix in ("", ".json"):
        shutil.copy(work / f"o.bin{suffix}", tmp_path / f"a.bin{suffix}")
    before = set((tmp_path / "again").glob("*.mcap"))
    p = cmsensord("replay", "a.bin", "--config", str(site), "--out", "again", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    (log,) = set((tmp_path / "again").glob("*.mcap")) - before
    assert "healthy_period" not in head_metadata(log)["cmsensord"]
    assert [ln for ln in p.stderr.splitlines() if "healthy period" in ln] == [
        "  note: the healthy period is not shaded: a.bin, at the commissioned path, is not the capture calibrate "
        "read (other first or last bytes): a capture written again to that name? calibrate again on it"], p.stderr


def test_a_site_file_without_the_captures_digest_says_why_its_moved_capture_is_not_shaded(work, tmp_path):
    """A site file written before calibrate kept the capture's size and digest still loads; its
    commissioned capture moved, the replay says in one line that it cannot know it."""
    site = _moved(work, tmp_path)
    site.write_text("".join(ln for ln in site.read_text().splitlines(keepends=True)
                            if not ln.startswith(("  capture_bytes:", "  capture_ends_sha256:"))))
    p = cmsensord("replay", "moved/b.bin", "--config", str(site), "--out", "logs", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert [ln for ln in p.stderr.splitlines() if "healthy period" in ln] == [
        f"  note: the healthy period is not shaded: its commissioned capture {tmp_path.resolve() / 'a.bin'} is not "
        "found, and the site file has no size and digest to know it moved by (if this is it: set "
        f"commissioned.capture to {tmp_path.resolve() / 'moved' / 'b.bin'}, or calibrate again)"], p.stderr


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
