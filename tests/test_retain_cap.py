"""``output.retain_mb`` caps the prefix's files with the one being written: retention leaves it
room to grow to ``rotate_mb`` (the files took up to retain_mb + rotate_mb: 1.77 MB of a 1.5-MB cap)."""

from __future__ import annotations

import subprocess
import sys


def test_a_replay_keeps_its_files_within_retain_mb(tmp_path):
    cap = tmp_path / "a.bin"
    subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "degrading", "--duration", "600",
                    "--out", str(cap)], check=True, capture_output=True)
    cfg = tmp_path / "ret.yaml"
    cfg.write_text("output:\n  rotate_mb: 0.5\n  retain_mb: 1.5\n  min_free_mb: 0\n")
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "-m", "cmsensord", "replay", str(cap), "--config", str(cfg), "--akf-trace",
                        "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    files = sorted(out.glob("*.mcap"))
    assert len(files) >= 2, files                       # a finished file kept beside the newest
    assert sum(f.stat().st_size for f in out.iterdir()) <= 1.5e6, [(f.name, f.stat().st_size) for f in files]
