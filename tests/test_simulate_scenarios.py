"""Every scenario of `cmsensord --simulate --help`, run as a new user types it.

Each runs with its own defaults (channels, mode, speed, the microphone as `kind: microphone`
with a calibration made from the simulator) and loses no frame: the board waits for a reader
that falls behind (flow control on the pty) instead of dropping bytes.  Briefly: only
``--duration`` is given, so the shape of a scenario is squeezed but its pace is the default.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from cmsensord.service.simulate import scenario_run
from cmsensord.sinks.mcap_sink import read_messages
from firmware_sim.scenarios import SCENARIOS
from processes import ENV, cmsensord

#: seconds of each brief run: the run-ups whole (close_orders: 5 s at 1x), the others 40 s
BRIEF = {"close_orders": 5.0}


@pytest.fixture(scope="module")
def cache_env(tmp_path_factory):
    """A private cache directory: the microphone scenarios make their calibration there once."""
    return dict(ENV, XDG_CACHE_HOME=str(tmp_path_factory.mktemp("cache")))


def run_scenario(tmp_path, env, scenario, *args, timeout=300):
    out = tmp_path / "out"
    p = cmsensord("--simulate", "--scenario", scenario, "--out", str(out), *args, env=env, timeout=timeout)
    assert p.returncode == 0, p.stderr
    (path,) = sorted(out.glob("*.mcap"))
    return p, read_messages(path)


def test_help_lists_every_scenario_with_its_defaults():
    p = cmsensord("--simulate", "--help")
    for name in SCENARIOS:
        run = scenario_run(name)
        assert re.search(rf"^  {name} ", p.stdout, re.M), name
        assert f"(defaults: {run.duration_s:g} s at {run.speed:g}x, {run.channels} channel(s)" in p.stdout
    assert "(defaults: 5 s at 1x, 1 channel(s), RAW)" in p.stdout            # close_orders


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_every_scenario_runs_with_its_defaults_and_loses_no_frame(tmp_path, cache_env, scenario):
    seconds = BRIEF.get(scenario, 40.0)
    args = [] if scenario in BRIEF else ["--duration", f"{seconds:g}"]
    p, msgs = run_scenario(tmp_path, cache_env, scenario, *args)
    run = scenario_run(scenario)
    assert f"{run.channels} channel(s)" in p.stderr and f"{run.mode.upper()} mode" in p.stderr
    assert re.search(r"\(\d+ observations, 0 missing, 0 frames lost\)", p.stderr), p.stderr[-2000:]
    kinds = [m["kind"] for t, _, m in msgs if t == "/cm/events"]
    assert "frames_lost" not in kinds and "queue_overflow" not in kinds
    assert "tacho_extra_pulse" not in kinds and "decode_error" not in kinds
    diag = [m for t, _, m in msgs if t == "/cm/diagnostics"]
    assert diag[-1]["link"]["frames_lost"] == 0 and diag[-1]["link"]["crc_failures"] == 0
    assert diag[-1]["queue_drops"] == 0
    for ch in range(run.channels):
        sev = [m for t, _, m in msgs if t == f"/cm/ch{ch}/severity"]
        assert len(sev) >= seconds - 3
    for ch in run.microphones:
        est = [m for t, _, m in msgs if t == f"/cm/ch{ch}/vibration_estimate"]
        assert len(est) >= 100 * (seconds - 1)


def test_degrading_mic_with_no_flag_follows_the_accelerometer(tmp_path, cache_env):
    """The bare command, `cmsensord --simulate --scenario degrading_mic`, nothing else: two
    channels, the microphone's vibration estimate on its own AKF bank, its level within one
    of the accelerometer's in >= 70 % of the 600 decisions (measured 0.72), 0 through the
    healthy part and a failure in the worst part, as the accelerometer."""
    p, msgs = run_scenario(tmp_path, cache_env, "degrading_mic")
    assert "acoustic calibration of the simulated motor:" in p.stderr
    acc = np.array([m["level"] for t, _, m in msgs if t == "/cm/ch0/severity"])
    mic = np.array([m["level"] for t, _, m in msgs if t == "/cm/ch1/severity"])
    assert acc.size == mic.size == 600
    assert np.mean(np.abs(acc - mic) <= 1) >= 0.70
    assert mic[:250].max() == 0 and acc[:250].max() == 0
    assert mic[400:480].max() == 10 and acc[400:480].max() == 10
    assert sum(1 for t, _, _ in msgs if t == "/cm/ch1/vibration_estimate") == 60000


def test_whirl_past_the_decision_size_names_the_longer_decision_that_takes_it(tmp_path, cache_env):
    """`cmsensord --simulate --scenario whirl`: the run-up's tacho passes 100 Hz, the 100
    observations of a 1-s decision; the warning names the decision_period_s that takes it.  A
    --config of that line alone (no orders of its own) keeps the scenario's orders, whirl alarm
    included, and nothing is warned of."""
    p, _ = run_scenario(tmp_path, cache_env, "whirl", "--speed", "30")
    # the f_r said is the first record's past 100 Hz: 100.1 Hz, a step later when a loaded machine's
    # queue overflowed (a queue_overflow event) and that record was not read
    said = [ln for ln in p.stderr.splitlines() if ln.startswith("WARNING decision_rule: ")]
    assert len(said) == 1 and re.fullmatch(
        r"WARNING decision_rule: ch0: tacho f_r 10[01]\.\d Hz >= the 100 observations per decision: using the "
        r"configured f_r 28\.66; for a machine this fast give a longer decision: monitor: \{decision_period_s: 2\} "
        r"in --config \(the tacho's f_r below 200 Hz, 12,000 rpm\)", said[0]), said
    assert "tacho f_r 100.1 Hz" in said[0] or "queue_overflow" in p.stderr, p.stderr[-2000:]
    cfg = tmp_path / "longer.yaml"
    cfg.write_text("monitor: {decision_period_s: 2}\n")
    p, msgs = run_scenario(tmp_path / "longer", cache_env, "whirl", "--speed", "30", "--config", str(cfg))
    assert "decision_rule" not in p.stderr
    assert [m["name"] for m in next(m for t, _, m in msgs if t == "/cm/ch0/orders")["orders"]] == [
        "o1", "whirl", "whip"]
    assert ("WARNING alarm_alert: order_whirl/ch0: order.whirl 1.456 m/s² (order whirl RMS) reached the alert "
            "level 0.7 m/s²\n") in p.stderr


def test_making_the_acoustic_calibration_is_said_before_it_starts(tmp_path):
    """With no calibration cached, the first microphone run says it is making one, from what and
    roughly how long it takes, before the seconds it takes (then how long it took, and where it
    is kept); the next run takes the cached file, in one line."""
    env = dict(ENV, XDG_CACHE_HOME=str(tmp_path / "cache"))
    p, _ = run_scenario(tmp_path / "first", env, "degrading_mic", "--duration", "5")
    said = [ln for ln in p.stderr.splitlines() if ln.startswith("acoustic calibration of the simulated motor: ")]
    (path,) = (tmp_path / "cache" / "cmsensord").glob("acoustic-simulated-motor-*.json")
    assert said[0] == (
        "acoustic calibration of the simulated motor: none cached yet: making it once (about 4-30 s, longer on a "
        "small board) from 300 s of degrading_mic (seed 1000) and 60 s of its background (seed 1001), as python -m "
        "cmsensord.acoustic_calib does"), p.stderr
    assert len(said) == 2 and re.fullmatch(
        rf"acoustic calibration of the simulated motor: made in \d+\.\d s; kept in {re.escape(str(path))}",
        said[1]), p.stderr
    p, _ = run_scenario(tmp_path / "again", env, "degrading_mic", "--duration", "5")
    assert [ln for ln in p.stderr.splitlines() if ln.startswith("acoustic calibration of the simulated motor: ")] == [
        f"acoustic calibration of the simulated motor: {path} (cached)"]


def test_a_config_whose_channel_kind_does_not_fit_the_board_is_one_line(tmp_path, cache_env):
    """degrading_mic sends pascals on channel 1: a configuration taking it as an
    accelerometer is a configuration error (exit 78) naming the key, before anything runs."""
    cfg = tmp_path / "two.yaml"
    cfg.write_text("channels:\n  - name: acc\n  - name: mic\n")
    p = cmsensord("--simulate", "--scenario", "degrading_mic", "--config", str(cfg), "--out",
                  str(tmp_path / "out"), env=cache_env)
    assert p.returncode == 78
    assert p.stderr.strip().splitlines() == [
        f"cmsensord: configuration error: {cfg}: channels[1].kind: the simulated board (degrading_mic) "
        "sends Pa (a microphone) on channel 1, which a channel of kind accelerometer cannot take "
        "(got 'accelerometer')"]


def test_a_microphone_channel_without_calibration_is_one_line(tmp_path, cache_env):
    cfg = tmp_path / "mic.yaml"
    cfg.write_text("channels:\n  - name: acc\n  - name: mic\n    kind: microphone\n")
    p = cmsensord("--simulate", "--scenario", "degrading_mic", "--config", str(cfg), "--out",
                  str(tmp_path / "out"), env=cache_env)
    assert p.returncode == 78
    assert p.stderr.strip().splitlines() == [
        f"cmsensord: configuration error: {cfg}: channels[1].kind: a microphone channel needs an "
        "acoustic calibration file (acoustic.calibration or channels[1].calibration) (got 'microphone')"]


def test_too_few_channels_for_the_microphone_is_a_usage_error(tmp_path, cache_env):
    p = cmsensord("--simulate", "--scenario", "healthy_mic", "--channels", "1", "--out",
                  str(tmp_path / "out"), env=cache_env)
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [
        "cmsensord: --channels: healthy_mic sends its microphone on channel 1: give at least 2 "
        "channels (got 1)"]
