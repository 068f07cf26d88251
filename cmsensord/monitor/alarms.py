"""The chain's messages -> the alarm manager -> alarm events and ``/cm/alarms``.

:class:`Alarms` reads the messages the Processor writes: each
``/cm/<ch>/indicators`` record (its values under the stable names of
:meth:`cmsensord.dsp.indicators.IndicatorRecord.values`, its shaft speed, which
also sets the operating state), each ``/cm/<ch>/severity`` decision
(``severity_index``) and each recursive ``/cm/<ch>/orders`` block
(``order.<name>``: the order's RMS, valid blocks only).  A value a record lists in
``unavailable`` by its name (a bearing line the envelope spectrum does not resolve) is no
reading: its alarms hold their levels and a delay pending on it starts again with its next
value (:meth:`AlarmManager.unknown`).  Each order component with
``alarm_rms`` is a rule ``order_<name>`` (:func:`order_rules`): alert at
``alarm_rms``, deadband ``1 - orders.alarm_clear``, ``orders.alarm_on_delay_s`` and
``alarm_off_delay_s``.  What they change comes back as events (``alarm_alert``,
``alarm_danger``, ``alarm_clear``, ``alarm_ack``) and, whenever the alarm table
changes, one ``/cm/alarms`` message — all stamped with the stamp of the message
that caused them (an acknowledgement: the newest stamp), so a replay gives what
the live run gave.  A change of the machine's operating state is an
``operating_state`` event (details: ``state``, ``previous``); with an
``alarms.operating`` source the manager runs for it even without rules.  A rule level given
as k x a baseline that ``alarms.baselines`` lacks for a channel is said once, with the first
message: an ``alarm_no_baseline`` event (a warning) naming the rule and the channel.  A record
whose ``accel_rms`` is below ``monitor.signal_floor`` x its learned baseline (``alarms.baselines``,
else the channel's ``monitor.baseline``) has no signal (a
sensor fault, or the machine stopped): the channel's rules hold (not judged on it; a delay
pending on it starts again with its next value), as its severity does (the ``signal_lost``
event of :mod:`cmsensord.monitor.severity`); so do they on a record marked ``signal_lost`` (the
severity decision it goes out with has no signal) and after a severity decision with no signal,
for any reason (also RAW blocks whose samples are all one count, ``monitor.flat_signal``).

The live daemon keeps the alarm state an operator relies on over a restart (:meth:`Alarms.keep`:
a store, :mod:`cmsensord.service.alarm_store`, and what it held): the saved alarms go back
into the manager when it is made (:mod:`cmsensord.alarms.saved`), with the first message,
each said by an ``alarm_restored`` or ``alarm_not_restored`` event (a warning) naming the
file; the store is written whenever the saved state changes, and a failed write is an
``alarm_state_error`` event.  Without a store (a replay) nothing is read or kept.  A step of
the wall clock moves the alarms' timers and stamps with the stamps (:meth:`Alarms.restepped`),
so a delay counts the stream's own time across it.
"""

from __future__ import annotations

import dataclasses
import logging
import re
import time
from collections.abc import Callable
from typing import Any, Protocol

from cmsensord.alarms import LEVELS, AlarmManager, Judged, Transition
from cmsensord.alarms.saved import ack_saved, latch_or_ack_changed, resume, saved_rows, shown, snapshot
from cmsensord.config import Config
from cmsensord.config.alarm_indicators import RECORD_VALUES, RMS_MODE_VALUES, raw_only_rules
from cmsensord.config.alarms import AlarmRuleConfig
from cmsensord.dsp.indicators.iso_zones import boundaries
from cmsensord.monitor import messages
from cmsensord.monitor.events import Event

__all__ = ["Alarms", "indicator_values", "unknown_values", "order_rules", "blind_in_rms_mode"]

log = logging.getLogger("cmsensord")

#: a state the store could not take is tried again this often (seconds of stream time)
SAVE_RETRY_S = 10.0
#: a change of levels alone (no latch or acknowledgement changed) is saved at most this often
#: (seconds of stream time) and at the stop: a chattering alarm does not rewrite the file each
#: second (an SD card's wear); a kill -9 may lose that long of such changes, which the next
#: values judge again
SAVE_LEVELS_S = 60.0
#: the message kinds the alarm manager reads
WATCHED = frozenset({"indicators", "severity", "orders"})
#: the measured values of a record (the names rules may watch: the zone is graded, below)
_SCALARS = tuple(k for k in RECORD_VALUES if k != "zone")


class StateStore(Protocol):
    """Where the alarm state is kept (:class:`cmsensord.service.alarm_store.AlarmStore`)."""

    path: Any

    def save(self, alarms: dict[str, dict[str, Any]]) -> None: ...


