"""The saved alarm state put back into a new manager, on scripted inputs: a restored level the
rule confirms (no new alarm) or drops after its wait, a machine found stopped, a vote, a rule
that no longer latches, and the records refused."""

from __future__ import annotations

import pytest

from cmsensord.alarms import AlarmManager
from cmsensord.alarms.saved import check, resume, snapshot
from cmsensord.alarms.state import RESUME_S
from cmsensord.config import config_from_dict

S = 1_000_000_000
RULE = {"name": "vel", "indicator": "velocity_rms_mm_s", "alert": 2.0, "danger": 4.0}


def manager(rules: list[dict], operating: dict | None = None, channels=("ch0",)) -> AlarmManager:
    cfg = config_from_dict({"channels": [{"name": c} for c in channels],
                            "alarms": {"rules": rules, "operating": operating or {}}})
    return AlarmManager(cfg.alarms, channels, (1.4, 2.8, 4.5))


def feed(m: AlarmManager, series, t0: int = 0, speed: float | None = None, channels=("ch0",)) -> list:
    """One value a second on each channel from ``t0`` [s]: (second, kind) of each transition."""
    out = []
    for k, x in enumerate(series):
        for ch in channels:
            out += [(t0 + k, t.kind) for t in m.record((t0 + k) * S, ch, {"velocity_rms_mm_s": x}, speed)]
    return out


def restarted(rules, series, operating=None, speed=None, channels=("ch0",), ack=False):
    """A manager fed ``series`` (acknowledged at the end if ``ack``), then a new one with its
    snapshot put back: (the new manager, what became of each saved alarm)."""
    m = manager(rules, operating, channels)
    feed(m, series, speed=speed, channels=channels)
    if ack:
        m.ack(len(series) * S, None, "alice")
    saved = check(snapshot(m))
    m2 = manager(rules, operating, channels)
    return m2, resume(m2, saved)


def test_a_danger_the_rule_confirms_goes_on_without_a_new_alarm():
    m, said = restarted([RULE], [5, 5], ack=True)
    assert [(r.alarm, r.restored) for r in said] == [("vel/ch0", True)]
    assert "danger since" in said[0].message and "by alice" in said[0].message
    row = m.alarms["vel/ch0"].row()
    assert (row["level"], row["live"], row["acknowledged"], row["restored"]) == ("danger", "normal", True, True)
    # the input climbs back through alert to danger: the same episode, acknowledged
    assert feed(m, [0, 3, 5, 5], t0=100) == []
    row = m.alarms["vel/ch0"].row()
    assert (row["level"], row["live"], row["acknowledged"], "restored" in row) == ("danger", "danger", True, False)
    # cleared, then raised again: a new alarm
    assert feed(m, [1, 5], t0=200) == [(200, "alarm_clear"), (201, "alarm_danger")]
    assert m.alarms["vel/ch0"].row()["acknowledged"] is False


def test_an_unconfirmed_restored_level_drops_after_its_wait():
    m, _ = restarted([{**RULE, "on_delay_s": 5}], [5] * 6)
    wait = int(RESUME_S) + 5
    assert feed(m, [3] * (wait + 1), t0=100) == [(100 + wait, "alarm_alert")]   # eased from danger
    assert m.alarms["vel/ch0"].row()["level"] == "alert"


def test_a_machine_found_stopped_drops_the_restored_level_and_keeps_the_latch():
    op = {"source": "speed", "running_above": 600}
    m, _ = restarted([RULE, {**RULE, "name": "lat", "latch": True}], [5, 5], operating=op, speed=1500)
    got = feed(m, [5], t0=100, speed=0.0)
    assert got == [(100, "alarm_clear")]
    assert m.alarms["vel/ch0"].state.level == 0 and m.alarms["lat/ch0"].row()["level"] == "danger"


def test_a_voting_alarm_is_restored_by_its_name():
    m, said = restarted([{**RULE, "vote": 2}], [5, 5], channels=("ch0", "ch1"))
    assert [(r.alarm, r.restored) for r in said] == [("vel", True)]
    assert feed(m, [5, 5], t0=100, channels=("ch0", "ch1")) == []


def test_a_latch_of_a_rule_that_no_longer_latches_is_dropped_and_said():
    m = manager([{**RULE, "latch": True}])
    feed(m, [5, 0])
    m2 = manager([RULE])
    said = resume(m2, check(snapshot(m)))
    assert [(r.restored, r.message.split(" not restored: ")[1]) for r in said] == [
        (False, "rule vel no longer latches (latch: false)")]
    assert m2.alarms["vel/ch0"].state.level == 0


@pytest.mark.parametrize("bad, why", [
    ([], "'alarms' is not an object"),
    ({"vel/ch0": {"rule": "vel"}}, "alarm 'vel/ch0': indicator missing or not a str"),
    ({"vel/ch0": {"rule": "vel", "indicator": "x", "latch": True, "levels": {}, "acknowledged": False,
                  "level": "red", "live": "normal", "latched": "normal"}}, "alarm 'vel/ch0': level is not one of"),
    ({"vel/ch0": {"rule": "vel", "indicator": "x", "latch": True, "levels": {}, "acknowledged": False,
                  "level": "alert", "live": "normal", "latched": "alert", "since_ns": 10**30}},
     "alarm 'vel/ch0': since_ns 1000000000000000000000000000000 is out of range"),
    ({"vel/ch0": {"rule": "vel", "indicator": "x", "latch": True, "levels": {}, "acknowledged": True,
                  "level": "alert", "live": "alert", "latched": "normal", "acked_ns": -1}},
     "alarm 'vel/ch0': acked_ns -1 is out of range"),
])
def test_records_that_are_not_saved_alarms_are_refused(bad, why):
    with pytest.raises(ValueError, match=why):
        check(bad)


def test_other_zone_boundaries_are_a_change_of_zone_levels():
    """alert_zone C is 2.8 mm/s for group 2 rigid, 4.5 for group 2 flexible: the alarm active
    at the stop is judged afresh against the other boundaries, and said."""
    rule = {"name": "iso", "indicator": "velocity_rms_mm_s", "alert_zone": "C"}
    m = manager([rule])
    feed(m, [3.0, 3.0])
    cfg = config_from_dict({"alarms": {"rules": [rule]}})
    m2 = AlarmManager(cfg.alarms, ("ch0",), (2.3, 4.5, 7.1))
    said = resume(m2, check(snapshot(m)))
    assert [(r.restored, r.message.split(" not restored: ")[1]) for r in said] == [
        (False, "its levels changed since (zone boundaries 1.4/2.8/4.5 -> 2.3/4.5/7.1 mm/s): judged afresh against "
                "them")]
    m3 = manager([rule])                                    # the same boundaries: the same episode
    assert [r.restored for r in resume(m3, check(snapshot(m)))] == [True]


def test_an_acknowledged_level_held_in_its_on_delay_is_restored_acknowledged():
    """A latched alert acknowledged while the value is back at it within its on-delay (held, see
    AlarmState.ack), then a restart: the alert is restored, acknowledged, and the rule confirming
    it raises no new alarm."""
    m, said = restarted([{**RULE, "latch": True, "on_delay_s": 5}], [3] * 6 + [1] + [3] * 3, ack=True)
    assert [(r.alarm, r.restored) for r in said] == [("vel/ch0", True)]
    row = m.alarms["vel/ch0"].row()
    assert (row["level"], row["acknowledged"]) == ("alert", True)
    assert feed(m, [3] * 7, t0=100) == []
    row = m.alarms["vel/ch0"].row()
    assert (row["level"], row["live"], row["acknowledged"]) == ("alert", "alert", True)
