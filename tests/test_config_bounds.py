"""Settings whose values would hang, exhaust memory or crash the run are refused on loading,
with one line and exit 78, by the command a user types (``cmsensord replay --config``,
``cmsensord calibrate``); within the bounds the run goes through.

Each bound and why: ``capture.every_s`` at least one sample at the board's 25 kHz and at most
a year (a shorter one at a slower stream ticks once a sample, said by a ``config`` event);
``monitor.decision_period_s`` at most an hour (its buffers grow with it) and calibrate's
advice within it; ``tacho.timeout_s`` at most the tracker's longest run timeout; the order
tracker's least order, frequency, bandwidth and min_rpm, the range of r and q1 (beyond, its
design overflows in float64), and at most 32 components (its cost
grows with about their cube); ``output.prefix`` short enough for the log's file names; a
channel's ``scale`` and ``offset`` within what float32 carries through the RMS; each channel
once in an alarm rule and each baseline once; a partly filled ``commissioned`` section
compared and said as far as it goes.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from cmsensord.config import config_from_dict
from cmsensord.errors import EXIT_CONFIG
from cmsensord.sinks.mcap_read import read_messages
from processes import cmsensord, run_module


@pytest.fixture(scope="module")
def rms_cap(tmp_path_factory) -> Path:
    cap = tmp_path_factory.mktemp("bounds") / "rms.bin"
    p = run_module("firmware_sim", "--scenario", "faulty", "--duration", "3", "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return cap


def _refused(tmp_path: Path, text: str) -> str:
    """``cmsensord replay --config`` of ``text``: exit 78 and one line on stderr, returned
    without the ``cmsensord: configuration error: FILE: `` head."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(text)
    run = cmsensord("replay", "--config", str(cfg), str(tmp_path / "none.bin"), timeout=30, cwd=tmp_path)
    assert run.returncode == EXIT_CONFIG, run.stderr
    assert run.stderr.count("\n") == 1 and "Traceback" not in run.stderr, run.stderr
    head = f"cmsensord: configuration error: {cfg}: "
    assert run.stderr.startswith(head), run.stderr
    return run.stderr.strip()[len(head):]


_PREFIX = "p" * 240
_COMPONENTS = "".join(f"    - {{name: o{i}, order: {1 + i * 0.01:.2f}}}\n" for i in range(33))


