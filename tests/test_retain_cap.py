"""``output.retain_mb`` caps the prefix's files with the one being written: retention leaves it
room to grow to ``rotate_mb`` (the files took up to retain_mb + rotate_mb: 1.77 MB of a 1.5-MB cap);
a cap below twice ``rotate_mb``, which at times keeps no finished file, is said at start."""

from __future__ import annotations

import subprocess
import sys


def _replay(tmp_path, scenario: str, duration: str, output: str, *more: str) -> subprocess.CompletedProcess:
    """``cmsensord replay`` of a simulated capture with ``output`` as its output section."""
    cap = tmp_path / "a.bin"
    subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", scenario, "--duration", duration,
                    "--out", str(cap)], check=True, capture_output=True)
    cfg = tmp_path / "ret.yaml"
    cfg.write_text(f"output:\n{output}  min_free_mb: 0\n")
    return subprocess.run([sys.executable, "-m", "cmsensord", "replay", str(cap), "--config", str(cfg), *more,
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=300)


def test_a_replay_keeps_its_files_within_retain_mb(tmp_path):
    p = _replay(tmp_path, "degrading", "600", "  rotate_mb: 0.5\n  retain_mb: 1.5\n", "--akf-trace")
    out = tmp_path / "out"
    assert p.returncode == 0, p.stderr
    files = sorted(out.glob("*.mcap"))
    assert len(files) >= 2, files                       # a finished file kept beside the newest
    assert sum(f.stat().st_size for f in out.iterdir()) <= 1.5e6, [(f.name, f.stat().st_size) for f in files]
    assert "retention: retain_mb" not in p.stderr, p.stderr       # 1.5 MB holds a 0.5-MB file beside the open one


def test_a_cap_below_twice_rotate_mb_is_said_at_start(tmp_path):
    p = _replay(tmp_path, "healthy", "5", "  rotate_mb: 1\n  retain_mb: 1.9\n")
    assert p.returncode == 0, p.stderr
    said = [ln for ln in p.stderr.splitlines() if "retention: retain_mb" in ln]
    assert said == ["WARNING retention: retain_mb = 1.9 MB counts the file being written (up to rotate_mb = 1 MB) "
                    "too: below 2 x rotate_mb, at times no finished log is kept; set retain_mb >= 2 or rotate_mb "
                    "<= 0.95"], p.stderr
