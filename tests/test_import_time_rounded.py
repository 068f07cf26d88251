"""A time column printed with fewer decimals than the rate needs (``0.0000, 0.0000, 0.0001, ...``
at 25.6 kHz: a time repeats) is still the time base and gives the rate: it was taken for a
vibration channel ("give --fs", then a ramp of seconds imported beside the signal)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from processes import run_module

FS = 25600


def _csv(path, times: np.ndarray, decimals: int = 4, label: str = "Time (s)") -> None:
    x = np.sin(2 * np.pi * 24.67 * np.arange(times.size) / FS)
    np.savetxt(path, np.column_stack([times, x]), fmt=[f"%.{decimals}f", "%.5f"], delimiter=",",
               header=f"{label},acc (g)", comments="")


def test_rounded_times_are_the_time_base_and_give_the_rate(tmp_path):
    _csv(tmp_path / "t4.csv", np.arange(2 * FS) / FS)
    for extra in ([], ["--fs", str(FS)]):
        p = run_module("cmsensord", "import", str(tmp_path / "t4.csv"), *extra, "--out", str(tmp_path / "t4.bin"))
        assert p.returncode == 0, p.stderr
        assert ("  note: column 'Time (s)' (0) is the time base: 25600 Hz from its steps; it is not imported as a "
                "channel\n") in p.stderr, p.stderr
        meta = json.loads((tmp_path / "t4.bin.json").read_text())
        assert meta["channel_names"] == ["acc_g"] and meta["fs"] == FS


@pytest.mark.parametrize("seconds, decimals", [(3, 0), (5, 0), (1, 1), (1, 2), (2, 3)])
def test_the_rate_of_coarse_times_is_the_rows_between_their_changes(tmp_path, seconds, decimals):
    """Times printed to whole seconds, or to 0.1 or 0.01 s, at 25.6 kHz: 25600 Hz (a straight
    line fitted to the stepped values gave 24253, 25098, 25472, 25599)."""
    _csv(tmp_path / "t.csv", np.arange(seconds * FS) / FS, decimals)
    p = run_module("cmsensord", "import", str(tmp_path / "t.csv"), "--out", str(tmp_path / "t.bin"))
    assert p.returncode == 0, p.stderr
    assert json.loads((tmp_path / "t.bin.json").read_text())["fs"] == FS


def test_a_temperature_headed_t_that_rises_unevenly_is_a_channel(tmp_path):
    """A warm-up printed to 0.1 degC only rises, with repeats, under a label a time column may
    have (``T``): its runs are uneven, so it is a channel (it was taken for the time base)."""
    n = 20_000
    temp = 20 + 15 * (1 - np.exp(-np.arange(n) / 6000.0))
    _csv(tmp_path / "w.csv", temp, 1, "T")
    p = run_module("cmsensord", "import", str(tmp_path / "w.csv"), "--fs", "1000", "--out", str(tmp_path / "w.bin"))
    assert p.returncode == 0, p.stderr
    assert json.loads((tmp_path / "w.bin.json").read_text())["channel_names"] == ["T", "acc_g"]
    assert "time base" not in p.stderr


def test_rounded_times_with_a_gap_are_the_time_base_without_a_rate(tmp_path):
    t = np.arange(2 * FS) / FS
    t[FS:] += 0.5
    _csv(tmp_path / "gap.csv", t)
    p = run_module("cmsensord", "import", str(tmp_path / "gap.csv"), "--out", str(tmp_path / "gap.bin"))
    assert p.returncode == 2
    assert ("column 'Time (s)' (0) is the time base, not evenly spaced (a step of 0.5 s after row 25600, in times "
            "printed to 0.0001 s)") in p.stderr and "give --fs HZ" in p.stderr, p.stderr
    p = run_module("cmsensord", "import", str(tmp_path / "gap.csv"), "--fs", str(FS), "--out", str(tmp_path / "g.bin"))
    assert p.returncode == 0, p.stderr
    assert json.loads((tmp_path / "g.bin.json").read_text())["channel_names"] == ["acc_g"]