@pytest.mark.parametrize("text, message", [
    ("capture:\n  every_s: 1.0e-5\n",
     "capture.every_s: must be 0 (none) or from 4e-05 s (one sample at the board's 25000 Hz) to 31,536,000 s (a "
     "year) (got 1e-05)"),
    ("capture:\n  every_s: 1.0e+308\n", "capture.every_s: must be 0 (none) or from 4e-05 s (one sample at the "
     "board's 25000 Hz) to 31,536,000 s (a year) (got 1e+308)"),
    ("monitor:\n  decision_period_s: 1.0e+9\n",
     "monitor.decision_period_s: must be > 0 and <= 3600 (got 1000000000.0)"),
    ("monitor:\n  decision_period_s: 1.0e+308\n", "monitor.decision_period_s: must be > 0 and <= 3600 (got 1e+308)"),
    ("channels:\n  - {name: de, decision_period_s: 100000}\n",
     "channels[0].decision_period_s: must be > 0 and <= 3600 (got 100000)"),
    ("monitor:\n  f_r: 1.0e+9\n",
     "monitor.f_r: must be below the 100 observations per decision (decision_period_s 1 x 100 blocks/s): at or "
     "above it no decision can flag an anomaly; no decision_period_s up to 3600 fits a machine this fast: f_r "
     "must be below 360000 Hz (got 1000000000.0)"),
    ("tacho:\n  timeout_s: 11\n", "tacho.timeout_s: must be > 0 and <= 10 (got 11)"),
    ("orders: {min_rpm: 5.0e-324}\n", "orders.min_rpm: must be >= 1.0 (got 5e-324)"),
    ("orders: {bandwidth_pct: 5.0e-324}\n", "orders.bandwidth_pct: must be >= 0.01 and <= 100 (got 5e-324)"),
    ("orders: {components: [{name: a, order: 5.0e-324}]}\n",
     "orders.components[0].order: must be >= 0.01 (got 5e-324)"),
    ("orders: {components: [{name: a, freq_hz: 5.0e-324}]}\n",
     "orders.components[0].freq_hz: must be >= 0.01 (got 5e-324)"),
    ("orders: {components: [{name: a, order: 1, bandwidth_pct: 5.0e-324}]}\n",
     "orders.components[0].bandwidth_pct: must be >= 0.01 and <= 100 (got 5e-324)"),
    ("orders: {components: [{name: a, order: 1, r: 5.0e-324}]}\n",
     "orders.components[0].r: must be >= 1e-06 and <= 1000000000000.0 (got 5e-324)"),
    ("orders: {components: [{name: a, order: 1, r: 1.0e+300}]}\n",
     "orders.components[0].r: must be >= 1e-06 and <= 1000000000000.0 (got 1e+300)"),
    ("orders: {components: [{name: a, order: 1, bandwidth_hz: 5.0e-324}]}\n",
     "orders.components[0].bandwidth_hz: must be >= 0.001 (got 5e-324)"),
    ("orders: {q1: 5.0e-324}\n", "orders.q1: must be >= 1e-12 and <= 1000000000000.0 (got 5e-324)"),
    ("orders: {q1: 1.0e+300}\n", "orders.q1: must be >= 1e-12 and <= 1000000000000.0 (got 1e+300)"),
    ("orders:\n  components:\n" + _COMPONENTS,
     "orders.components: at most 32 components: the tracker's cost grows with about the cube of their count, "
     "and more fall behind real time (got 33)"),
    (f'output:\n  prefix: "{_PREFIX}"\n',
     "output.prefix: must be at most 128 characters (240 given): the log file names add up to 54 more, and a "
     f"file name holds at most 255 bytes (got '{_PREFIX[:56]}...)"),
    ("channels:\n  - {name: de, scale: 1.0e+39}\n",
     "channels[0].scale: must be between 1e-09 and 1e+06 (or -1e+06 and -1e-09) per ADC count (got 1e+39)"),
    ("channels:\n  - {name: de, scale: -1.0e-50}\n",
     "channels[0].scale: must be between 1e-09 and 1e+06 (or -1e+06 and -1e-09) per ADC count (got -1e-50)"),
    ("channels:\n  - {name: de, offset: 1.0e+39}\n",
     "channels[0].offset: must be between -1e+06 and 1e+06 ADC counts (got 1e+39)"),
    ("alarms:\n  rules:\n    - {name: r, indicator: accel_rms, alert: 1, channels: [ch0, ch0], vote: 2}\n",
     "alarms.rules[0].channels[1]: duplicate channel (also channels[0]): a rule watches each channel once "
     "(got 'ch0')"),
    ("alarms:\n  baselines:\n    - {channel: ch0, indicator: accel_rms, value: 2}\n"
     "    - {channel: ch0, indicator: kurtosis, value: 3}\n    - {channel: ch0, indicator: accel_rms, value: 1}\n",
     "alarms.baselines[2]: duplicate baseline of accel_rms on ch0 (also baselines[0]) (got 1.0)"),
], ids=["every_s-below-a-sample", "every_s-overflows", "decision-1e9", "decision-1e308", "channel-decision",
        "f_r-beyond-any-decision", "tacho-timeout", "min_rpm-denormal", "bandwidth_pct-denormal",
        "order-denormal", "freq_hz-denormal", "component-bandwidth_pct-denormal", "r-denormal", "r-1e300",
        "bandwidth_hz-denormal", "q1-denormal", "q1-1e300", "33-components",
        "prefix-240", "scale-beyond-float32", "scale-below-float32", "offset-beyond-float32",
        "rule-repeats-a-channel", "baseline-twice"])
def test_a_value_out_of_bounds_is_one_line_config_error(tmp_path, text, message):
    assert _refused(tmp_path, text) == message


def test_the_bounds_themselves_load():
    cfg = config_from_dict({
        "capture": {"every_s": 1 / 25000}, "monitor": {"decision_period_s": 3600}, "tacho": {"timeout_s": 10},
        "output": {"prefix": "p" * 128},
        "channels": [{"name": "de", "scale": -1e6, "offset": 1e6}, {"name": "nde", "scale": 1e-9, "offset": -1e6}],
        "orders": {"min_rpm": 1, "bandwidth_pct": 0.01, "q1": 1e-12,
                   "components": [{"name": f"o{i}", "order": 0.01 + i} for i in range(29)]
                   + [{"name": "f", "freq_hz": 0.01, "bandwidth_pct": 0.01}, {"name": "r", "order": 1, "r": 1e12},
                      {"name": "b", "order": 2, "bandwidth_hz": 0.001}]}})
    assert len(cfg.orders.components) == 32 and cfg.tacho.timeout_s == 10


