"""The combined severity's level part reads the overall RMS of a decision period against the
healthy baseline, as the analysts' "2 x baseline" rule does: growth that lives in a few blocks
of each second (a bearing's impacts) counts with its energy, not only when it fills most blocks."""

from __future__ import annotations

import numpy as np

from cmsensord.sinks.mcap_sink import read_messages
from processes import run_module

FS = 25600


def _impacts(seconds: float, per_s: float, rng) -> np.ndarray:
    """Unit impacts ``per_s`` a second, each a 3-kHz ring decaying in 1.5 ms."""
    n = int(seconds * FS)
    t = np.arange(int(0.01 * FS)) / FS
    ring = np.exp(-t / 0.0015) * np.sin(2 * np.pi * 3000 * t)
    at = np.zeros(n)
    at[(np.arange(0, seconds, 1 / per_s) * FS).astype(int)] = 1.0
    return np.convolve(at, ring)[:n]


def test_impacts_that_raise_the_overall_rms_2_5_times_grade_the_level(tmp_path):
    rng = np.random.default_rng(2)
    healthy = rng.standard_normal(30 * FS)
    imp = _impacts(30, 12, rng)
    faulty = rng.standard_normal(30 * FS) + np.sqrt((2.5**2 - 1) / np.mean(imp**2)) * imp
    np.save(tmp_path / "x.npy", np.concatenate([healthy, faulty]))
    cap, site, out = tmp_path / "x.bin", tmp_path / "site.yaml", tmp_path / "out"
    for args in (("import", str(tmp_path / "x.npy"), "--fs", str(FS), "--unit", "m/s2", "--out", str(cap)),
                 ("calibrate", str(cap), "--to", "50%", "--out", str(site)),
                 ("replay", str(cap), "--config", str(site), "--out", str(out))):
        p = run_module("cmsensord", *args)
        assert p.returncode == 0, p.stderr
    sev = [m for path in out.glob("*.mcap") for t, _, m in read_messages(path) if t == "/cm/ch/severity"]
    assert len(sev) == 60
    ratio = np.median([m["level_ratio"] for m in sev[35:]])
    assert abs(ratio - 2.5) < 0.1, ratio                     # the overall RMS ratio; the median block read 1.01
    assert all(m["severity_level"] >= 0.5 for m in sev[35:])
    assert all(m["severity_level"] == 0.0 for m in sev[1:29])
