"""The alarm manager on scripted inputs: delays, deadband, latching and acknowledgement,
start-up and coast-down suppression, speed bands, ISO zone and baseline levels, N-of-M voting,
and the config section's one-line errors."""

from __future__ import annotations

import pytest

from cmsensord.alarms import AlarmManager
from cmsensord.alarms.state import AlarmState
from cmsensord.config import ConfigError, config_from_dict

S = 1_000_000_000
ZONES = (1.4, 2.8, 4.5)         # ISO 10816-3 group 2, rigid


def manager(rules: list[dict], operating: dict | None = None, baselines: list[dict] | None = None,
            channels: tuple[str, ...] = ("ch0",)) -> AlarmManager:
    cfg = config_from_dict({"channels": [{"name": c} for c in channels],
                            "alarms": {"rules": rules, "operating": operating or {},
                                       "baselines": baselines or []}})
    return AlarmManager(cfg.alarms, channels, ZONES)


def run(m: AlarmManager, series, indicator="velocity_rms_mm_s", channel="ch0", speeds=None):
    """Feed one value per second; the (second, kind) of every transition."""
    out = []
    for k, x in enumerate(series):
        speed = speeds[k] if speeds is not None else None
        out += [(k, t.kind, t.alarm) for t in m.record(k * S, channel, {indicator: x}, speed)]
    return out


RULE = {"name": "vel", "indicator": "velocity_rms_mm_s", "alert": 2.0, "danger": 4.0}


def test_no_delay_raises_and_clears_at_once():
    m = manager([RULE])
    assert run(m, [1, 2.5, 5, 1]) == [(1, "alarm_alert", "vel/ch0"), (2, "alarm_danger", "vel/ch0"),
                                      (3, "alarm_clear", "vel/ch0")]


def test_on_delay_needs_the_level_held_continuously():
    m = manager([{**RULE, "on_delay_s": 3}])
    # exceeded at 1, 2, dips at 3, exceeded from 4 on: alert at 4 + 3 s
    ev = run(m, [1, 3, 3, 1, 3, 3, 3, 3, 3])
    assert ev == [(7, "alarm_alert", "vel/ch0")]


def test_on_delay_restarts_when_the_value_falls_inside_the_deadband():
    """2.05 reaches 2.0; 1.95 is under it (inside the 5 % deadband): the delay starts again."""
    m = manager([{**RULE, "on_delay_s": 2}])
    assert run(m, [2.05, 1.95, 1.95, 1.95, 2.05, 2.05, 2.05]) == [(6, "alarm_alert", "vel/ch0")]
    m = manager([{**RULE, "on_delay_s": 2, "vote": 2}], channels=("a", "b"))
    out = []
    for k, v in enumerate([2.05, 1.95, 1.95, 1.95, 2.05, 2.05, 2.05]):
        for ch in "ab":
            out += [(k, t.kind) for t in m.record(k * S, ch, {"velocity_rms_mm_s": v})]
    assert out == [(6, "alarm_alert")]


def test_off_delay_holds_the_alarm():
    m = manager([{**RULE, "off_delay_s": 2}])
    ev = run(m, [3, 1, 3, 1, 1, 1, 1])
    assert ev == [(0, "alarm_alert", "vel/ch0"), (5, "alarm_clear", "vel/ch0")]


def test_deadband_stops_chatter_around_the_level():
    series = [2.1, 1.95, 2.05, 1.92, 2.02, 1.85]
    plain = run(manager([{**RULE, "deadband_pct": 0}]), series)
    banded = run(manager([{**RULE, "deadband_pct": 5}]), series)
    assert [k for k, kind, _ in plain] == [0, 1, 2, 3, 4, 5]
    assert banded == [(0, "alarm_alert", "vel/ch0"), (5, "alarm_clear", "vel/ch0")]  # 1.85 < 2 x 0.95


