"""A record that misses a small share of its samples (a link losing a 10-ms block now and then)
still gives its spectral indicators, from the samples it has (cmsensord/dsp/indicators/gapped.py),
so the ISO velocity alarm and the bearing lines keep working on such a link; a record missing
more than ``indicators.max_missing_fraction`` lists them unavailable.

The same stationary signal (4 mm/s at 50 Hz, an impact train at the BPFO of 107.5 Hz, noise)
imported twice, whole and with one 10-ms block missing in each 1-s record (the last but one
missing exactly the default limit of 5 %, the last 20 %), and replayed.  Measured: velocity RMS
within 0.44 %, envelope RMS within 0.14 %, the BPFO line's amplitude within 0.43 % of the
records without gaps.
"""

from __future__ import annotations

import numpy as np

from cmsensord.sinks.mcap_sink import read_messages
from processes import cmsensord

FS = 20000
SECONDS = 11
BPFO = 107.5435450819672        # 9 balls of 7.94 on 39.04 at 1800 rpm
CONFIG = """\
indicators:
  rpm: 1800
bearings:
  - {name: b, channel: ch, elements: 9, ball_diameter: 7.94, pitch_diameter: 39.04}
alarms:
  rules:
    - name: velocity
      indicator: velocity_rms_mm_s
      alert_zone: C
      danger_zone: D
"""
SPECTRAL = ["velocity_rms_mm_s", "zone", "envelope_rms", "bearings", "bands"]


def _signal() -> np.ndarray:
    t = np.arange(SECONDS * FS) / FS
    x = 4.0 * np.sqrt(2) * 2 * np.pi * 50 / 1000 * np.sin(2 * np.pi * 50 * t)
    n = np.arange(400)
    pulse = 3.0 * np.exp(-n / FS * 800) * np.sin(2 * np.pi * 4000 * n / FS)
    for tk in np.arange(0, SECONDS, 1 / BPFO):
        i0 = int(tk * FS)
        m = min(400, t.size - i0)
        x[i0:i0 + m] += pulse[:m]
    return x + 0.5 * np.random.default_rng(7).standard_normal(t.size)


def _replay(tmp_path, name: str, x: np.ndarray | None, config: str = "c.yaml") -> tuple[list[dict], list[str]]:
    """The indicator records and alarm lines of a replay of ``x`` imported as <name>.bin (None:
    imported already) with ``config``."""
    if x is not None:
        np.save(tmp_path / f"{name}.npy", x[:, None])
        p = cmsensord("import", f"{name}.npy", "--fs", str(FS), "--unit", "m/s2", "--names", "ch", "--rpm", "1800",
                      "--out", f"{name}.bin", cwd=tmp_path)
        assert p.returncode == 0, p.stderr
    out = f"o_{name}_{config}"
    p = cmsensord("replay", f"{name}.bin", "--config", config, "--out", out, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    recs = [m for path in sorted((tmp_path / out).glob("*.mcap"))
            for t, _, m in read_messages(path) if t == "/cm/ch/indicators"]
    return recs, [ln.split(" mm/s")[0] for ln in p.stderr.splitlines() if ln.startswith("WARNING alarm_")]


def test_a_record_missing_one_block_gives_its_spectral_indicators_as_a_whole_one(tmp_path):
    (tmp_path / "c.yaml").write_text(CONFIG)
    x = _signal()
    gapped = x.copy()
    for k in range(SECONDS - 1):            # one 10-ms block (200 samples) a record, here and there in it
        at = k * FS + (37 + 29 * k) % 100 * 200
        gapped[at:at + 200] = np.nan
    at = (SECONDS - 2) * FS + 7000
    gapped[at:at + 800] = np.nan            # the last but one misses 5 % (1000 samples): the default limit
    last = (SECONDS - 1) * FS
    gapped[last + 1000:last + 5000] = np.nan    # the last record misses 20 %
    whole, alarms_whole = _replay(tmp_path, "whole", x)
    holed, alarms_holed = _replay(tmp_path, "holed", gapped)
    assert len(whole) == len(holed) == SECONDS
    assert [m["missing_fraction"] for m in holed] == [0.01] * (SECONDS - 2) + [0.05, 0.2]
    for w, g in zip(whole[:-1], holed[:-1]):
        assert "unavailable" not in g, g
        assert g["zone"] == w["zone"] == "C"
        assert abs(g["velocity_rms_mm_s"] / w["velocity_rms_mm_s"] - 1) < 0.02, (g, w)
        assert abs(g["envelope_rms"] / w["envelope_rms"] - 1) < 0.05, (g, w)
        bw, bg = w["bearings"][0]["lines"]["bpfo"], g["bearings"][0]["lines"]["bpfo"]
        assert bg["freq_hz"] == bw["freq_hz"] == 108.0
        assert abs(bg["amplitude"] / bw["amplitude"] - 1) < 0.05, (bg, bw)
    assert holed[-1]["unavailable"] == SPECTRAL and "velocity_rms_mm_s" not in holed[-1]
    assert "accel_rms" in holed[-1]
    # the velocity alarm fires on the link that loses a block in every record as without losses
    alert = "WARNING alarm_alert: velocity/ch: velocity_rms_mm_s "
    assert alarms_whole == [alert + "4.021"] and alarms_holed == [alert + "4.035"]
    # max_missing_fraction 0: the spectral indicators of complete records only
    (tmp_path / "none.yaml").write_text(CONFIG.replace("  rpm: 1800\n", "  rpm: 1800\n  max_missing_fraction: 0\n"))
    strict, alarms = _replay(tmp_path, "holed", None, "none.yaml")
    assert [m["unavailable"] for m in strict] == [SPECTRAL] * SECONDS and alarms == []
