"""Alarm rules that could never fire are refused, through the commands a user types: a rule on no
indicator (a misspelt name, a bearing or band not configured), levels in the wrong order or
negative; each a one-line configuration error (exit 78) of `cmsensord replay` and `cmsensord
calibrate`, before anything is read or written."""

from __future__ import annotations

from pathlib import Path

import pytest

from cmsensord.config import ConfigError, config_from_dict
from processes import cmsensord, run_module

ERROR = "cmsensord: configuration error: "


@pytest.fixture(scope="module")
def capture(tmp_path_factory) -> Path:
    """4 s of the degrading motor, RAW with a tacho."""
    work = tmp_path_factory.mktemp("rules_checked")
    p = run_module("firmware_sim", "--scenario", "degrading", "--mode", "raw", "--tacho", "--duration", "4",
                   "--out", str(work / "deg.bin"))
    assert p.returncode == 0, p.stderr
    return work / "deg.bin"


def refused(tmp_path: Path, capture: Path, rules: str, *, command: str = "replay") -> str:
    """The stderr of ``cmsensord COMMAND CAPTURE --config bad.yaml`` (alarms: {rules: RULES}),
    asserting exit 78 and that nothing was written."""
    (tmp_path / "bad.yaml").write_text(f"alarms:\n  rules: {rules}\n")
    out = "site.yaml" if command == "calibrate" else "logs"
    p = cmsensord(command, str(capture), "--config", "bad.yaml", "--out", out, cwd=tmp_path)
    assert p.returncode == 78, p.stderr
    assert not (tmp_path / out).exists()
    return p.stderr


def test_a_misspelt_indicator_is_refused_by_replay_and_calibrate(tmp_path, capture):
    rules = "[{name: v, indicator: velocity_rms, alert: 2.8}]"
    line = (ERROR + "bad.yaml: alarms.rules[0].indicator: unknown indicator (did you mean "
            "'velocity_rms_mm_s'?): a rule on it never fires (got 'velocity_rms')\n")
    assert refused(tmp_path, capture, rules) == line
    assert refused(tmp_path, capture, rules, command="calibrate") == line     # no site file with it


def test_a_bearing_line_of_no_configured_bearing_is_refused(tmp_path, capture):
    assert refused(tmp_path, capture, "[{name: de_outer, indicator: de.bpfo, alert: 1}]") == (
        ERROR + "bad.yaml: alarms.rules[0].indicator: names no bearing 'de' (bearings: none configured): "
        "add it under bearings (name, channel, geometry) or name one of them (got 'de.bpfo')\n")


BANDS = {"bands": [{"name": "low", "lo_hz": 10, "hi_hz": 100}]}
BEARING = {"name": "motor_de", "channel": "ch0", "elements": 9, "ball_diameter": 7.94, "pitch_diameter": 39.04}


@pytest.mark.parametrize("indicator, reason", [
    ("de.bpfo", "names no bearing 'de' (bearings: motor_de): add it under bearings (name, channel, geometry) "
     "or name one of them; did you mean 'motor_de.bpfo'?"),
    ("motor_de.bpfx", "'bpfx' is not a line of bearing motor_de (lines: ftf, ftf_2x, bpfo, bpfo_2x, bpfi, "
     "bpfi_2x, bsf, bsf_2x; each also as <line>_ratio); did you mean 'motor_de.bpfo'?"),
    ("band.high", "no band 'high' in indicators.bands (bands: low)"),
    ("order.whirl", "no component 'whirl' in orders.components (components: 1x, 2x, 3x, 4x)"),
    ("sevrity_index", "unknown indicator (did you mean 'severity_index'?): a rule on it never fires"),
])
def test_every_kind_of_indicator_name_is_checked(indicator, reason):
    with pytest.raises(ConfigError) as err:
        config_from_dict({"bearings": [BEARING], "indicators": BANDS,
                          "alarms": {"rules": [{"name": "r", "indicator": indicator, "alert": 1}]}}, source="m.yaml")
    assert str(err.value) == f"m.yaml: alarms.rules[0].indicator: {reason} (got {indicator!r})"


def test_the_level_indicator_of_the_operating_state_is_checked():
    with pytest.raises(ConfigError) as err:
        config_from_dict({"alarms": {"operating": {"source": "level", "running_above": 1,
                                                   "level_indicator": "accel"}}}, source="m.yaml")
    assert str(err.value) == ("m.yaml: alarms.operating.level_indicator: unknown indicator (did you mean "
                              "'accel_rms'?): the machine would never be seen running (got 'accel')")


def test_every_name_the_chain_writes_is_accepted():
    cfg = config_from_dict({"bearings": [BEARING], "indicators": BANDS,
                            "alarms": {"rules": [{"name": f"r{i}", "indicator": n, "alert": 1} for i, n in enumerate(
                                ["velocity_rms_mm_s", "accel_rms", "accel_peak", "crest_factor", "kurtosis",
                                 "envelope_rms", "zone", "motor_de.bpfi_2x", "band.low", "severity_index",
                                 "order.1x"])]}})
    assert len(cfg.alarms.rules) == 11