def test_latch_holds_until_acknowledged():
    m = manager([{**RULE, "latch": True}])
    assert run(m, [1, 5, 1, 1]) == [(1, "alarm_danger", "vel/ch0")]
    assert m.alarms["vel/ch0"].row()["level"] == "danger"
    assert m.alarms["vel/ch0"].row()["live"] == "normal"
    acks = [(t.kind, t.level, t.previous) for t in m.ack(10 * S)]
    assert acks == [("alarm_ack", 0, 2), ("alarm_clear", 0, 2)]
    assert m.worst() is None


def test_ack_of_an_active_alarm_keeps_it_and_marks_it():
    m = manager([{**RULE, "latch": True}])
    run(m, [5, 3])
    t = m.ack(2 * S, "vel/ch0")
    assert [(x.kind, x.level) for x in t] == [("alarm_ack", 1), ("alarm_alert", 1)]
    row = m.alarms["vel/ch0"].row()
    assert (row["level"], row["acknowledged"], row["latched"]) == ("alert", True, False)
    with pytest.raises(KeyError):
        m.ack(3 * S, "nope")
    assert m.ack(4 * S) == []            # `ack --all` again: nothing left to acknowledge, no second event


def test_an_alarm_acknowledged_while_active_clears_when_the_value_falls_and_latches_a_new_rise():
    m = manager([{**RULE, "latch": True}])
    run(m, [5])
    assert [x.kind for x in m.ack(1 * S, "vel/ch0")] == ["alarm_ack"]       # danger, still on
    out = [(k, t.kind) for k, v in enumerate([5, 1, 3, 1], start=2)
           for t in m.record(k * S, "ch0", {"velocity_rms_mm_s": v})]
    assert out == [(3, "alarm_clear"), (4, "alarm_alert")]
    row = m.alarms["vel/ch0"].row()
    assert (row["level"], row["live"], row["latched"], row["acknowledged"]) == ("alert", "normal", True, False)


def test_an_ack_while_the_value_is_back_above_the_level_within_its_on_delay_holds_the_level():
    """A latched alert, a dip under the deadband (live normal), the value back at 6x the level,
    its on-delay running: the acknowledgement keeps the alert, acknowledged (it said "now normal"
    and "alert cleared (3.5)", and raised the alert again when the delay ran out); once the delay
    has run, the same episode goes on, no new alarm; a fall then clears it."""
    m = manager([{**RULE, "latch": True, "on_delay_s": 5}])
    seen = run(m, [3] * 6 + [1] + [3] * 3)
    assert seen == [(5, "alarm_alert", "vel/ch0")]
    row = m.alarms["vel/ch0"].row()
    assert (row["level"], row["live"]) == ("alert", "normal")
    acks = [(t.kind, t.level, t.message) for t in m.ack(10 * S, "vel/ch0")]
    assert acks == [("alarm_ack", 1, "vel/ch0 acknowledged (alert)")]
    row = m.alarms["vel/ch0"].row()
    assert (row["level"], row["acknowledged"]) == ("alert", True)
    out = [(k, t.kind) for k, v in enumerate([3, 3, 3, 3, 1], start=10)
           for t in m.record(k * S, "ch0", {"velocity_rms_mm_s": v})]
    assert out == [(14, "alarm_clear")]
    assert m.alarms["vel/ch0"].row()["level"] == "normal"


def test_an_ack_holds_a_pending_level_only_while_the_value_stays_at_it():
    m = manager([{**RULE, "latch": True, "on_delay_s": 5}])
    run(m, [3] * 6 + [1, 3])
    assert [t.kind for t in m.ack(8 * S, "vel/ch0")] == ["alarm_ack"]
    out = [(k, t.kind) for k, v in enumerate([1, 3, 3], start=8)
           for t in m.record(k * S, "ch0", {"velocity_rms_mm_s": v})]
    assert out == [(8, "alarm_clear")]               # the dip ends the hold; a new rise waits its delay