def indicator_values(msg: dict) -> dict[str, float]:
    """The values of an indicators message under the stable names (zone A-D as 0-3; a bearing
    line's amplitude as ``<bearing>.<line>``, its ratio as ``<bearing>.<line>_ratio``)."""
    out = {k: float(msg[k]) for k in _SCALARS if k in msg}
    if "zone" in msg:
        out["zone"] = float("ABCD".index(msg["zone"]))
    for b in msg.get("bearings", ()):
        out.update({f"{b['name']}.{k}": float(p["amplitude"]) for k, p in b.get("lines", {}).items()})
        out.update({f"{b['name']}.{k}_ratio": float(p["ratio"]) for k, p in b.get("lines", {}).items()
                    if "ratio" in p})
    out.update({f"band.{b['name']}": float(b["rms"]) for b in msg.get("bands", ())})
    return out


def unknown_values(msg: dict) -> tuple[str, ...]:
    """The values an indicators message names unavailable one by one (``<bearing>.<line>``:
    a line its envelope spectrum does not resolve, and so its ``<bearing>.<line>_ratio``); not
    the groups (``speed``, ``bearings``, ``bands``) nor the spectral indicators of an interval
    with lost samples, whose delays go on."""
    named = [k for k in msg.get("unavailable", ()) if "." in k]
    return tuple(named) + tuple(f"{k}_ratio" for k in named if not k.startswith("band."))


def _order_values(msg: dict) -> dict[str, float]:
    if msg.get("method") != "recursive" or not msg.get("valid"):
        return {}
    return {f"order.{o['name']}": float(o["rms"]) for o in msg.get("orders", ()) if o.get("rms") is not None}


def order_rules(cfg: Config) -> tuple[AlarmRuleConfig, ...]:
    """The order tracker's alarms as rules: one per component with ``alarm_rms`` (a rule of
    the same name in ``alarms.rules`` replaces it)."""
    o = cfg.orders
    taken = {r.name for r in cfg.alarms.rules}
    out = []
    for c in o.components:
        name = "order_" + re.sub(r"[^A-Za-z0-9_]", "_", c.name)
        if c.alarm_rms is not None and name not in taken:
            out.append(AlarmRuleConfig(name=name, indicator=f"order.{c.name}", alert=c.alarm_rms,
                                       on_delay_s=o.alarm_on_delay_s, off_delay_s=o.alarm_off_delay_s,
                                       deadband_pct=round(100.0 * (1.0 - o.alarm_clear), 9)))
    return tuple(out)


def blind_in_rms_mode(cfg: Config) -> str | None:
    """What never fires on an RMS-mode board, whose indicator records carry ``accel_rms`` only and
    no shaft speed (beside them the severity index: :data:`RMS_MODE_VALUES`): the rules on any
    other indicator, and every rule when the operating state is taken from the shaft speed or from
    another indicator's level; None when nothing is so (or ``alarms.enabled`` is false)."""
    if not cfg.alarms.enabled:
        return None
    never = []
    rules = raw_only_rules(cfg.alarms.rules + order_rules(cfg))
    if rules:
        never.append(f"alarm rule(s) {', '.join(rules)} never fire")
    op = cfg.alarms.operating
    if op.source == "speed" or (op.source == "level" and op.level_indicator not in RMS_MODE_VALUES):
        what = "shaft speed" if op.source == "speed" else f"level of {op.level_indicator}"
        never.append(f"alarms.operating.source {op.source} gets no {what}: the machine is never seen "
                     "running, no rule fires")
    if not never:
        return None
    return ("the board is in RMS mode, whose indicator records carry accel_rms only and no shaft speed (RAW "
            "mode gives the rest): " + "; ".join(never))


def has_alarm_rules(cfg: Config) -> bool:
    """Whether alarms are evaluated: ``alarms.enabled`` and a rule (of ``alarms.rules`` or an
    order component's ``alarm_rms``); without, no ``/cm/alarms`` table is ever written."""
    return cfg.alarms.enabled and bool(cfg.alarms.rules or order_rules(cfg))


