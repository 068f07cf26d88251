"""A configured band narrower than the record's spectral bins (1 Hz for records of 1 s) can hold
no bin: its value read 0 (the faulty motor at 8.4 mm/s read velocity 0.0, zone A, envelope 0.0
under an inverted band [2001, 2000]; a band 0.0), with no word.  `cmsensord replay` leaves those
values out, lists them unavailable in the indicator records, and says so once per channel and
band, naming the bin width and what would do; a band that holds one bin reads it."""

from __future__ import annotations

import subprocess
import sys

from test_band_above_nyquist import _replay

NARROW = ("indicators:\n  velocity_band_hz: [10.2, 10.8]\n  envelope_band_hz: [2000.2, 2000.7]\n  bands:\n"
          "    - {name: narrow, lo_hz: 100.2, hi_hz: 100.8}\n    - {name: one_x, lo_order: 1.0, hi_order: 1.008}\n"
          "    - {name: wide, lo_hz: 100, hi_hz: 101}\n")
TOLD = "holds no bin of the record's spectrum (1-Hz bins, records of 1 s): {} listed unavailable; widen the band " \
       "to at least 1 Hz, or lengthen indicators.interval_s"


def test_bands_narrower_than_a_bin_are_unavailable_and_said_once(tmp_path):
    lines, recs = _replay(tmp_path, NARROW, "--scenario", "faulty", "--tacho", "--duration", "5")
    told = [ln for ln in lines if ln.startswith("WARNING band_too_narrow: ")]
    shaft = [r for r in recs if "speed_rpm" in r]
    assert len(shaft) >= 3, recs
    lo, hi = (round(shaft[0]["speed_rpm"] / 60 * k, 6) for k in (1.0, 1.008))
    assert told[:3] == [
        "WARNING band_too_narrow: ch0: indicators.velocity_band_hz 10.2-10.8 Hz " + TOLD.format(
            "velocity_rms_mm_s, zone"),
        "WARNING band_too_narrow: ch0: indicators.envelope_band_hz 2000.2-2000.7 Hz " + TOLD.format(
            "envelope_rms, bearings"),
        "WARNING band_too_narrow: ch0: indicators.bands[0] (narrow) 100.2-100.8 Hz " + TOLD.format(
            "band.narrow")], lines
    assert len(told) == 4 and told[3].startswith(
        f"WARNING band_too_narrow: ch0: indicators.bands[1] (one_x, 1-1.008 orders) {lo:g}-{hi:g} Hz holds no "
        "bin"), told
    for r in shaft:
        assert r["unavailable"] == ["velocity_rms_mm_s", "zone", "envelope_rms", "bearings", "band.narrow",
                                    "band.one_x"], r
        assert not {"velocity_rms_mm_s", "zone", "envelope_rms"} & set(r), r
        assert r["envelope_band_hz"] == [2000.2, 2000.7], r
        assert [b["name"] for b in r["bands"]] == ["wide"] and r["bands"][0]["rms"] > 0, r


def test_calibrate_says_why_a_rule_on_such_a_band_is_not_judged(tmp_path):
    """A rule on the velocity of a band that holds no bin: calibrate's line gives that as the
    reason (it gave an RMS-mode board's, of a RAW capture)."""
    cap = tmp_path / "raw.bin"
    subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "healthy", "--mode", "raw", "--duration", "8",
                    "--out", str(cap)], check=True, capture_output=True)
    base = tmp_path / "base.yaml"
    base.write_text("indicators:\n  velocity_band_hz: [10.2, 10.8]\nalarms:\n  rules:\n"
                    "    - {name: vel, indicator: velocity_rms_mm_s, alert: 4.5}\n")
    p = subprocess.run([sys.executable, "-m", "cmsensord", "calibrate", str(cap), "--config", str(base),
                        "--out", str(tmp_path / "site.yaml")], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert ("alarms: rule(s) vel not judged: the capture's indicator records carry no velocity_rms_mm_s (listed "
            "unavailable: a band past Nyquist, or one that holds no bin of the records' spectrum)"
            ) in p.stdout.splitlines(), p.stdout