def test_an_ack_with_no_value_at_the_level_clears_the_latch():
    s = AlarmState(on_delay_s=5, latch=True)
    for k in range(6):
        s.step(k * S, 1)
    s.step(6 * S, 0)
    assert (s.level, s.pending) == (1, 0)
    assert s.ack(7 * S) == 0 and not s.acknowledged


def test_a_new_danger_after_an_acknowledged_alert_latches_again():
    """Danger, then alert (the latch shows danger), acknowledged at alert; danger again is a new
    alarm: it latches, and stays when the value falls."""
    m = manager([{**RULE, "latch": True}])
    run(m, [5, 3])
    assert [x.kind for x in m.ack(2 * S, "vel/ch0")] == ["alarm_ack", "alarm_alert"]
    out = [(k, t.kind) for k, v in enumerate([5, 1], start=3) for t in m.record(k * S, "ch0", {"velocity_rms_mm_s": v})]
    assert out == [(3, "alarm_danger")]
    row = m.alarms["vel/ch0"].row()
    assert (row["level"], row["live"], row["latched"], row["acknowledged"]) == ("danger", "normal", True, False)


def test_a_saved_acknowledged_latch_is_not_put_back_as_a_latch():
    """A state file saying an acknowledged alarm is latched at danger (as written while an alarm
    acknowledged on could re-latch) resumes as the acknowledged live level, not a latch."""
    s = AlarmState(latch=True)
    s.resume(0, 2, True, 5 * S)
    assert (s.level, s.latched, s.acknowledged) == (0, 0, False)
    s = AlarmState(latch=True)
    s.resume(0, 2, False, 5 * S)
    assert (s.level, s.latched) == (2, 2)


def test_startup_suppression_by_speed():
    m = manager([RULE], {"source": "speed", "running_above": 600, "startup_suppress_s": 5})
    speeds = [0, 0, 1500, 1500, 1500, 1500, 1500, 1500, 1500, 0]
    ev = run(m, [5] * 10, speeds=speeds)
    # started at 2: suppressed until 7; stopped at 9 clears
    assert ev == [(7, "alarm_danger", "vel/ch0"), (9, "alarm_clear", "vel/ch0")]
    assert m.operating.state == "stopped"


def test_coastdown_suppression():
    m = manager([RULE], {"source": "speed", "running_above": 100, "coastdown_suppress_s": 3,
                         "coastdown_drop_pct": 10})
    speeds = [1500, 1500, 1200, 900, 700, 650, 650]
    ev = run(m, [1, 1, 5, 5, 5, 5, 5], speeds=speeds)
    # the drop at 2 starts coasting: no alarm until 5, when 3 s have passed
    assert ev == [(5, "alarm_danger", "vel/ch0")]


def test_level_source_and_hysteresis_between_thresholds():
    m = manager([{**RULE, "indicator": "accel_rms"}],
                {"source": "level", "level_indicator": "accel_rms", "running_above": 1.0, "stopped_below": 0.5})
    states = []
    for k, x in enumerate([0.1, 0.8, 1.2, 0.8, 0.4]):
        m.record(k * S, "ch0", {"accel_rms": x})
        states.append(m.operating.state)
    assert states == ["stopped", "stopped", "running", "running", "stopped"]


def test_speed_bands_select_the_levels():
    m = manager([{**RULE, "bands": [{"below_rpm": 1000, "alert": 1.0, "danger": 1.5}]}])
    ev = run(m, [1.2, 1.2, 1.2], speeds=[1500, 800, 1500])
    assert ev == [(1, "alarm_alert", "vel/ch0"), (2, "alarm_clear", "vel/ch0")]
    assert m.alarms["vel/ch0"].row()["alert_level"] == 2.0


