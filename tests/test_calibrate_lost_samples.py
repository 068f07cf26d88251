"""`cmsensord calibrate` on a lossy link: the indicator baselines come from the records that miss
at most ``indicators.max_missing_fraction`` of their samples (the limit up to which the daemon
gives their spectral indicators, cmsensord/dsp/indicators/gapped.py), of the configuration
calibrate runs with; the records past it are left out, with one line that says how many, why,
which channel got no indicator baseline and what to do."""

from __future__ import annotations

import numpy as np
import yaml

from processes import cmsensord

FS, SECONDS = 10000, 6
SPECTRAL = {"velocity_rms_mm_s", "envelope_rms"}


def _lossy(tmp_path):
    """Channels a (1 % of each 1-s record lost), b (10 % of each), c (10 % of the first three, 1 % of
    the others),
    4 mm/s at 50 Hz and noise, imported: the lost samples' blocks are frames the board lost."""
    t = np.arange(SECONDS * FS) / FS
    rng = np.random.default_rng(7)
    x = np.stack([4.0 * np.sqrt(2) * 2 * np.pi * 50 / 1000 * np.sin(2 * np.pi * 50 * t)
                  + 0.5 * rng.standard_normal(t.size) for _ in range(3)], axis=1)
    for k in range(SECONDS):
        at = k * FS + 3000
        x[at:at + 100, 0] = np.nan
        x[at:at + 1000, 1] = np.nan
        x[at:at + (1000 if k < 3 else 100), 2] = np.nan
    np.save(tmp_path / "lossy.npy", x)
    p = cmsensord("import", "lossy.npy", "--fs", str(FS), "--unit", "m/s2", "--names", "a,b,c", "--rpm", "1800",
                  "--out", "lossy.bin", cwd=tmp_path)
    assert p.returncode == 0, p.stderr


def _baselines(path) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for row in yaml.safe_load(path.read_text())["alarms"]["baselines"]:
        out.setdefault(row["channel"], set()).add(row["indicator"])
    return out


def test_records_with_a_few_lost_samples_give_the_indicator_baselines(tmp_path):
    _lossy(tmp_path)
    p = cmsensord("calibrate", "lossy.bin", "--out", "site.yaml", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    learned = _baselines(tmp_path / "site.yaml")
    assert SPECTRAL <= learned["a"] and SPECTRAL <= learned["c"] and "b" not in learned, learned
    lines = [ln for ln in p.stdout.splitlines() if "left out" in ln and "indicator" in ln]
    assert lines == [
        "note: indicator records of the healthy period left out, more than 5 % of their samples lost "
        "(indicators.max_missing_fraction 0.05): b 6 of 6, c 3 of 6; so no indicator baseline for b: calibrate on "
        "a healthy period from a better link, or give a higher indicators.max_missing_fraction in --config "
        "BASE.yaml"], p.stdout
    # the limit is the configuration's: at 0.5 % every record is left out, at 20 % none
    (tmp_path / "strict.yaml").write_text("indicators:\n  max_missing_fraction: 0.005\n")
    (tmp_path / "lax.yaml").write_text("indicators:\n  max_missing_fraction: 0.2\n")
    p = cmsensord("calibrate", "lossy.bin", "--config", "strict.yaml", "--out", "strict_site.yaml", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "note: 6 of 6 indicator record(s) of the healthy period left out: more than 0.5 % of their samples " \
           "lost (indicators.max_missing_fraction 0.005); so no indicator baseline for a, b, c: calibrate on a " \
           "healthy period from a better link, or give a higher indicators.max_missing_fraction in --config " \
           "BASE.yaml" in p.stdout.splitlines(), p.stdout
    assert "alarms:" not in (tmp_path / "strict_site.yaml").read_text()
    p = cmsensord("calibrate", "lossy.bin", "--config", "lax.yaml", "--out", "lax_site.yaml", cwd=tmp_path)
    assert p.returncode == 0 and "indicator record" not in p.stdout, p.stdout + p.stderr
    assert all(SPECTRAL <= v for v in _baselines(tmp_path / "lax_site.yaml").values())