def test_levels_in_the_wrong_order_are_refused_by_replay_and_calibrate(tmp_path, capture):
    """alert 7.1 above danger 2.8: only the danger alarm would ever show, never the alert."""
    rules = "[{name: v, indicator: velocity_rms_mm_s, alert: 7.1, danger: 2.8}]"
    line = (ERROR + "bad.yaml: alarms.rules[0].danger: must be greater than alert = 7.1: the alert comes first "
            "(got 2.8)\n")
    assert refused(tmp_path, capture, rules) == line
    assert refused(tmp_path, capture, rules, command="calibrate") == line


@pytest.mark.parametrize("levels, expected", [
    ({"alert_zone": "D", "danger_zone": "C"},
     "danger_zone: must be a zone above alert_zone = D (zones A < B < C < D): the alert comes first (got 'C')"),
    ({"alert_zone": "C", "danger_zone": "C"},
     "danger_zone: must be a zone above alert_zone = C (zones A < B < C < D): the alert comes first (got 'C')"),
    ({"alert_x_baseline": 6, "danger_x_baseline": 3},
     "danger_x_baseline: must be greater than alert_x_baseline = 6.0: the alert comes first (got 3.0)"),
    ({"alert": 2.8, "danger": 2.8}, "danger: must be greater than alert = 2.8: the alert comes first (got 2.8)"),
    ({"alert": -1}, "alert: must be >= 0 (got -1)"),
    ({"danger": -0.5}, "danger: must be >= 0 (got -0.5)"),
    ({"alert": 5, "danger_zone": "C"}, "danger_zone: must be above the alert level: alert 5.0 against danger_zone C "
     "(zone C begins at 2.8 mm/s for machine group 2, rigid): the alert comes first (got 'C')"),
    ({"alert_zone": "D", "danger": 3}, "danger: must be above the alert level: alert_zone D against danger 3.0 "
     "(zone D begins at 4.5 mm/s for machine group 2, rigid): the alert comes first (got 3.0)"),
    ({"alert": 1, "bands": [{"below_rpm": 1000, "alert": 5, "danger": 2}]},
     "bands[0].danger: must be greater than alert = 5.0: the alert comes first (got 2.0)"),
    ({"alert": 1, "bands": [{"below_rpm": 1000, "alert": -5}]}, "bands[0].alert: must be >= 0 (got -5)"),
    ({"alert": 1, "bands": [{"below_rpm": 1000, "alert_zone": "D", "danger": 4}]},
     "bands[0].danger: must be above the alert level: alert_zone D against danger 4.0 (zone D begins at 4.5 "
     "mm/s for machine group 2, rigid): the alert comes first (got 4.0)"),
])
def test_every_level_pair_must_rise_and_no_level_is_negative(levels, expected):
    with pytest.raises(ConfigError) as err:
        config_from_dict({"alarms": {"rules": [{"name": "v", "indicator": "velocity_rms_mm_s", **levels}]}},
                         source="m.yaml")
    assert str(err.value) == "m.yaml: alarms.rules[0]." + expected


def test_rising_levels_given_in_different_ways_are_accepted():
    cfg = config_from_dict({"alarms": {"rules": [
        {"name": "a", "indicator": "velocity_rms_mm_s", "alert": 2.0, "danger_zone": "C"},
        {"name": "b", "indicator": "velocity_rms_mm_s", "alert_zone": "C", "danger": 9.5},
        {"name": "c", "indicator": "velocity_rms_mm_s", "alert_x_baseline": 2, "danger": 9.5},
        {"name": "d", "indicator": "kurtosis", "alert": 0, "bands": [{"below_rpm": 600, "danger": 8}]}]}})
    assert [r.name for r in cfg.alarms.rules] == ["a", "b", "c", "d"]


def test_a_baseline_level_without_a_baseline_is_said_once_per_rule_and_channel(tmp_path, capture):
    """alert_x_baseline with no alarms.baselines: accepted (calibrate's base configuration learns
    them), but replay says once, with an event and a warning line, that the level is not in force."""
    (tmp_path / "base.yaml").write_text(
        "output: {status_line: false}\nalarms:\n  rules:\n"
        "    - {name: vel, indicator: velocity_rms_mm_s, alert_x_baseline: 2, danger: 9.5}\n")
    p = cmsensord("replay", str(capture), "--config", "base.yaml", "--out", "logs", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    said = [ln for ln in p.stderr.splitlines() if ln.startswith("WARNING alarm_no_baseline")]
    assert said == ["WARNING alarm_no_baseline: rule vel on ch0: no baseline of velocity_rms_mm_s learned for ch0 "
                    "(alarms.baselines), so its alert_x_baseline level(s) are not in force there: run cmsensord "
                    "calibrate on a healthy capture of this machine"]
    from cmsensord.sinks.mcap_sink import read_messages
    events = [m for t, _, m in read_messages(next((tmp_path / "logs").glob("*.mcap")))
              if t == "/cm/events" and m["kind"] == "alarm_no_baseline"]
    assert [(m["channel"], m["alarm"]) for m in events] == [("ch0", "vel/ch0")]
    p = cmsensord("calibrate", str(capture), "--config", "base.yaml", "--out", "site.yaml", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    p = cmsensord("replay", str(capture), "--config", "site.yaml", "--out", "logs2", cwd=tmp_path)
    assert p.returncode == 0 and "alarm_no_baseline" not in p.stderr, p.stderr