def test_calibrate_refuses_a_speed_no_decision_period_fits(rms_cap, tmp_path):
    p = cmsensord("calibrate", str(rms_cap), "--rpm", "1e9", "--out", str(tmp_path / "site.yaml"), timeout=60)
    assert p.returncode == EXIT_CONFIG and not (tmp_path / "site.yaml").exists(), p.stderr
    assert p.stderr == (
        "cmsensord: configuration error: calibrate: ch0.f_r: 1.667e+07 Hz must be below the 100 observations per "
        "decision (100 blocks/s x decision_period_s 1); no decision_period_s up to 3600 fits a machine this fast "
        "(f_r below 360000 Hz, 2.16e+07 rpm)\n")


def test_calibrate_advises_a_decision_period_within_the_bound(rms_cap, tmp_path):
    p = cmsensord("calibrate", str(rms_cap), "--rpm", "2e7", "--out", str(tmp_path / "site.yaml"), timeout=60)
    assert p.returncode == EXIT_CONFIG, p.stderr
    assert p.stderr.endswith("monitor: {decision_period_s: 3334} in --config BASE.yaml\n"), p.stderr


def test_every_s_shorter_than_an_observation_ticks_once_an_observation(rms_cap, tmp_path):
    """RMS mode at 100 observations a second: every_s 0.004 is no step of the stream; the replay
    ticks every observation (said once) and ends, its captures written."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text("capture:\n  every_s: 0.004\n  pre_s: 0.5\n  post_s: 0.5\n  min_interval_s: 1\n")
    p = cmsensord("replay", str(rms_cap), "--config", str(cfg), "--out", str(tmp_path / "logs"), timeout=10)
    assert p.returncode == 0, p.stderr
    (log,) = (tmp_path / "logs").glob("*.mcap")
    msgs = read_messages(log)
    said = [m["message"] for t, _, m in msgs if t == "/cm/events" and m["kind"] == "config"
            and "every_s" in m["message"]]
    assert said == ["capture.every_s 0.004 is shorter than one sample of the RMS stream (0.01 s): a periodic "
                    "tick every sample"]
    waves = [m for t, _, m in msgs if t == "/cm/ch0/capture_waveform"]
    assert waves and all(w["trigger"]["kind"] == "periodic" for w in waves)


def _learned_said(rms_cap: Path, tmp_path: Path, commissioned: str) -> list[str]:
    cfg = tmp_path / "c.yaml"
    cfg.write_text("commissioned:\n  capture: site.bin\n" + commissioned)
    p = cmsensord("replay", str(rms_cap), "--config", str(cfg), "--out", str(tmp_path / "logs"), timeout=60)
    assert p.returncode == 0, p.stderr
    return [ln for ln in p.stderr.splitlines() if "baselines were learned from" in ln]


@pytest.mark.parametrize("commissioned, learned, sends", [
    ("  fs_hz: 20000\n", "fs 20000 Hz", "fs 25000 Hz"),
    ("  block_len: 200\n", "block 200", "block 250"),
    ("  fs_hz: 25000\n  block_len: 200\n", "fs 25000 Hz, block 200", "fs 25000 Hz, block 250"),
], ids=["fs-only", "block-only", "both-block-differs"])
def test_a_partly_filled_commissioned_section_is_compared_as_far_as_it_goes(rms_cap, tmp_path, commissioned,
                                                                            learned, sends):
    assert _learned_said(rms_cap, tmp_path, commissioned) == [
        f"WARNING config: the baselines were learned from site.bin at {learned}; this board sends {sends}: they "
        "and the alarm levels on them may not fit it (cmsensord calibrate on this machine's healthy period)"]


@pytest.mark.parametrize("commissioned", ["  fs_hz: 25000\n", "  block_len: 250\n"], ids=["fs", "block"])
def test_a_partly_filled_commissioned_section_that_fits_says_nothing(rms_cap, tmp_path, commissioned):
    assert _learned_said(rms_cap, tmp_path, commissioned) == []
