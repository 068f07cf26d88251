"""A time column printed with fewer decimals than the rate needs (``0.0000, 0.0000, 0.0001, ...``
at 25.6 kHz: a time repeats) is still the time base and gives the rate: it was taken for a
vibration channel ("give --fs", then a ramp of seconds imported beside the signal)."""

from __future__ import annotations

import json

import numpy as np

from processes import run_module

FS = 25600


def _csv(path, times: np.ndarray) -> None:
    x = np.sin(2 * np.pi * 24.67 * np.arange(times.size) / FS)
    np.savetxt(path, np.column_stack([times, x]), fmt=["%.4f", "%.5f"], delimiter=",", header="Time (s),acc (g)",
               comments="")


def test_rounded_times_are_the_time_base_and_give_the_rate(tmp_path):
    _csv(tmp_path / "t4.csv", np.arange(2 * FS) / FS)
    for extra in ([], ["--fs", str(FS)]):
        p = run_module("cmsensord", "import", str(tmp_path / "t4.csv"), *extra, "--out", str(tmp_path / "t4.bin"))
        assert p.returncode == 0, p.stderr
        assert ("  note: column 'Time (s)' (0) is the time base: 25600 Hz from its steps; it is not imported as a "
                "channel\n") in p.stderr, p.stderr
        meta = json.loads((tmp_path / "t4.bin.json").read_text())
        assert meta["channel_names"] == ["acc_g"] and meta["fs"] == FS


def test_rounded_times_with_a_gap_are_the_time_base_without_a_rate(tmp_path):
    t = np.arange(2 * FS) / FS
    t[FS:] += 0.5
    _csv(tmp_path / "gap.csv", t)
    p = run_module("cmsensord", "import", str(tmp_path / "gap.csv"), "--out", str(tmp_path / "gap.bin"))
    assert p.returncode == 2
    assert "column 'Time (s)' (0) is the time base, not evenly spaced" in p.stderr and "give --fs HZ" in p.stderr
    p = run_module("cmsensord", "import", str(tmp_path / "gap.csv"), "--fs", str(FS), "--out", str(tmp_path / "g.bin"))
    assert p.returncode == 0, p.stderr
    assert json.loads((tmp_path / "g.bin.json").read_text())["channel_names"] == ["acc_g"]
