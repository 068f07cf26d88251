"""Settings of the alarm manager (``alarms``): operating states, alarm rules, learned baselines.

:class:`AlarmsConfig` holds the machine's :class:`OperatingConfig` (running or
stopped, from the shaft speed or an indicator's level, with start-up and
coast-down suppression), the :class:`AlarmRuleConfig` list (per indicator: alert
and danger levels, absolute, at an ISO 10816-3 zone boundary or k x a learned
baseline; delays, deadband, latching, N-of-M voting, level sets per speed band)
and the :class:`BaselineConfig` list that ``cmsensord calibrate`` writes.  The
manager is :mod:`cmsensord.alarms`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

from .validation import Rule, fmt_num, setting, validate

__all__ = ["AlarmsConfig", "AlarmRuleConfig", "BaselineConfig", "OperatingConfig", "SpeedBandConfig",
           "LEVEL_KEYS", "rules_levels_rise"]

_NAME: dict[str, Any] = {"pattern": r"[A-Za-z0-9_]+", "pattern_reason": "must contain only letters, digits and _"}
_INDICATOR: dict[str, Any] = {"pattern": r"[A-Za-z0-9_.]+",
                              "pattern_reason": "must be an indicator name (letters, digits, _ and .)"}
#: the three ways to give each level; at most one per level
LEVEL_KEYS = {"alert": ("alert", "alert_zone", "alert_x_baseline"),
              "danger": ("danger", "danger_zone", "danger_x_baseline")}
_ZONE = {"choices": ("B", "C", "D")}
#: the zones in their order: a zone's level is its lower boundary
ZONES = "ABCD"
#: the level settings of a rule and of its speed bands: help text and checks
_LEVEL_SETTINGS: dict[str, tuple[str, dict[str, Any]]] = {
    "alert": ("alert level [the indicator's unit]", {"ge": 0}),
    "danger": ("danger level [the indicator's unit]", {"ge": 0}),
    "alert_zone": ("alert at the lower boundary of this ISO zone (B, C or D)", _ZONE),
    "danger_zone": ("danger at the lower boundary of this ISO zone", _ZONE),
    "alert_x_baseline": ("alert at k x the learned baseline", {"gt": 0}),
    "danger_x_baseline": ("danger at k x the learned baseline", {"gt": 0}),
}


def _level(key: str) -> Any:
    """The setting ``key`` of :data:`_LEVEL_SETTINGS` (default None: not given)."""
    text, checks = _LEVEL_SETTINGS[key]
    return setting(None, text, **checks)


def _levels(need: bool) -> Rule:
    """Rule: each level given at most one way; with ``need``, at least one level given."""

    def rule(obj: Any) -> tuple[str, str, Any] | None:
        given = 0
        for keys in LEVEL_KEYS.values():
            set_ = [k for k in keys if getattr(obj, k) is not None]
            if len(set_) > 1:
                return set_[1], f"give {keys[0]} one way only (also {set_[0]} is set)", getattr(obj, set_[1])
            given += len(set_)
        if need and not given:
            return "alert", "give an alert or a danger level (alert, alert_zone, alert_x_baseline, ...)", None
        return None

    return rule


def _levels_rise(obj: Any) -> tuple[str, str, Any] | None:
    """Rule: where alert and danger are given the same way, danger is the higher level (zones by
    their order A < B < C < D); else the danger alarm would come first and the alert never."""
    for a_key, d_key in zip(LEVEL_KEYS["alert"], LEVEL_KEYS["danger"]):
        a, d = getattr(obj, a_key), getattr(obj, d_key)
        if a is None or d is None:
            continue
        if a_key == "alert_zone":
            if ZONES.index(d) <= ZONES.index(a):
                return (d_key, f"must be a zone above alert_zone = {a} (zones A < B < C < D): the alert "
                        "comes first", d)
        elif not d > a:
            return d_key, f"must be greater than {a_key} = {fmt_num(a)}: the alert comes first", d
    return None


#: indicators whose values have a top, what it is, and the absolute levels above it that never fire
_TOPS = {"severity_index": (1.0, "the severity index is 0 to 1"), "zone": (3.0, "zone is 0-3 for zones A-D")}


def _levels_reachable(obj: Any) -> tuple[str, str, Any] | None:
    """Rule: an absolute level of an indicator with a top (:data:`_TOPS`) is at most that top (in
    the rule and in each of its bands): a higher one is never reached."""
    if obj.indicator not in _TOPS:
        return None
    top, why = _TOPS[obj.indicator]
    for where, src in (("", obj), *((f"bands[{j}].", b) for j, b in enumerate(obj.bands))):
        for key in ("alert", "danger"):
            value = getattr(src, key)
            if value is not None and value > top:
                return (f"{where}{key}", f"must be <= {top:g} ({why}): a level above it is never reached",
                        value)
    return None


def _zone_needs_velocity(obj: Any) -> tuple[str, str, Any] | None:
    for key in ("alert_zone", "danger_zone"):
        if getattr(obj, key) is not None and obj.indicator != "velocity_rms_mm_s":
            return key, "an ISO zone boundary is a level of velocity_rms_mm_s only", getattr(obj, key)
    for b in obj.bands:
        for key in ("alert_zone", "danger_zone"):
            if getattr(b, key) is not None and obj.indicator != "velocity_rms_mm_s":
                return "bands", "an ISO zone boundary is a level of velocity_rms_mm_s only", getattr(b, key)
    return None


def _vote_fits(obj: Any) -> tuple[str, str, Any] | None:
    """AlarmRuleConfig: each channel listed once, and a vote of at most the channels listed."""
    for i, ch in enumerate(obj.channels):
        if ch in obj.channels[:i]:
            return (f"channels[{i}]", f"duplicate channel (also channels[{obj.channels.index(ch)}]): a rule "
                    "watches each channel once", ch)
    if obj.vote > 1 and obj.channels and obj.vote > len(obj.channels):
        return "vote", f"must be at most the {len(obj.channels)} channel(s) listed", obj.vote
    return None


@dataclass(frozen=True)
class SpeedBandConfig:
    """The alarm levels of a rule below a shaft speed (the rule's own levels apply above
    its highest band)."""

    below_rpm: float = setting(dataclasses.MISSING, "these levels apply while the speed is below this [rpm]", gt=0)
    alert: float | None = _level("alert")
    danger: float | None = _level("danger")
    alert_zone: str | None = _level("alert_zone")
    danger_zone: str | None = _level("danger_zone")
    alert_x_baseline: float | None = _level("alert_x_baseline")
    danger_x_baseline: float | None = _level("danger_x_baseline")

    _RULES: ClassVar[tuple[Rule, ...]] = (_levels(True), _levels_rise)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class AlarmRuleConfig:
    """One alarm: an indicator watched on some channels against alert and danger levels."""

    name: str = setting(dataclasses.MISSING, "alarm name (in /cm/alarms and the events)", **_NAME)
    indicator: str = setting(dataclasses.MISSING, "indicator: a /cm/<ch>/indicators name (velocity_rms_mm_s, "
                             "accel_rms, kurtosis, envelope_rms, zone, <bearing>.bpfo, band.<name>, ...), "
                             "severity_index, or order.<component> (order RMS)", **_INDICATOR)
    channels: tuple[str, ...] = setting((), "channels watched (default: every vibration channel; a bearing's "
                                        "line: the bearing's channel)")
    alert: float | None = _level("alert")
    danger: float | None = _level("danger")
    alert_zone: str | None = _level("alert_zone")
    danger_zone: str | None = _level("danger_zone")
    alert_x_baseline: float | None = _level("alert_x_baseline")
    danger_x_baseline: float | None = _level("danger_x_baseline")
    on_delay_s: float = setting(0.0, "the level must be exceeded this long before the alarm [s]", ge=0)
    off_delay_s: float = setting(0.0, "the value must stay below this long before it clears [s]", ge=0)
    deadband_pct: float = setting(5.0, "hysteresis: exceeded until below level x (1 - pct/100) [%]",
                                  ge=0, lt=100)
    latch: bool = setting(False, "the alarm stays until acknowledged (cmsensord ack)")
    vote: int = setting(1, "1: one alarm per channel; N > 1: one alarm, raised when N of the channels "
                        "exceed the level", ge=1, le=8)
    bands: tuple[SpeedBandConfig, ...] = field(default=(), metadata={"help": "level sets per speed band"})

    _RULES: ClassVar[tuple[Rule, ...]] = (_levels(True), _levels_rise, _levels_reachable, _zone_needs_velocity,
                                          _vote_fits)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class OperatingConfig:
    """Running or stopped, and when alarms are suppressed."""

    source: str = setting("none", "none (always running), speed (the shaft speed of the indicator "
                          "records) or level (an indicator's value)", choices=("none", "speed", "level"))
    running_above: float | None = setting(None, "running at or above this [rpm, or the level indicator's unit]",
                                          ge=0)
    stopped_below: float | None = setting(None, "stopped below this (default: running_above)", ge=0)
    level_indicator: str = setting("accel_rms", "the indicator of source: level", **_INDICATOR)
    startup_suppress_s: float = setting(0.0, "alarms suppressed this long after the machine starts [s]", ge=0)
    coastdown_suppress_s: float = setting(0.0, "alarms suppressed this long once the speed falls "
                                          "coastdown_drop_pct below its running value [s]", ge=0)
    coastdown_drop_pct: float = setting(10.0, "a speed drop that starts a coast-down [%]", gt=0, lt=100)

    _RULES: ClassVar[tuple[Rule, ...]] = (lambda o: _operating(o),)

    def __post_init__(self) -> None:
        validate(self)


def _operating(obj: Any) -> tuple[str, str, Any] | None:
    if obj.source != "none" and obj.running_above is None:
        return "running_above", f"needed with source: {obj.source}", None
    if obj.stopped_below is not None and obj.running_above is not None and obj.stopped_below > obj.running_above:
        return "stopped_below", f"must be <= running_above = {obj.running_above:g}", obj.stopped_below
    return None


@dataclass(frozen=True)
class BaselineConfig:
    """A healthy value of an indicator on a channel (``cmsensord calibrate`` writes them)."""

    channel: str = setting(dataclasses.MISSING, "channel name", **_NAME)
    indicator: str = setting(dataclasses.MISSING, "indicator name", **_INDICATOR)
    value: float = setting(dataclasses.MISSING, "its healthy value [the indicator's unit]", ge=0)

    def __post_init__(self) -> None:
        validate(self)


def _unique_rules(obj: Any) -> tuple[str, str, Any] | None:
    names = [r.name for r in obj.rules]
    for i, n in enumerate(names):
        if n in names[:i]:
            return f"rules[{i}].name", "duplicate alarm name", n
    seen: dict[tuple[str, str], int] = {}
    for i, b in enumerate(obj.baselines):
        j = seen.setdefault((b.channel, b.indicator), i)
        if j != i:
            return (f"baselines[{i}]", f"duplicate baseline of {b.indicator} on {b.channel} (also baselines[{j}])",
                    b.value)
    return None


@dataclass(frozen=True)
class AlarmsConfig:
    """The alarm manager: /cm/alarms, alarm events, ``cmsensord ack`` and ``status``."""

    enabled: bool = setting(True, "run the alarm manager (it does nothing without rules)")
    operating: OperatingConfig = field(default_factory=OperatingConfig, metadata={"help": "operating states"})
    rules: tuple[AlarmRuleConfig, ...] = field(default=(), metadata={"help": "alarm rules"})
    baselines: tuple[BaselineConfig, ...] = field(default=(), metadata={"help": "learned baselines"})

    _RULES: ClassVar[tuple[Rule, ...]] = (_unique_rules,)

    def __post_init__(self) -> None:
        validate(self)

    def baseline(self, channel: str, indicator: str) -> float | None:
        """The learned baseline of ``indicator`` on ``channel`` (None: not learned)."""
        return next((b.value for b in self.baselines if b.channel == channel and b.indicator == indicator), None)


def _mixed_levels_rise(src: Any, zones: tuple[float, float, float], machine: str) -> tuple[str, str, Any] | None:
    """(key, reason, value) when one of ``src``'s levels is absolute and the other a zone boundary
    (``zones``: B, C, D's lower boundaries of ``machine``) and danger is not the higher."""
    pairs = (("alert", "danger_zone"), ("alert_zone", "danger"))
    for a_key, d_key in pairs:
        a, d = getattr(src, a_key), getattr(src, d_key)
        if a is None or d is None:
            continue
        a_lv = a if a_key == "alert" else zones[ZONES.index(a) - 1]
        d_lv = d if d_key == "danger" else zones[ZONES.index(d) - 1]
        if not d_lv > a_lv:
            zone, lv = (d, d_lv) if d_key == "danger_zone" else (a, a_lv)
            return (d_key, f"must be above the alert level: {a_key} {a} against {d_key} {d} (zone {zone} "
                    f"begins at {lv:g} mm/s for {machine}): the alert comes first", d)
    return None


def _level_sets(rules: tuple[AlarmRuleConfig, ...]) -> list[tuple[str, Any]]:
    """Every rule and speed band, with its key path."""
    return [(f"alarms.rules[{i}]", r) for i, r in enumerate(rules)] + [
        (f"alarms.rules[{i}].bands[{j}]", b) for i, r in enumerate(rules) for j, b in enumerate(r.bands)]


def rules_levels_rise(cfg: Any) -> tuple[str, str, Any] | None:
    """Config rule: a rule (or speed band) with an absolute alert and a danger zone, or the reverse,
    has danger above alert at the configured machine group's and foundation's zone boundaries."""
    mixed = [(where, src) for where, src in _level_sets(cfg.alarms.rules)
             if (src.alert is not None and src.danger_zone is not None)
             or (src.alert_zone is not None and src.danger is not None)]
    if not mixed:                       # (the zone table's module loads numpy)
        return None
    from cmsensord.dsp.indicators.iso_zones import boundaries

    ic = cfg.indicators
    zones = boundaries(ic.machine_group, ic.foundation)
    for where, src in mixed:
        found = _mixed_levels_rise(src, zones, f"machine group {ic.machine_group}, {ic.foundation}")
        if found is not None:
            return f"{where}.{found[0]}", found[1], found[2]
    return None
