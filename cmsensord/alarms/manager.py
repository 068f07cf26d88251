"""The alarm manager: the configured rules over the channels, the alarm table, acknowledgements.

Each rule watches one indicator on its channels (default: a bearing's line on the
bearing's channel, any other indicator on every vibration channel given).  With
``vote: 1`` each channel has its own alarm, named ``<rule>/<channel>``; with ``vote: N``
the rule is one alarm, named ``<rule>``, whose input is the highest level that at least
N of its channels exceed.  Per channel the value is compared with the rule's levels at
the current speed (:mod:`.levels`) with the rule's deadband (:mod:`.exceedance`); the alarm applies
the delays and the latch (:mod:`.state`).  A value not given is no reading: its
alarms hold their levels (one said to be unknown, :meth:`AlarmManager.unknown`, also
restarts the delays pending on it).  Alarms are evaluated while the
machine is running (:mod:`.operating`); when it leaves that state each alarm is
suppressed (non-latched ones clear).  Alarms put back from a saved state (a
daemon's restart, :mod:`.saved`) show their restored levels until the rules confirm
them (:mod:`.state`); when the first reading of the operating state after that says
the machine is stopped, they are suppressed as when it stops.

Every call returns the :class:`Transition` records it caused, stamped with the
stream time it was given; :meth:`AlarmManager.table` is the alarm table.
"""

from __future__ import annotations

from array import array
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from cmsensord.config.alarm_indicators import unit_of, what_is
from cmsensord.config.alarms import AlarmRuleConfig, AlarmsConfig
from cmsensord.config.channel_refs import rule_channels

from .exceedance import Exceedance
from .levels import rule_levels
from .operating import Operating
from .state import LEVELS, AlarmState

__all__ = ["AlarmManager", "Transition", "Alarm", "Judged"]

#: the event kind of a change of the shown level to this level
KIND = {0: "alarm_clear", 1: "alarm_alert", 2: "alarm_danger"}


@dataclass(frozen=True)
class Transition:
    """An alarm's shown level changed (or it was acknowledged) at ``stamp_ns``."""

    kind: str               # alarm_alert, alarm_danger, alarm_clear, alarm_ack
    alarm: str
    channel: str | None     # None for a voting alarm
    level: int
    previous: int
    stamp_ns: int
    message: str


