"""A configured band at or above the board's Nyquist frequency (fs/2) holds no signal: its
value would read 0 (zone A) and its alarm never fire.  `cmsensord replay` lists those values
unavailable in the indicator records and says so once, naming the keys; a band in orders, in
the records where the speed puts it there."""

from __future__ import annotations

import subprocess
import sys

from cmsensord.sinks.mcap_sink import read_messages
from cmsensord.sinks.schemas import SCHEMAS
from foxglove_schema import message_problems

WARNING = ("WARNING band_above_nyquist: indicators.velocity_band_hz 13000-20000 Hz; indicators.envelope_band_hz "
           "13000-20000 Hz; indicators.bands[0] 12600-14000 Hz: at or above the Nyquist frequency 12500 Hz of the "
           "board's 25000 Hz sampling, no signal there: velocity_rms_mm_s, zone, envelope_rms, bearings, band.hf "
           "listed unavailable in the indicator records; set a band below it")


def _replay(tmp_path, yaml: str, *board: str):
    """(the output lines, the /cm/ch0/indicators records) of `cmsensord replay` with ``yaml`` of a
    RAW capture of the simulated board (4 s of the healthy motor, or as the ``board`` options say)."""
    cap = tmp_path / "raw.bin"
    subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "healthy", "--mode", "raw", "--duration", "4",
                    *board, "--out", str(cap)], check=True, capture_output=True)
    cfg = tmp_path / "site.yaml"
    cfg.write_text(yaml)
    p = subprocess.run([sys.executable, "-m", "cmsensord", "replay", str(cap), "--config", str(cfg),
                        "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    recs = [m for t, _, m in read_messages(next((tmp_path / "out").glob("*.mcap"))) if t == "/cm/ch0/indicators"]
    return p.stderr.splitlines(), recs


def test_bands_past_fs_over_2_are_unavailable_and_said_once(tmp_path):
    lines, recs = _replay(tmp_path, "indicators:\n  velocity_band_hz: [13000, 20000]\n"
                                    "  envelope_band_hz: [13000, 20000]\n  bands:\n"
                                    "    - {name: hf, lo_hz: 12600, hi_hz: 14000}\n"
                                    "    - {name: lf, lo_hz: 10, hi_hz: 1000}\n")
    assert [ln for ln in lines if ln.startswith("WARNING band_above_nyquist")] == [WARNING]
    assert not [ln for ln in lines if "band_too_narrow" in ln], lines      # past Nyquist: said as that alone
    assert len(recs) >= 3
    for r in recs:
        assert r["unavailable"] == ["velocity_rms_mm_s", "zone", "envelope_rms", "bearings", "band.hf"], r
        assert not {"velocity_rms_mm_s", "zone", "envelope_rms", "bearings"} & set(r), r
        assert r["velocity_band_hz"] == [13000, 20000], r          # as configured, not cut to a band backwards
        assert [b["name"] for b in r["bands"]] == ["lf"] and r["bands"][0]["rms"] > 0, r


def test_bands_below_fs_over_2_read_as_before(tmp_path):
    lines, recs = _replay(tmp_path, "indicators:\n  velocity_band_hz: [10, 1000]\n")
    assert not [ln for ln in lines if "band_above_nyquist" in ln]
    assert recs and all(r["velocity_rms_mm_s"] > 0 and "unavailable" not in r for r in recs), recs[0]


def test_a_band_in_orders_past_fs_over_2_at_the_speed_is_unavailable_and_said_once(tmp_path):
    """Orders 450-500 at 1720 rpm are 12.9-14.3 kHz, past 12.5 kHz: the band's entry had no rms
    (its record broke the indicator schema) and nothing said so; now it is left out, listed
    unavailable, and one warning says which band and at what frequencies."""
    lines, recs = _replay(tmp_path, "indicators:\n  bands:\n    - {name: low, lo_hz: 10, hi_hz: 100}\n"
                                    "    - {name: high_orders, lo_order: 450, hi_order: 500}\n", "--tacho")
    said = [ln for ln in lines if ln.startswith("WARNING band_")]
    assert len(said) == 1 and said[0].startswith(
        "WARNING band_above_nyquist: ch0: indicators.bands[1] (high_orders, 450-500 orders) 12"), said
    assert said[0].endswith(" Hz at this speed: at or above the Nyquist frequency 12500 Hz of the board's 25000 Hz "
                            "sampling, no signal there: band.high_orders listed unavailable while it is; set the "
                            "band's orders lower"), said
    assert len(recs) >= 3
    for r in recs:
        assert message_problems(r, SCHEMAS["indicators"]) == [], r
        assert r["unavailable"] == ["band.high_orders"], r
        assert [b["name"] for b in r["bands"]] == ["low"] and r["bands"][0]["rms"] > 0, r