def test_zone_boundary_and_baseline_levels():
    m = manager([{"name": "iso", "indicator": "velocity_rms_mm_s", "alert_zone": "C", "danger_zone": "D"},
                 {"name": "base", "indicator": "velocity_rms_mm_s", "alert_x_baseline": 2.0,
                  "danger_x_baseline": 4.0}],
                baselines=[{"channel": "ch0", "indicator": "velocity_rms_mm_s", "value": 0.5}])
    m.record(0, "ch0", {"velocity_rms_mm_s": 1.5})
    rows = {r["id"]: r for r in m.table()}
    assert (rows["iso/ch0"]["alert_level"], rows["iso/ch0"]["danger_level"]) == (2.8, 4.5)
    assert (rows["base/ch0"]["alert_level"], rows["base/ch0"]["danger_level"]) == (1.0, 2.0)
    assert (rows["iso/ch0"]["level"], rows["base/ch0"]["level"]) == ("normal", "alert")


def test_baseline_level_without_a_baseline_never_raises():
    m = manager([{"name": "base", "indicator": "kurtosis", "alert_x_baseline": 2.0}])
    assert run(m, [100.0], indicator="kurtosis") == []
    assert "alert_level" not in m.table()[0]


def test_two_of_three_voting():
    m = manager([{**RULE, "vote": 2}], channels=("a", "b", "c"))
    out = []
    for k, vals in enumerate([(3, 1, 1), (3, 1, 3), (5, 5, 1), (1, 1, 5)]):
        for ch, v in zip("abc", vals):
            out += [(k, t.kind, t.alarm, t.channel) for t in m.record(k * S, ch, {"velocity_rms_mm_s": v})]
    assert out == [(1, "alarm_alert", "vel", None), (2, "alarm_danger", "vel", None),
                   (3, "alarm_clear", "vel", None)]


def test_alarms_config_errors_are_one_line():
    cases = {
        "alarms.rules[0].alert_zone: an ISO zone boundary is a level of velocity_rms_mm_s only":
            {"rules": [{"name": "a", "indicator": "accel_rms", "alert_zone": "C"}]},
        "alarms.rules[0].alert: give an alert or a danger level":
            {"rules": [{"name": "a", "indicator": "accel_rms"}]},
        "alarms.operating.running_above: needed with source: speed": {"operating": {"source": "speed"}},
        "alarms.rules[1].name: duplicate alarm name":
            {"rules": [{"name": "a", "indicator": "accel_rms", "alert": 1},
                       {"name": "a", "indicator": "kurtosis", "alert": 1}]},
        "alarms.rules[0].vote: must be at most the 1 channel(s) listed":
            {"rules": [{"name": "a", "indicator": "accel_rms", "alert": 1, "channels": ["ch0"], "vote": 2}]},
        "alarms.rules[0].bands[0].below_rpm: missing (required)":
            {"rules": [{"name": "a", "indicator": "accel_rms", "alert": 1, "bands": [{"alert": 2}]}]},
        "alarms.rules[0].on_dealy_s": {"rules": [{"name": "a", "indicator": "accel_rms", "alert": 1, "on_dealy_s": 2}]},
    }
    for expected, alarms in cases.items():
        with pytest.raises(ConfigError) as err:
            config_from_dict({"alarms": alarms}, source="m.yaml")
        text = str(err.value)
        assert "\n" not in text and text.startswith("m.yaml: " + expected), text


def test_the_readme_motor_example_loads_with_the_iso_group_2_rigid_levels():
    from pathlib import Path

    import yaml

    text = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    block = text.split("`motor.yaml`:\n\n```yaml\n", 1)[1].split("```", 1)[0]
    cfg = config_from_dict(yaml.safe_load(block))
    assert [r.name for r in cfg.alarms.rules][:3] == ["de_velocity", "de_velocity_trend", "de_envelope"]
    from cmsensord.dsp.indicators.iso_zones import boundaries
    m = AlarmManager(cfg.alarms, ("ch0",), boundaries(cfg.indicators.machine_group, cfg.indicators.foundation))
    m.record(0, "ch0", {"velocity_rms_mm_s": 1.0}, 1500.0)
    row = m.alarms["de_velocity/ch0"].row()
    assert (row["alert_level"], row["danger_level"]) == (2.8, 4.5)
