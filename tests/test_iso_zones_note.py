"""The ISO 10816-3 machine class the zones are graded for, said once after a replay's summary or
at the start of a simulated board, in RAW mode (an RMS-mode board's records carry no zone), when
the configuration does not set it; `cmsensord --simulate --help` gives the faulty motor's zone as
the daemon grades it.  With the same runs: an ``indicators.interval_s`` longer than a RAW record
holds at the board's rate is said once by the daemon, replay and calibrate (in RAW mode only), and
one that is not a whole number of an RMS board's blocks, with the length its records are instead
(in RMS mode only)."""

from __future__ import annotations

import pytest

from processes import run_module

NOTE = ("note: ISO 10816-3 zones graded for machine group 2 (15-300 kW) on a rigid foundation (1.4/2.8/4.5 mm/s), "
        "machine_group and foundation not set: the standard covers machines above 15 kW; set "
        "indicators.machine_group (1: > 300 kW, 2: 15-300 kW) and indicators.foundation (rigid, flexible) for "
        "this machine")

#: 5 s of a 25 kHz RAW board: more than the 65,536 samples a record holds
CAPPED = ("indicators.interval_s 5 s is longer than a RAW record holds at 25000 Hz (65,536 samples, 2.62 s): "
          "indicator records are 2.62 s; set indicators.interval_s 2.62 or less")

#: 5.005 s of a board's 100 blocks a second: 500.5 blocks, rounded half to even
ROUNDED = ("indicators.interval_s 5.005 s is not a whole number of the board's RMS blocks (250 samples at "
           "25000 Hz, 0.01 s): indicator records are 500 blocks, 5 s; set indicators.interval_s 5 or 5.01")
#: 1.005 s: 100.49999999999999 blocks as a float, rounded down
ROUNDED_DOWN = ("indicators.interval_s 1.005 s is not a whole number of the board's RMS blocks (250 samples at "
                "25000 Hz, 0.01 s): indicator records are 100 blocks, 1 s; set indicators.interval_s 1 or 1.01")


def capped(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if "indicators.interval_s" in ln]


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    work = tmp_path_factory.mktemp("zones_note")
    p = run_module("firmware_sim", "--scenario", "healthy", "--mode", "raw", "--duration", "2",
                   "--out", str(work / "h.bin"))
    assert p.returncode == 0, p.stderr
    return work / "h.bin"


def test_replay_without_a_machine_class_says_the_one_assumed(tmp_path, capture):
    p = run_module("cmsensord", "replay", str(capture), "--out", str(tmp_path / "a"))
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines()[-1] == NOTE
    assert capped(p.stderr) == []           # 1 s: 25,000 samples a record
    (tmp_path / "one.yaml").write_text("indicators: {machine_group: 1}\n")
    p = run_module("cmsensord", "replay", str(capture), "--config", str(tmp_path / "one.yaml"),
                   "--out", str(tmp_path / "b"))
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines()[-1] == NOTE.replace("group 2 (15-300 kW)", "group 1 (> 300 kW)").replace(
        "1.4/2.8/4.5", "2.3/4.5/7.1").replace("machine_group and foundation not set", "foundation not set")


def test_replay_with_the_machine_class_set_says_nothing_of_it(tmp_path, capture):
    (tmp_path / "set.yaml").write_text("indicators: {machine_group: 2, foundation: flexible}\n")
    p = run_module("cmsensord", "replay", str(capture), "--config", str(tmp_path / "set.yaml"),
                   "--out", str(tmp_path / "c"))
    assert p.returncode == 0, p.stderr
    assert "ISO 10816-3" not in p.stderr


def test_an_interval_longer_than_a_raw_record_holds_is_said_once_by_replay_and_calibrate(tmp_path, capture):
    (tmp_path / "five.yaml").write_text("indicators: {interval_s: 5, machine_group: 2, foundation: rigid}\n")
    p = run_module("cmsensord", "replay", str(capture), "--config", str(tmp_path / "five.yaml"),
                   "--out", str(tmp_path / "e"))
    assert p.returncode == 0, p.stderr
    assert capped(p.stderr) == ["WARNING config: " + CAPPED], p.stderr
    p = run_module("cmsensord", "calibrate", str(capture), "--config", str(tmp_path / "five.yaml"),
                   "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 0, p.stderr
    assert capped(p.stdout + p.stderr) == ["note: " + CAPPED], p.stdout


def test_a_replay_of_an_rms_capture_says_nothing_of_it(tmp_path):
    """Nor of its 1-s records (100 blocks); calibrate notes an interval_s of 1.005 s, 100 blocks."""
    p = run_module("firmware_sim", "--scenario", "healthy", "--duration", "2", "--out", str(tmp_path / "r.bin"))
    assert p.returncode == 0, p.stderr
    p = run_module("cmsensord", "replay", str(tmp_path / "r.bin"), "--out", str(tmp_path / "d"))
    assert p.returncode == 0, p.stderr
    assert "ISO 10816-3" not in p.stderr
    assert capped(p.stderr) == []
    (tmp_path / "odd.yaml").write_text("indicators: {interval_s: 1.005}\n")
    p = run_module("cmsensord", "calibrate", str(tmp_path / "r.bin"), "--config", str(tmp_path / "odd.yaml"),
                   "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 0, p.stderr
    assert capped(p.stdout + p.stderr) == ["note: " + ROUNDED_DOWN], p.stdout


def test_simulate_says_the_machine_class_in_raw_mode_and_its_help_the_zone_it_grades(tmp_path):
    """And an interval_s of 5 s: too long for a RAW record at 25 kHz, said once; an RMS record has no such
    bound, but 5.005 s is not a whole number of its blocks: its records are 5 s, said once."""
    (tmp_path / "five.yaml").write_text("indicators: {interval_s: 5}\n")
    (tmp_path / "odd.yaml").write_text("indicators: {interval_s: 5.005}\n")
    p = run_module("cmsensord", "--simulate", "--duration", "1", "--config", str(tmp_path / "odd.yaml"),
                   "--out", str(tmp_path / "rms"))
    assert p.returncode == 0, p.stderr
    assert "ISO 10816-3" not in p.stderr
    assert capped(p.stderr) == ["WARNING config: " + ROUNDED], p.stderr
    p = run_module("cmsensord", "--simulate", "--scenario", "healthy", "--mode", "raw", "--duration", "1",
                   "--config", str(tmp_path / "five.yaml"), "--out", str(tmp_path / "raw"))
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines()[0] == NOTE
    assert capped(p.stderr) == ["WARNING config: " + CAPPED]
    h = run_module("cmsensord", "--simulate", "--help")
    assert ("faulty              the same motor with unbalance/looseness (~8.3 mm/s velocity RMS: zone D above "
            "4.5 of the default ISO 10816-3 group 2, rigid) and an outer-race bearing defect") in h.stdout
