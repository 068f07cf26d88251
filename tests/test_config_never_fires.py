"""Settings under which an alarm or a capture trigger could never fire, through the commands a user
types: a learned baseline that is no number or of no indicator a rule could watch, a rule on the
indicator records or the orders turned off, a level above what its indicator reaches and an
``anomaly_akf`` past the bank are each a one-line configuration error (exit 78) of `cmsensord
replay`; rules an RMS-mode board leaves blind are one warning; `cmsensord ack` given both an alarm
and --all says so."""

from __future__ import annotations

from pathlib import Path

import pytest

from processes import cmsensord, run_module

ERROR = "cmsensord: configuration error: "


@pytest.fixture(scope="module")
def captures(tmp_path_factory) -> dict[str, Path]:
    """4 s of the healthy motor: RAW with a tacho, and RMS."""
    work = tmp_path_factory.mktemp("never_fires")
    out = {}
    for mode in ("raw", "rms"):
        out[mode] = work / f"{mode}.bin"
        extra = ("--tacho",) if mode == "raw" else ()
        p = run_module("firmware_sim", "--scenario", "healthy", "--mode", mode, *extra, "--duration", "4",
                       "--out", str(out[mode]))
        assert p.returncode == 0, p.stderr
    return out


def replay(tmp_path: Path, capture: Path, config: str):
    (tmp_path / "b.yaml").write_text("output: {status_line: false}\n" + config)
    return cmsensord("replay", str(capture), "--config", "b.yaml", "--out", "logs", cwd=tmp_path)


def refused(tmp_path: Path, capture: Path, config: str) -> str:
    """The one line of a replay refusing ``config`` (exit 78, nothing written)."""
    p = replay(tmp_path, capture, config)
    assert p.returncode == 78 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
    assert not (tmp_path / "logs").exists()
    return p.stderr.rstrip("\n")


BASELINE_RULE = "alarms:\n  rules: [{name: r, indicator: accel_rms, alert_x_baseline: 2}]\n"


@pytest.mark.parametrize("value, reason", [
    ('"0.5"', "value: expected a number (got '0.5')"),
    ("-1", "value: must be >= 0 (got -1)"),
    (".nan", "value: expected a finite number (got nan)"),
])
def test_a_baseline_that_is_no_number_is_refused(tmp_path, captures, value, reason):
    """Guards against a string baseline accepted and a TypeError traceback at the first indicator record."""
    line = refused(tmp_path, captures["raw"], BASELINE_RULE + f"  baselines: [{{channel: ch0, indicator: accel_rms, "
                   f"value: {value}}}]\n")
    assert line == ERROR + "b.yaml: alarms.baselines[0]." + reason


@pytest.mark.parametrize("indicator, reason", [
    ("acel_rms", "unknown indicator (did you mean 'accel_rms'?): no rule can use this baseline"),
    ("band.low", "no band 'low' in indicators.bands (bands: none configured)"),
])
def test_a_baseline_of_no_indicator_a_rule_could_watch_is_refused(tmp_path, captures, indicator, reason):
    line = refused(tmp_path, captures["raw"], BASELINE_RULE + f"  baselines: [{{channel: ch0, indicator: {indicator}, "
                   "value: 0.5}]\n")
    assert line == ERROR + f"b.yaml: alarms.baselines[0].indicator: {reason} (got {indicator!r})"


@pytest.mark.parametrize("config, reason, got", [
    ("indicators: {enabled: false}\nalarms: {rules: [{name: r, indicator: accel_rms, alert: 1}]}\n",
     "alarms.rules[0].indicator: indicators.enabled is false: no indicator record is written, a rule on it never "
     "fires", "'accel_rms'"),
    ("indicators: {enabled: false}\nalarms: {rules: [{name: r, indicator: kurtosis, alert: 5}]}\n",
     "alarms.rules[0].indicator: indicators.enabled is false: no indicator record is written, a rule on it never "
     "fires", "'kurtosis'"),
    ("orders: {enabled: false}\nalarms: {rules: [{name: r, indicator: order.1x, alert: 1}]}\n",
     "alarms.rules[0].indicator: orders.enabled is false: no order is tracked, a rule on it never fires",
     "'order.1x'"),
    ("orders: {enabled: false, components: [{name: 1x, order: 1, alarm_rms: 0.5}]}\n",
     "orders.components[0].alarm_rms: orders.enabled is false: no order is tracked, this order alarm never fires",
     "0.5"),
    ("indicators: {enabled: false}\nalarms: {operating: {source: speed, running_above: 600}}\n",
     "alarms.operating.source: the shaft speed comes with the indicator records, and indicators.enabled is false: "
     "the machine would never be seen running", "'speed'"),
])
def test_a_rule_on_what_the_configuration_turns_off_is_refused(tmp_path, captures, config, reason, got):
    """Guards against such a rule accepted without a word and never firing."""
    assert refused(tmp_path, captures["raw"], config) == ERROR + f"b.yaml: {reason} (got {got})"


