"""An alarm line on the velocity RMS, or on its ISO 10816-3 zone, says the band the velocity was
taken over (a velocity RMS means nothing without it: ISO 10816-3 grades 10-1000 Hz, 2-1000 Hz for
machines at or below 600 r/min): it said `velocity_rms_mm_s 4.085 mm/s (velocity RMS)`.  A 300-rpm
machine imported with its speed (`cmsensord import --rpm 300`) and replayed: its 1x at 5 Hz of
4.0 mm/s RMS (4.085 read, +2.1 % at 5 bins up: the README's low-frequency bias; zone C of
group 2, rigid) is graded over 2-1000 Hz, and the lines say so."""

from __future__ import annotations

import numpy as np

from processes import run_module

FS = 25600
F1 = 5.0                                     # the 1x of 300 rpm
V_MM_S = 4.0                                 # its velocity RMS


def test_the_alarm_line_names_the_velocity_band(tmp_path):
    t = np.arange(4 * FS) / FS
    a_peak = V_MM_S / 1000 * np.sqrt(2) * 2 * np.pi * F1       # m/s^2 of a 4.0 mm/s RMS sine at 5 Hz
    np.save(tmp_path / "x.npy", a_peak * np.sin(2 * np.pi * F1 * t)[:, None])
    p = run_module("cmsensord", "import", str(tmp_path / "x.npy"), "--fs", str(FS), "--unit", "m/s2", "--names", "ch",
                   "--rpm", "300", "--out", str(tmp_path / "x.bin"))
    assert p.returncode == 0, p.stderr
    (tmp_path / "site.yaml").write_text(
        "output:\n  status_line: false\nindicators:\n  machine_group: 2\n  foundation: rigid\nalarms:\n  rules:\n"
        "    - {name: vel, indicator: velocity_rms_mm_s, alert: 2.8}\n    - {name: z, indicator: zone, alert: 2}\n")
    p = run_module("cmsensord", "replay", str(tmp_path / "x.bin"), "--config", str(tmp_path / "site.yaml"),
                   "--out", str(tmp_path / "out"))
    assert p.returncode == 0, p.stderr
    said = [ln for ln in p.stderr.splitlines() if ln.startswith("WARNING alarm_")]
    assert said == [
        "WARNING alarm_alert: vel/ch: velocity_rms_mm_s 4.085 mm/s (velocity RMS, 2-1000 Hz) reached the alert level "
        "2.8 mm/s",
        "WARNING alarm_alert: z/ch: zone 2 (ISO 10816-3 zone, A-D as 0-3, of the velocity RMS over 2-1000 Hz) "
        "reached the alert level 2"], p.stderr
