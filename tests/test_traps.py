"""The decision rule's silent traps are one-line warnings, through the commands a user types.

Each case builds a small capture (the simulator or `cmsensord import`), replays it
with `cmsensord replay` and asserts the exact line on stderr.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.io import wavfile

from processes import run_module


def replay(capture, tmp_path, *extra):
    p = run_module("cmsensord", "replay", str(capture), "--out", str(tmp_path / "logs"), *extra)
    assert p.returncode == 0, p.stderr
    return p.stderr.splitlines()


def imported(tmp_path, *options, seconds=5.0):
    """A 20480 Hz WAV of broadband vibration imported with ``options``."""
    wav, cap = tmp_path / "rig.wav", tmp_path / "rig.bin"
    x = 0.1 * np.random.default_rng(0).standard_normal(int(seconds * 20480)).astype(np.float32)
    wavfile.write(wav, 20480, x)
    p = run_module("cmsensord", "import", str(wav), "--unit", "g", *options, "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return cap


def test_a_recording_shorter_than_two_decisions_says_no_decision(tmp_path):
    cap = tmp_path / "short.bin"
    p = run_module("firmware_sim", "--scenario", "healthy", "--duration", "1.5", "--out", str(cap))
    assert p.returncode == 0, p.stderr
    lines = replay(cap, tmp_path)
    assert ("  ch0: no decision (the recording is shorter than two decision periods of 1 s; "
            "the first is the filters' transient)") in lines
    assert not any("final severity" in line for line in lines)


def test_a_board_rate_other_than_100_hz_is_said(tmp_path):
    lines = replay(imported(tmp_path, "--block-len", "256"), tmp_path)
    assert ("WARNING decision_rule: board block rate 80 blocks/s (fs 20480 / block 256), not 100: a "
            "decision is 80 observations (1 s); f_r 28.66 is 36% of them; the window N = 10 "
            "observations is 0.125 s") in lines


def test_a_board_rate_within_one_percent_of_100_hz_is_not_a_warning(tmp_path):
    """The default import of 20480 Hz (blocks of 205: 99.9 blocks/s) keeps the decision rule's
    counts within 0.1 % of the paper's times: no decision_rule warning."""
    lines = replay(imported(tmp_path), tmp_path)
    assert any(line.startswith("  ch0: final severity") for line in lines), lines
    assert not [line for line in lines if "decision_rule" in line], lines


def test_f_r_no_decision_can_reach_at_the_board_rate_is_said(tmp_path):
    cfg = tmp_path / "fr.yaml"
    cfg.write_text("monitor:\n  f_r: 90\n")
    lines = replay(imported(tmp_path, "--block-len", "256"), tmp_path, "--config", str(cfg))
    assert ("WARNING decision_rule: ch0: f_r 90 >= the 80 observations per decision at 80 blocks/s: "
            "no decision can flag an anomaly (set f_r below 80)") in lines


def test_a_tacho_faster_than_the_decision_size_falls_back_to_the_configured_f_r(tmp_path):
    lines = replay(imported(tmp_path, "--rpm", "7200"), tmp_path)
    assert ("WARNING decision_rule: ch0: tacho f_r 120 Hz >= the 100 observations per decision: "
            "using the configured f_r 28.66; for a machine this fast give a longer decision: monitor: "
            "{decision_period_s: 2} in --config (the tacho's f_r below 200 Hz, 12,000 rpm)") in lines


@pytest.fixture
def held_capture(tmp_path):
    """50 spikes a second for 5 s (the flags set), then 25 a second: c f_r <= 25 < f_r."""
    a, b = tmp_path / "a.bin", tmp_path / "b.bin"
    for path, rate, seconds, t0 in ((a, 50, 5, 0), (b, 25, 80, 125000)):
        p = run_module("firmware_sim", "--scenario", "spikes", "--param", f"spikes_per_s={rate}",
                       "--duration", str(seconds), "--t0-start", str(t0), "--seed", "1", "--out", str(path))
        assert p.returncode == 0, p.stderr
    both = tmp_path / "held.bin"
    both.write_bytes(a.read_bytes() + b.read_bytes())
    return both


def test_a_flag_held_by_the_hysteresis_alone_is_said(held_capture, tmp_path):
    lines = replay(held_capture, tmp_path)
    held = [line for line in lines if line.startswith("WARNING anomaly_held: ")]
    assert held and all(re.fullmatch(
        r"WARNING anomaly_held: ch0: AKF_\d+(, AKF_\d+)* anomaly flag held 60 decisions by the hysteresis "
        r"alone \(11\.5 <= outliers < f_r 28\.7\): it neither sets anew nor clears; if the machine is "
        r"healthy, commission it \(cmsensord calibrate\)", line) for line in held)