@dataclass
class Alarm:
    """One row of the alarm table."""

    id: str
    rule: AlarmRuleConfig
    channels: tuple[str, ...]
    channel: str | None
    state: AlarmState
    value: float | None = None
    levels: tuple[float | None, float | None] = (None, None)
    inputs: dict[str, tuple[int, int]] = field(default_factory=dict)   # voting: each channel's (exceedance, reached)
    latest: dict[str, float] = field(default_factory=dict)  # each channel's newest value (shown: the highest)

    def row(self) -> dict:
        """The table row (absent fields: not known)."""
        s = self.state
        out: dict = {"id": self.id, "rule": self.rule.name, "indicator": self.rule.indicator,
                     "channels": list(self.channels), "level": LEVELS[s.level], "live": LEVELS[s.live],
                     "latched": s.latched > 0, "acknowledged": s.acknowledged}
        if s.restored:
            out["restored"] = True
        if self.channel is not None:
            out["channel"] = self.channel
        if self.value is not None:
            out["value"] = round(self.value, 9)
        for name, lv in zip(("alert_level", "danger_level"), self.levels):
            if lv is not None:
                out[name] = round(lv, 9)
        if s.changed_ns is not None:
            out["since"] = {"sec": s.changed_ns // 1_000_000_000, "nsec": s.changed_ns % 1_000_000_000}
        return out


def _voted(levels: list[int], vote: int) -> int:
    """The highest level at least ``vote`` of the channels' ``levels`` are at (0: none)."""
    return max((lv for lv in (2, 1) if sum(v >= lv for v in levels) >= vote), default=0)


class Judged:
    """Every value an :class:`AlarmManager` judged while running, per alarm and channel: its stamps
    [ns] and the values as multiples of the lowest level in force when each was judged (alert, else
    danger; NaN without one), in compact arrays (16 bytes a value: a week of 1-s records of 20
    alarms in 190 MB, not the ~2 GB of a tuple each): a channel's own baseline level, or a speed
    band's, judges its values as the alarm judged them; and the alert and danger levels last in force."""

    def __init__(self) -> None:
        self.stamps: dict[str, dict[str, array]] = {}
        self.ratios: dict[str, dict[str, array]] = {}
        self.levels: dict[str, tuple[float | None, float | None]] = {}
        self.origin_ns = 0          # the stamp the reader counts seconds from (board second 0)

    def add(self, t_ns: int, alarm: str, channel: str, value: float,
            levels: tuple[float | None, float | None]) -> None:
        """Alarm ``alarm`` judged ``value`` of ``channel`` at stamp ``t_ns`` against ``levels`` (alert, danger)."""
        low = levels[0] if levels[0] is not None else levels[1]
        if channel not in self.stamps.setdefault(alarm, {}):
            self.stamps[alarm][channel], self.ratios.setdefault(alarm, {})[channel] = array("q"), array("d")
        self.stamps[alarm][channel].append(t_ns)
        self.ratios[alarm][channel].append(value / low if low else float("nan"))
        self.levels[alarm] = levels


class AlarmManager:
    """Rules over channels (see module docstring).  ``channels``: the vibration channels'
    names (the default set of each rule); ``zones``: the ISO 10816-3 boundaries A/B, B/C,
    C/D of the configured machine [mm/s]; ``bearings``: the configured bearings
    (:class:`~cmsensord.config.indicators.BearingConfig`), whose channel is the default set of
    a rule on one of their lines."""

    def __init__(self, cfg: AlarmsConfig, channels: tuple[str, ...], zones: tuple[float, float, float],
                 bearings: Sequence[Any] = ()):
        self.cfg, self.zones = cfg, zones
        self.operating = Operating(cfg.operating)
        self.speed_rpm: float | None = None
        #: channel -> the velocity band [Hz] of its newest indicator record, said with a value
        #: of the velocity RMS or its zone (a velocity RMS means nothing without its band)
        self.velocity_bands: dict[str, tuple[float, float]] = {}
        self.levels_seen: dict[str, float] = {}          # channel -> the level indicator's newest value
        self.alarms: dict[str, Alarm] = {}
        self.exceed: dict[tuple[str, str], Exceedance] = {}
        self.by_indicator: dict[str, list[AlarmRuleConfig]] = {}
        #: levels were put back from a saved state and no operating reading has come since
        self.resumed = False
        #: when given: every value judged while running (``cmsensord calibrate``'s check of the
        #: alarm levels against the healthy period)
        self.judged: Judged | None = None
        for r in cfg.rules:
            watched = rule_channels(r, channels, bearings)
            self.by_indicator.setdefault(r.indicator, []).append(r)
            if r.vote > 1:
                self._add(r.name, r, tuple(watched), None)
            else:
                for ch in watched:
                    self._add(f"{r.name}/{ch}", r, (ch,), ch)

    def _add(self, aid: str, r: AlarmRuleConfig, chans: tuple[str, ...], ch: str | None) -> None:
        self.alarms[aid] = Alarm(aid, r, chans, ch, AlarmState(r.on_delay_s, r.off_delay_s, r.latch))
        for c in chans:
            self.exceed[(r.name, c)] = Exceedance(r.deadband_pct / 100.0)

    # ---------------------------------------------------------------- input
    def record(self, t_ns: int, channel: str, values: dict[str, float],
               speed_rpm: float | None = None, unknown: tuple[str, ...] = (),
               velocity_band: tuple[float, float] | None = None) -> list[Transition]:
        """One indicator record of ``channel`` at ``t_ns``: the operating state, then the rules;
        ``unknown``: indicators the record says it cannot give (:meth:`unknown`);
        ``velocity_band``: the band [Hz] of its velocity RMS, which an alarm line on the velocity
        or its zone names."""
        if velocity_band is not None:
            self.velocity_bands[channel] = velocity_band
        out = self._operate(t_ns, channel, values, speed_rpm)
        self.unknown(channel, unknown)
        return out + self.values(t_ns, channel, values)

    def unknown(self, channel: str, names: tuple[str, ...]) -> None:
        """The indicators ``names`` of ``channel`` are not known now (a bearing line its envelope
        spectrum does not resolve).  An alarm on one holds its shown level (no value: neither
        raised nor cleared), but nothing measured before counts on after: a delay pending on the
        channel's values starts again with its next value, and a voting alarm counts no
        exceedance of that channel until it has one."""
        for name in names:
            for r in self.by_indicator.get(name, ()):
                a = self.alarms.get(f"{r.name}/{channel}") if r.vote == 1 else self.alarms[r.name]
                if a is None or channel not in a.channels:
                    continue
                if a.channel is None:
                    a.inputs.pop(channel, None)
                else:
                    a.state.restart_delays()

    def values(self, t_ns: int, channel: str, values: dict[str, float]) -> list[Transition]:
        """Values (by indicator name) of ``channel`` at ``t_ns`` against the rules watching them."""
        out: list[Transition] = []
        running = self.operating.running
        for name, value in values.items():
            for r in self.by_indicator.get(name, ()):
                a = self.alarms.get(f"{r.name}/{channel}") if r.vote == 1 else self.alarms[r.name]
                if a is None or channel not in a.channels:
                    continue
                levels = rule_levels(r, self.speed_rpm, self.zones, self.cfg.baseline(channel, name))
                a.latest[channel] = value
                a.value, a.levels = max(a.latest.values()), levels
                if not running:
                    continue
                if self.judged is not None:
                    self.judged.add(t_ns, a.id, channel, value, levels)
                exceed = self.exceed[(r.name, channel)]
                x, reached = exceed.step(value, *levels), exceed.reached
                if a.channel is None:
                    a.inputs[channel] = (x, reached)
                    x, reached = (_voted([v[k] for v in a.inputs.values()], r.vote) for k in (0, 1))
                before = a.state.level
                out += self._apply(a, t_ns, before, a.state.step(t_ns, x, reached))
        return out

    def _operate(self, t_ns: int, channel: str, values: dict[str, float],
                 speed_rpm: float | None) -> list[Transition]:
        if speed_rpm is not None:
            self.speed_rpm = speed_rpm
        op = self.cfg.operating
        if op.source == "level" and op.level_indicator in values:
            self.levels_seen[channel] = values[op.level_indicator]
        reading = {"speed": speed_rpm, "level": max(self.levels_seen.values(), default=None)}.get(op.source)
        was = self.operating.running
        self.operating.step(t_ns, reading)
        if self.resumed and reading is not None:
            self.resumed = False
            if self.operating.state == "stopped":
                return self._suppress(t_ns)
        if not was or self.operating.running:
            return []
        return self._suppress(t_ns)

    def _suppress(self, t_ns: int) -> list[Transition]:
        """Every alarm suppressed at ``t_ns`` (the machine left ``running``)."""
        out: list[Transition] = []
        for a in self.alarms.values():
            before = a.state.level
            a.inputs.clear()
            out += self._apply(a, t_ns, before, a.state.suppress(t_ns))
        for e in self.exceed.values():
            e.reset()
        return out

    def ack(self, t_ns: int, which: str | None = None, by: str | None = None) -> list[Transition]:
        """Acknowledge alarm ``which`` (None: every alarm) at ``t_ns``, by user ``by`` (None: not
        known); only an alarm showing a level not acknowledged yet is (one at normal, or
        acknowledged already, has no transition). Raises KeyError for an unknown alarm."""
        if which is not None and which not in self.alarms:
            raise KeyError(which)
        named = [self.alarms[which]] if which is not None else list(self.alarms.values())
        targets = [a for a in named if a.state.level > 0 and not a.state.acknowledged]
        out: list[Transition] = []
        for a in targets:
            before = a.state.level
            after = a.state.ack(t_ns, by)
            out.append(Transition("alarm_ack", a.id, a.channel, after, before, t_ns,
                                  f"{a.id} acknowledged{f' by {by}' if by else ''} ({LEVELS[before]}"
                                  + (f", now {LEVELS[after]})" if after != before else ")")))
            out += self._apply(a, t_ns, before, after)
        return out

    def _apply(self, a: Alarm, t_ns: int, prev: int, after: int) -> list[Transition]:
        """The transition of ``a`` from the shown level ``prev`` to ``after`` (none if equal)."""
        if after == prev:
            return []
        name = a.rule.indicator
        unit = f" {unit_of(name)}" if unit_of(name) else ""
        what = f"{name} {a.value:.4g}{unit}" if a.value is not None else name
        lv = a.levels[after - 1] if after > 0 else a.levels[prev - 1]
        said = what_is(name) + self._band_said(a, name)
        if said and said.replace(" ", "_") != name:     # kurtosis is just that
            what += f" ({said})" if after > prev else ""
        if after > prev:
            msg = (f"{a.id}: {what} reached the {LEVELS[after]} level"
                   + (f" {lv:.4g}{unit}" if lv is not None else ""))
        elif after == 0:
            msg = f"{a.id}: {LEVELS[prev]} cleared ({what})"
        else:
            msg = f"{a.id}: eased from {LEVELS[prev]} to {LEVELS[after]} ({what})"
        return [Transition(KIND[after], a.id, a.channel, after, prev, t_ns, msg)]

    def _band_said(self, a: Alarm, name: str) -> str:
        """``, 10-1000 Hz`` (of the velocity RMS: ``, of the velocity RMS over 10-1000 Hz``): the
        velocity band of the channel whose value ``a`` shows, for an alarm on ``name``
        ``velocity_rms_mm_s`` or ``zone`` (ISO 10816-3 grades the RMS over a stated band: 10-1000 Hz,
        2-1000 Hz for machines at or below 600 r/min); "" for another indicator or no band known."""
        if name not in ("velocity_rms_mm_s", "zone"):
            return ""
        ch = a.channel if a.channel is not None else max(a.latest, key=a.latest.__getitem__, default=None)
        band = self.velocity_bands.get(ch) if ch is not None else None
        if band is None:
            return ""
        hz = f"{band[0]:g}-{band[1]:g} Hz"
        return f", {hz}" if name == "velocity_rms_mm_s" else f", of the velocity RMS over {hz}"

    def shift(self, shift_ns: int) -> None:
        """The stamps were re-anchored by ``shift_ns`` (a step of the wall clock): the delays, the
        suppression times and the stamps of the alarms move with them (:meth:`AlarmState.shift`)."""
        self.operating.shift(shift_ns)
        for a in self.alarms.values():
            a.state.shift(shift_ns)

    # ---------------------------------------------------------------- output
    def table(self) -> list[dict]:
        """Every alarm's row, in configuration order."""
        return [a.row() for a in self.alarms.values()]

    def signature(self) -> tuple:
        """What a change of the table is: each alarm's shown and live level, flags and levels in
        force (a speed band, a first value), and the operating state; not the values."""
        return (self.operating.state,) + tuple(
            (a.state.level, a.state.live, a.state.latched, a.state.acknowledged, a.state.restored, a.levels)
            for a in self.alarms.values())

    def worst(self) -> Alarm | None:
        """The alarm showing the highest level (the first of them), None when all are normal."""
        top = max(self.alarms.values(), key=lambda a: a.state.level, default=None)
        return top if top is not None and top.state.level > 0 else None
