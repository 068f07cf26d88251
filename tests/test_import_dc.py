"""`cmsensord import` takes each channel's mean out, as the board's offset calibration does: a
DC-coupled logger's offset goes neither into the block RMS and the severity's level nor into
the 12-bit range; each snapshot's own mean, or the whole recording's; `--keep-dc` keeps it."""

from __future__ import annotations

import json

import numpy as np

from cmsensord.sinks.mcap_sink import read_messages
from processes import run_module

FS = 2000


def _run(*args) -> str:
    p = run_module("cmsensord", *map(str, args))
    assert p.returncode == 0, p.stderr
    return p.stderr


def test_an_offset_does_not_go_into_the_baseline_and_the_level(tmp_path):
    """A vibration that grows 2.5 x on an offset of 1.2 m/s2 (1.2 x its healthy RMS, as the
    IMS rig's first test): the level reads 2.5 x the baseline (guards against a baseline
    that is the RMS with the offset, 1.56, and a level of 1.78 x, graded 0)."""
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.standard_normal(30 * FS), 2.5 * rng.standard_normal(30 * FS)]) + 1.2
    np.save(tmp_path / "x.npy", x)
    cap, site, out = tmp_path / "x.bin", tmp_path / "site.yaml", tmp_path / "out"
    err = _run("import", tmp_path / "x.npy", "--fs", FS, "--unit", "m/s2", "--out", cap)
    mean = float(np.mean(x))
    assert (f"  ch: mean {mean:.4g} m/s2 removed (the board's offset correction; --keep-dc keeps it)\n"
            in err), err
    assert f"  ch: full scale +-15 m/s2 (0.007324 m/s2 a count), peak {np.abs(x - mean).max():.4g} m/s2" in err
    meta = json.loads((tmp_path / "x.bin.json").read_text())
    assert meta["dc_removed"] == [round(mean, 9)]
    _run("calibrate", cap, "--to", "50%", "--out", site)
    baseline = next(float(ln.split()[1]) for ln in site.read_text().splitlines() if "baseline:" in ln)
    assert abs(baseline - 1.0) < 0.02, baseline
    _run("replay", cap, "--config", site, "--out", out)
    sev = [m for path in out.glob("*.mcap") for t, _, m in read_messages(path) if t == "/cm/ch/severity"]
    assert round(float(np.median([m["level_ratio"] for m in sev[35:]])), 1) == 2.5
    assert float(np.median([m["severity_level"] for m in sev[35:]])) > 0.5


def _snapshots() -> np.ndarray:
    """Three snapshots of two channels, sines of whole periods (mean 0, peak 1) on offsets of
    1, 2 and 3 (the accelerometer's, m/s2) and 10, 20, 30 (the microphone's, Pa)."""
    t = np.arange(FS) / FS
    ac = np.sin(2 * np.pi * 50 * t)
    return np.stack([np.stack([ac + k, ac + 10 * k], axis=1) for k in (1, 2, 3)])


def test_each_snapshot_loses_its_own_mean_and_the_range_fits_the_vibration(tmp_path):
    np.save(tmp_path / "s.npy", _snapshots())
    err = _run("import", tmp_path / "s.npy", "--fs", FS, "--unit", "m/s2,Pa", "--names", "acc,mic",
               "--out", tmp_path / "s.bin")
    assert ("  acc: each snapshot's mean removed, 1 to 3 m/s2 (over the recording 2 m/s2) (the board's "
            "offset correction; --keep-dc keeps it)\n") in err, err
    assert ("  mic: each snapshot's mean removed, 10 to 30 Pa (over the recording 20 Pa) (the board's "
            "offset correction; --keep-dc keeps it)\n") in err, err
    assert "  acc: full scale +-1.5 m/s2 (0.0007324 m/s2 a count), peak 1 m/s2, no clipping\n" in err
    assert "  mic: full scale +-1.5 Pa (0.0007324 Pa a count), peak 1 Pa, no clipping\n" in err
    meta = json.loads((tmp_path / "s.bin.json").read_text())
    assert [[round(v, 6) for v in s["dc_removed"]] for s in meta["snapshots"]] == [[1, 10], [2, 20], [3, 30]]
    assert [round(v, 6) for v in meta["dc_removed"]] == [2, 20]


def test_keep_dc_keeps_the_offset(tmp_path):
    np.save(tmp_path / "s.npy", _snapshots())
    err = _run("import", tmp_path / "s.npy", "--fs", FS, "--unit", "m/s2,Pa", "--names", "acc,mic",
               "--keep-dc", "--out", tmp_path / "s.bin")
    assert "removed" not in err
    assert "  acc: full scale +-5 m/s2 (0.002441 m/s2 a count), peak 4 m/s2, no clipping\n" in err
    assert json.loads((tmp_path / "s.bin.json").read_text())["dc_removed"] is None