class Alarms:
    """Messages -> alarm events and /cm/alarms (see module docstring).  ``channels``: the
    vibration channels' names when the first watched message comes."""

    def __init__(self, cfg: Config, channels: Callable[[], tuple[str, ...]]):
        self.cfg, self.channels = cfg, channels
        self.manager: AlarmManager | None = None
        self.rules = dataclasses.replace(cfg.alarms, rules=cfg.alarms.rules + order_rules(cfg))
        self.active = has_alarm_rules(cfg)
        #: the manager runs: for the rules, or for the operating state alone
        self.watching = self.active or (cfg.alarms.enabled and cfg.alarms.operating.source != "none")
        self.newest_ns = 0
        self._signature: tuple = ()
        self.store: StateStore | None = None
        self._saved: dict[str, dict[str, Any]] = {}       # to put back when the manager is made
        self._kept: dict[str, dict[str, Any]] = {}        # what the store holds
        self._unsaved: dict[str, dict[str, Any]] | None = None   # what it could not take (retried)
        self._retry_ns = 0
        self._deferred: dict[str, dict[str, Any]] | None = None  # levels not saved yet (SAVE_LEVELS_S)
        self._levels_due_ns = 0
        self._no_signal: set[str] = set()     # channels whose last severity decision had no signal
        #: when given: the manager keeps every value it judges in it (:attr:`AlarmManager.judged`)
        self.judged: Judged | None = None

    def keep(self, store: StateStore, saved: dict[str, dict[str, Any]]) -> list:
        """Keep the alarm state in ``store`` from now on and put ``saved`` (what it held) back
        with the first message.  Returns the ``alarm_not_restored`` events of saved alarms that
        cannot go back as no rule is in force (then the store is emptied)."""
        self.store, self._saved, self._kept = store, saved, {k: dict(v) for k, v in saved.items()}
        if self.active or not saved:
            return []
        why = "alarms.enabled is false" if not self.cfg.alarms.enabled else "no alarm rules are configured"
        self._saved = {}
        return [self._resumed(name, None, False, f"{name} not restored: {why}") for name in saved] \
            + self._persist(None, {})

    def _manager(self) -> AlarmManager:
        if self.manager is None:
            ic = self.cfg.indicators
            self.manager = AlarmManager(self.rules, self.channels(), boundaries(ic.machine_group, ic.foundation),
                                        self.cfg.bearings)
            self.manager.judged = self.judged
        return self.manager

    def see(self, m: messages.Message) -> list:
        """The events and the /cm/alarms message that message ``m`` causes (often none); with the
        first, an ``alarm_no_baseline`` event per rule and channel whose levels need a baseline
        not learned (:meth:`_unlearned`)."""
        if m.schema not in WATCHED or not self.watching:
            return []
        out = self.tick(m.stamp_ns)
        first = self.manager is None
        back = self._resume(m.stamp_ns) if first else []
        out += self._see(m)
        return self._unlearned(m.stamp_ns) + back + out if first else out

    def tick(self, stamp: int) -> list:
        """At stream time ``stamp`` (a message, or a wake-up of an idle link): the state the store
        could not take, tried again every SAVE_RETRY_S, or the levels not saved yet, once
        SAVE_LEVELS_S after the last save, into the store; the ``alarm_state_error`` event of
        the first save that fails."""
        if self._unsaved is not None and stamp >= self._retry_ns:
            return self._persist(stamp, self._unsaved)
        if self._deferred is not None and stamp >= self._levels_due_ns:
            return self._persist(stamp, self._deferred)
        return []

    def _resume(self, stamp: int) -> list:
        """The saved alarms put back into the manager just made: an event for each."""
        mgr, saved, self._saved = self._manager(), self._saved, {}
        return [self._resumed(r.alarm, r.channel, r.restored, r.message, stamp) for r in resume(mgr, saved)]

    def _resumed(self, alarm: str, channel: str | None, restored: bool, message: str,
                 stamp: int | None = None) -> Event:
        where = str(self.store.path) if self.store is not None else ""
        return Event("alarm_restored" if restored else "alarm_not_restored", channel,
                     f"{message}, from {where}", stamp, {"alarm": alarm, "details": {"file": where}})

    def _persist(self, stamp: int | None, now: dict[str, dict[str, Any]]) -> list:
        """``now`` into the store if it holds something else; an ``alarm_state_error`` event if
        it cannot be written (then tried again, silently, with the messages at least every
        SAVE_RETRY_S of stream time, until it is written)."""
        self._deferred = None
        if self.store is None or now == self._kept:
            self._unsaved = None
            return []
        try:
            self.store.save(now)
        except OSError as exc:
            told = self._unsaved is not None
            self._unsaved, self._retry_ns = now, (stamp or 0) + int(SAVE_RETRY_S * 1e9)
            return [] if told else [
                Event("alarm_state_error", None, f"{self.store.path}: cannot write the alarm state "
                      f"({exc.strerror or exc}): latches and acknowledgements of now would not survive a "
                      f"restart; trying again every {SAVE_RETRY_S:g} s", stamp,
                      {"details": {"file": str(self.store.path)}})]
        if self._unsaved is not None:
            log.info("alarm state: written to %s again", self.store.path)
        self._kept, self._unsaved = now, None
        return []

    def _unlearned(self, stamp: int) -> list:
        """An ``alarm_no_baseline`` event for each rule and channel with a level given as k x a
        baseline that ``alarms.baselines`` does not hold: that level is not in force there."""
        out: list[Any] = []
        for a in self._manager().alarms.values():
            r = a.rule
            keys = list(dict.fromkeys(k for src in (r, *r.bands) for k in ("alert_x_baseline", "danger_x_baseline")
                                      if getattr(src, k) is not None))
            for ch in a.channels if keys else ():
                if self.rules.baseline(ch, r.indicator) is None:
                    out.append(Event("alarm_no_baseline", ch, f"rule {r.name} on {ch}: no baseline of "
                                     f"{r.indicator} learned for {ch} (alarms.baselines), so its "
                                     f"{' and '.join(keys)} level(s) are not in force there: run cmsensord "
                                     "calibrate on a healthy capture of this machine", stamp, {"alarm": a.id}))
        return out

    def _see(self, m: messages.Message) -> list:
        msg, stamp = m.msg, m.stamp_ns
        self.newest_ns = max(self.newest_ns, stamp)
        mgr = self._manager()
        ch = msg["channel"]
        if m.schema == "indicators":
            speed = msg.get("speed_rpm")
            was = mgr.operating.state
            values = indicator_values(msg)
            judged = self._judged(ch, values, bool(msg.get("signal_lost")))  # no signal: none judged
            unknown = unknown_values(msg) + tuple(k for k in values if k not in judged)
            band = msg.get("velocity_band_hz")
            tr = mgr.record(stamp, ch, judged, None if speed is None else float(speed), unknown,
                            (float(band[0]), float(band[1])) if band else None)
            if mgr.operating.state != was:
                return [self._state_event(stamp, was, mgr.operating.state, speed)] + self._after(stamp, tr)
        elif m.schema == "severity":
            (self._no_signal.add if msg.get("signal_lost") else self._no_signal.discard)(ch)
            tr = mgr.values(stamp, ch, {"severity_index": float(msg["severity_index"])})
        else:
            tr = mgr.values(stamp, ch, _order_values(msg))
        return self._after(stamp, tr)

    def _judged(self, ch: str, values: dict[str, float], lost: bool = False) -> dict[str, float]:
        """``values`` of a record of ``ch``; none but the operating state's level when its
        ``accel_rms`` is below ``monitor.signal_floor`` x its learned baseline, or the record is
        marked ``lost`` (its decision has no signal) or the channel's last severity decision had
        no signal (that, or flat RAW blocks: ``monitor.flat_signal``; no signal: the channel's
        alarms hold, their delays start again, as its severity does)."""
        mon = next((c.monitor for c in self.cfg.channels if c.name == ch), self.cfg.monitor)
        base = self.rules.baseline(ch, "accel_rms") or mon.baseline     # else the bank's block RMS
        level = values.get("accel_rms")
        quiet = lost or ch in self._no_signal or bool(mon.signal_floor and level is not None and base is not None
                                              and level < mon.signal_floor * base)
        if not quiet:
            return values
        keep = self.rules.operating.level_indicator if self.rules.operating.source == "level" else None
        return {k: v for k, v in values.items() if k == keep}

    def _state_event(self, stamp: int, was: str, now: str, speed: float | None) -> Event:
        op = self.rules.operating
        why = f"speed {float(speed):.0f} rpm" if op.source == "speed" and speed is not None else \
            f"{op.level_indicator} {self.manager.operating.reading:.4g}" if self.manager and \
            self.manager.operating.reading is not None and op.source == "level" else "suppression time over"
        return Event("operating_state", None, f"operating state {was} -> {now} ({why})", stamp,
                     {"details": {"state": now, "previous": was}})

    def restepped(self, shift_ns: int) -> None:
        """The wall clock stepped and the stamps with it by ``shift_ns``: the alarms' timers and
        stamps move with them (:meth:`AlarmManager.shift`), so a delay counts the stream's time."""
        if self.newest_ns:
            self.newest_ns += shift_ns
        if self._levels_due_ns:
            self._levels_due_ns += shift_ns
        if self._retry_ns:
            self._retry_ns += shift_ns
        if self.manager is not None:
            self.manager.shift(shift_ns)

    def ack(self, which: str | None, by: str | None = None) -> list:
        """Acknowledge alarm ``which`` (None: all) by user ``by`` (None: not known); KeyError for an
        unknown alarm (and for any before the first value: the alarms are made with the channels
        the stream brings)."""
        if not self.active:
            raise KeyError(which or "all")
        if self.manager is None:
            return self._ack_saved(which, by)
        return self._after(self.newest_ns, self.manager.ack(self.newest_ns, which, by))

    def _ack_saved(self, which: str | None, by: str | None) -> list:
        """Before the first value: acknowledge what the last run saved (:func:`ack_saved`), kept
        in the store at once; an ``alarm_ack`` event each (KeyError: no such saved alarm)."""
        now = time.time_ns()
        done = ack_saved(self._saved, which, now, by)
        who = f" by {by}" if by else ""
        out: list[Any] = [Event("alarm_ack", None, f"{name} acknowledged{who} ({before}, saved by the last run; "
                                f"{after} at its stop, judged again when data comes)", None,
                                {"alarm": name, "alarm_level": after, "previous_level": before})
                          for name, before, after in done]
        return out + self._persist(None, {k: dict(v) for k, v in self._saved.items()})

    def _after(self, stamp: int, tr: list[Transition]) -> list:
        out: list[Any] = [Event(t.kind, t.channel, t.message, t.stamp_ns,
                                {"alarm": t.alarm, "alarm_level": LEVELS[t.level],
                                 "previous_level": LEVELS[t.previous]})
                          for t in tr]
        mgr = self._manager()
        sig = mgr.signature()
        if sig != self._signature:
            self._signature = sig
            out.append(messages.alarms(stamp, self.table()))
            now = snapshot(mgr)
            if self._unsaved is None and stamp < self._levels_due_ns and not latch_or_ack_changed(self._kept, now):
                self._deferred = now            # levels alone: saved with the next due message or the stop
            else:
                self._levels_due_ns = stamp + int(SAVE_LEVELS_S * 1e9)
                out += self._persist(stamp, now)
        return out

    def finish(self) -> list:
        """The stop: the levels not saved yet (:data:`SAVE_LEVELS_S`), or the state the store could
        not take, into the store."""
        now = self._deferred if self._deferred is not None else self._unsaved
        return self._persist(self.newest_ns, now) if now is not None else []

    def table(self) -> dict:
        """The /cm/alarms message body: operating state, worst level, every alarm's row (before
        the first value: the rows the last run saved, :meth:`_saved_table`)."""
        if self.manager is None:
            return self._saved_table()
        mgr = self.manager
        worst = mgr.worst()
        out: dict[str, Any] = {"operating_state": mgr.operating.state,
                               "worst": LEVELS[worst.state.level] if worst else "normal",
                               "alarms": mgr.table()}
        if worst is not None:
            out["worst_alarm"] = worst.id
        if mgr.speed_rpm is not None:
            out["speed_rpm"] = round(mgr.speed_rpm, 6)
        return out

    def saved_names(self) -> list[str]:
        """The alarms the last run saved, not put back yet (no data has come)."""
        return list(self._saved)

    def _saved_table(self) -> dict:
        rows = saved_rows(self._saved, self.rules)
        top = max(rows, key=lambda r: LEVELS.index(r["level"]), default=None)
        out = {"operating_state": "running" if self.rules.operating.source == "none" else "stopped",
               "worst": top["level"] if top else "normal", "alarms": rows}
        if top is not None and top["level"] != "normal":
            out["worst_alarm"] = top["id"]
        return out

    def summary(self) -> str | None:
        """The worst active alarm for the status line, and how many others show a level ("ALARM
        danger vel/ch0 and 1 more at alert or danger"), None if none; before the first value, the
        worst alarm saved by the last run, said to be so."""
        if self.manager is None:
            return _saved_summary(self._saved)
        worst = self.manager.worst()
        if worst is None:
            return None
        n = sum(a.state.level > 0 for a in self.manager.alarms.values())
        return f"ALARM {LEVELS[worst.state.level]} {worst.id}{_more(n - 1)}"


def _more(others: int) -> str:
    """The other alarms showing a level, after the worst one's name ("" when none)."""
    return f" and {others} more at alert or danger" if others else ""


def _saved_summary(saved: dict[str, dict[str, Any]]) -> str | None:
    """The worst alarm the last run saved, for the status line until data comes."""
    levels = {name: LEVELS.index(shown(r)) for name, r in saved.items()}
    levels = {name: level for name, level in levels.items() if level > 0}
    if not levels:
        return None
    name = max(levels, key=lambda k: levels[k])
    return f"ALARM {LEVELS[levels[name]]} {name}{_more(len(levels) - 1)} (saved by the last run; waiting for data)"
