"""A change of alarm levels alone waits up to SAVE_LEVELS_S of stream time before the state
file is written (tests/test_alarm_state_writes.py); what waits must still reach the file, and
a file that cannot take it must still be said: the first failing save is an
``alarm_state_error`` event even when it is a deferred one, a link gone idle saves what waits
when it falls due, a wall-clock step moves when it falls due, and the stop writes what the
store could not take."""

from __future__ import annotations

from cmsensord.monitor.alarms import SAVE_LEVELS_S
from test_alarms_unavailable import S, alarms, record


class Store:
    """An alarm state store that keeps the levels of each save, or fails (read-only)."""

    path = "/var/lib/cmsensord/cmsensord-alarms.json"

    def __init__(self) -> None:
        self.saves: list[dict[str, str]] = []
        self.fail = False

    def save(self, state: dict) -> None:
        if self.fail:
            raise OSError(30, "Read-only file system")
        self.saves.append({k: v["level"] for k, v in state.items()})


def _kinds(a, values: list[float], start: int) -> list[tuple[int, str]]:
    """One record a second from stream second ``start``: the (second, kind) of each event."""
    out = []
    for k, x in enumerate(values):
        out += [(start + k, e.kind) for e in a.see(record(start + k, "ch0", x)) if hasattr(e, "kind")]
    return out


def _alert_then_danger(start: int = 0):
    """The alert saved at once at ``start``, then danger 3 s later (levels alone: deferred)."""
    a, store = alarms({"danger": 2.0}), Store()
    a.keep(store, {})
    assert _kinds(a, [1.5] * 3 + [2.5] * 2, start) == [(start, "alarm_alert"), (start + 3, "alarm_danger")]
    assert store.saves == [{"r/ch0": "alert"}]
    return a, store


def test_a_deferred_save_that_fails_first_is_said():
    a, store = _alert_then_danger()
    store.fail = True                               # the disk turned read-only meanwhile
    got = _kinds(a, [2.5] * int(SAVE_LEVELS_S + 5), 5)
    assert [k for _, k in got] == ["alarm_state_error"], got
    assert got[0][0] == SAVE_LEVELS_S               # when the deferred save fell due


def test_an_idle_link_saves_the_waiting_levels_when_they_fall_due():
    a, store = _alert_then_danger()
    assert a.tick(30 * S) == [] and store.saves == [{"r/ch0": "alert"}]     # not due yet
    assert a.tick(int(SAVE_LEVELS_S) * S) == []
    assert store.saves[-1] == {"r/ch0": "danger"}


def test_a_wall_clock_step_back_moves_when_the_waiting_levels_fall_due():
    a, store = _alert_then_danger(100_000)
    a.restepped(-86_400 * S)                        # the stamps step back a day with the wall clock
    start = 100_005 - 86_400
    _kinds(a, [2.5] * int(SAVE_LEVELS_S), start)
    assert store.saves[-1] == {"r/ch0": "danger"}, store.saves


def test_the_stop_writes_what_the_store_could_not_take():
    a, store = alarms({"danger": 2.0}), Store()
    a.keep(store, {})
    store.fail = True
    assert [k for _, k in _kinds(a, [1.5], 0)] == ["alarm_alert", "alarm_state_error"]
    store.fail = False                              # the disk is back before the next retry
    a.finish()
    assert store.saves == [{"r/ch0": "alert"}]