def test_the_severity_index_and_the_zone_without_those_rules_are_accepted(tmp_path, captures):
    p = replay(tmp_path, captures["raw"], "indicators: {enabled: false}\norders: {enabled: false}\n"
               "alarms: {rules: [{name: s, indicator: severity_index, alert: 0.5}]}\n")
    assert p.returncode == 0, p.stderr


@pytest.mark.parametrize("rule, reason", [
    ("{name: s, indicator: severity_index, alert: 1.5}",
     "alert: must be <= 1 (the severity index is 0 to 1): a level above it is never reached (got 1.5)"),
    ("{name: z, indicator: zone, alert: 7}",
     "alert: must be <= 3 (zone is 0-3 for zones A-D): a level above it is never reached (got 7.0)"),
    ("{name: z, indicator: zone, alert: 2, bands: [{below_rpm: 600, danger: 4}]}",
     "bands[0].danger: must be <= 3 (zone is 0-3 for zones A-D): a level above it is never reached (got 4.0)"),
])
def test_a_level_above_what_the_indicator_reaches_is_refused(tmp_path, captures, rule, reason):
    line = refused(tmp_path, captures["raw"], f"alarms: {{rules: [{rule}]}}\n")
    assert line == ERROR + "b.yaml: alarms.rules[0]." + reason


def test_the_top_levels_themselves_are_accepted(tmp_path, captures):
    p = replay(tmp_path, captures["raw"], "alarms: {rules: [{name: s, indicator: severity_index, alert: 0.5, "
               "danger: 1}, {name: z, indicator: zone, alert: 2, danger: 3}]}\n")
    assert p.returncode == 0, p.stderr


def test_an_anomaly_akf_past_the_bank_is_refused(tmp_path, captures):
    """Guards against anomaly_akf: 11 of a bank of 10 accepted, a trigger that never fires."""
    capture = "capture: {triggers: [anomaly_onset], anomaly_akf: 11}\n"
    assert refused(tmp_path, captures["raw"], capture) == ERROR + (
        "b.yaml: capture.anomaly_akf: must be <= monitor.n = 10: the bank has no AKF_11, so the anomaly_onset "
        "trigger never fires (got 11)")
    small = "monitor: {n: 4}\ncapture: {triggers: [anomaly_onset], anomaly_akf: 5}\n"
    assert refused(tmp_path, captures["raw"], small) == ERROR + (
        "b.yaml: capture.anomaly_akf: must be <= monitor.n = 4: the bank has no AKF_5, so the anomaly_onset "
        "trigger never fires (got 5)")
    p = replay(tmp_path, captures["raw"], "capture: {triggers: [anomaly_onset], anomaly_akf: 10}\n")
    assert p.returncode == 0, p.stderr


RMS_RULES = """\
bearings: [{name: de, channel: ch0, elements: 8, ball_diameter: 17.462, pitch_diameter: 72.5}]
orders: {components: [{name: 1x, order: 1, alarm_rms: 1}]}
alarms:
  rules:
    - {name: k, indicator: kurtosis, alert: 5}
    - {name: a, indicator: accel_rms, alert: 5}
    - {name: s, indicator: severity_index, alert: 0.5}
    - {name: o, indicator: de.bpfo, alert: 5}
"""
RMS_WARNING = ("WARNING config: the board is in RMS mode, whose indicator records carry accel_rms only and no shaft "
               "speed (RAW mode gives the rest): alarm rule(s) k (kurtosis), o (de.bpfo), order_1x (order.1x) never "
               "fire")


def test_rules_an_rms_mode_board_leaves_blind_are_one_warning(tmp_path, captures):
    """Guards against rules on indicators the RMS path does not give never evaluated, and nothing said."""
    p = replay(tmp_path, captures["rms"], RMS_RULES)
    assert p.returncode == 0, p.stderr
    assert [ln for ln in p.stderr.splitlines() if ln.startswith("WARNING config")] == [RMS_WARNING]
    p = replay(tmp_path, captures["raw"], RMS_RULES)                      # a RAW board gives them all
    assert p.returncode == 0 and "WARNING config" not in p.stderr, p.stderr
    p = replay(tmp_path, captures["rms"], "alarms: {operating: {source: speed, running_above: 600}, rules: "
               "[{name: a, indicator: accel_rms, alert: 5}]}\n")
    assert [ln for ln in p.stderr.splitlines() if ln.startswith("WARNING config")] == [
        "WARNING config: the board is in RMS mode, whose indicator records carry accel_rms only and no shaft speed "
        "(RAW mode gives the rest): alarms.operating.source speed gets no shaft speed: the machine is never seen "
        "running, no rule fires"]


def test_ack_given_a_name_and_all_says_not_both(tmp_path):
    p = run_module("cmsensord", "ack", "--all", "lat/ch0", "--socket", str(tmp_path / "none.sock"))
    assert (p.returncode, p.stdout, p.stderr) == (
        2, "", "cmsensord: ack: give an alarm name or --all, not both (see cmsensord ack --help)\n")
    p = run_module("cmsensord", "ack", "--socket", str(tmp_path / "none.sock"))
    assert (p.returncode, p.stderr) == (2, "cmsensord: ack: give an alarm name or --all (see cmsensord ack --help)\n")
