"""Low-speed machines through the commands a user types: a synthetic recording imported
(`cmsensord import`, the speed from a tacho made with `--rpm` or none) and replayed, its
indicators read from the MCAP. ISO 10816-3's 2-1000 Hz velocity band follows the speed each
record carries: the tacho's, else ``indicators.rpm``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cmsensord.sinks.mcap_sink import read_messages
from processes import run_module

FS = 25600
#: the 1x's velocity RMS [mm/s]: zone C of a group 2 machine on a rigid foundation (2.8-4.5)
V_MM_S = 4.0


def ok(*args: str) -> None:
    p = run_module("cmsensord", *args)
    assert p.returncode == 0, p.stderr


def replay_1x(work: Path, rpm: float, *, tacho: bool, site: str = "", seconds: int = 5,
              v_mm_s: float = V_MM_S) -> list[dict]:
    """A pure 1x at ``rpm`` of ``v_mm_s`` velocity RMS, in m/s^2, imported (with ``--rpm`` when
    ``tacho``) and replayed with the configuration ``site``: its indicator records."""
    f1 = rpm / 60.0
    t = np.arange(seconds * FS) / FS
    np.save(work / "x.npy", v_mm_s / 1000.0 * np.sqrt(2) * 2 * np.pi * f1 * np.sin(2 * np.pi * f1 * t))
    ok("import", str(work / "x.npy"), "--fs", str(FS), "--unit", "m/s2", "--names", "ch",
       *(("--rpm", f"{rpm:g}") if tacho else ()), "--out", str(work / "x.bin"))
    (work / "site.yaml").write_text("output:\n  status_line: false\n" + site)
    ok("replay", str(work / "x.bin"), "--config", str(work / "site.yaml"), "--out", str(work / "out"))
    return [m for t, _, m in read_messages(next((work / "out").glob("*.mcap"))) if t == "/cm/ch/indicators"]


def test_a_tacho_speed_below_600_rpm_grades_the_velocity_over_2_to_1000_hz(tmp_path):
    recs = replay_1x(tmp_path, 300.0, tacho=True)[1:-1]
    assert recs and all(m["speed_source"] == "tacho" and m["speed_rpm"] == pytest.approx(300, rel=1e-3) for m in recs)
    for m in recs:      # the 5-Hz 1x inside the band (not 10-1000 Hz: 0.000 mm/s, zone A)
        assert m["velocity_band_hz"] == [2.0, 1000.0] and m["zone"] == "C"
        assert m["velocity_rms_mm_s"] == pytest.approx(V_MM_S, rel=0.03)


def test_at_600_rpm_the_1x_is_inside_the_2_hz_band_not_on_the_10_hz_edge(tmp_path):
    recs = replay_1x(tmp_path, 600.0, tacho=False, site="indicators:\n  rpm: 600\n")[1:-1]
    assert recs
    for m in recs:      # not 10-1000 Hz: 3.588 mm/s (the Hann lobe's lower half cut off)
        assert m["velocity_band_hz"] == [2.0, 1000.0] and m["speed_source"] == "config"
        assert m["velocity_rms_mm_s"] == pytest.approx(V_MM_S, rel=0.01)


def test_a_tacho_speed_above_600_rpm_keeps_10_to_1000_hz_whatever_indicators_rpm_says(tmp_path):
    recs = replay_1x(tmp_path, 1500.0, tacho=True, site="indicators:\n  rpm: 300\n", seconds=4)[1:-1]
    assert recs
    for m in recs:
        assert m["speed_source"] == "tacho" and m["velocity_band_hz"] == [10.0, 1000.0]
        assert m["velocity_rms_mm_s"] == pytest.approx(V_MM_S, rel=0.01)
