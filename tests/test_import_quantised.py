"""An import whose range leaves some snapshots (or seconds of a continuous recording) a few counts
says so in one line a channel: how many, the first, what is quantised, and the --range that resolves
them, which an import of those alone then takes without the line and without clipping."""

from __future__ import annotations

import re

import numpy as np

from processes import run_module

FS = 25600
N = FS // 10
QUIET = (3, 5)                  # the snapshots 1000 x quieter than the others


def _import(tmp_path, src, name: str, *extra: str) -> str:
    p = run_module("cmsensord", "import", str(src), "--fs", str(FS), "--unit", "m/s2", *extra,
                   "--out", str(tmp_path / f"{name}.bin"))
    assert p.returncode == 0, p.stderr
    return p.stderr


def _counts_rms(x: np.ndarray, full_scale: float) -> float:
    """The RMS in counts of ``x`` without its mean at +-full_scale (2048 counts)."""
    return float(np.sqrt(np.mean((x - x.mean()) ** 2)) / (full_scale / 2048))


def _snapshots() -> np.ndarray:
    x = np.random.default_rng(3).standard_normal((6, N, 1))
    x[list(QUIET)] *= 1e-3
    return x


def test_the_snapshots_under_10_counts_rms_are_named_with_the_range_that_resolves_them(tmp_path):
    x = _snapshots()
    np.save(tmp_path / "s.npy", x)
    err = _import(tmp_path, tmp_path / "s.npy", "s")
    full = float(re.search(r"ch: full scale \+-([0-9.]+) m/s2", err).group(1))
    assert [_counts_rms(x[k, :, 0], full) < 10 for k in range(6)] == [k in QUIET for k in range(6)]
    lines = [ln for ln in err.splitlines() if "counts RMS" in ln]
    assert len(lines) == 1, err
    assert lines[0].startswith(f"  WARNING ch: 2 of 6 snapshot(s) carry under 10 counts RMS at +-{full:g} m/s2 "), err
    assert "the first: s.npy[3] at 50 % of the record, " in lines[0], err
    assert "level, kurtosis and crest factor" in lines[0], err
    fix = re.search(r"with --range ([0-9.e-]+)$", lines[0])
    assert fix, lines[0]
    # the quiet snapshots on their own at that range: resolved, and nothing clips
    np.save(tmp_path / "q.npy", x[list(QUIET)])
    alone = _import(tmp_path, tmp_path / "q.npy", "q", "--range", fix.group(1))
    assert "counts RMS" not in alone and "no clipping" in alone, alone


def test_the_quiet_seconds_of_a_continuous_recording_and_no_line_when_every_part_is_resolved(tmp_path):
    x = np.random.default_rng(4).standard_normal(FS * 10)
    x[FS * 3:FS * 5] *= 1e-3
    np.save(tmp_path / "c.npy", x)
    err = _import(tmp_path, tmp_path / "c.npy", "c")
    line = [ln for ln in err.splitlines() if "counts RMS" in ln]
    assert len(line) == 1 and line[0].startswith("  WARNING ch: 2 s of its 10 s carry under 10 counts RMS at "), err
    assert "; the first from 3 s, " in line[0] and line[0].split("--range ")[0].endswith("on its own with "), err
    np.save(tmp_path / "loud.npy", _snapshots()[[0, 1, 2, 4]])
    assert "counts RMS" not in _import(tmp_path, tmp_path / "loud.npy", "loud"), err
