"""The alarm state an operator relies on, as a saved record, and putting it back (a restart).

:func:`snapshot` gives, per alarm showing a level or holding a latch, what an operator
relies on: the shown, live and latched level, since when the shown level holds, whether it
is acknowledged (when, by whom), and the rule it was judged by (its name, indicator, latch
and level settings, with what those levels are resolved against: the learned baseline of
each channel for levels given as k x a baseline, the zone boundaries for levels at a zone
boundary), and the alert and danger levels in force at its last value (``alert_level``,
``danger_level``; a speed band's, a channel's baseline level), which the alarm table shows
until data comes (:func:`saved_rows`).  :func:`check` refuses a record that is not such a one
(ValueError), a stamp outside 1970..2262 (:data:`MAX_STAMP_NS`) included.

:func:`resume` puts saved records back into a new manager.  A saved alarm is restored when
the manager has an alarm of that name on the same rule and indicator, and the rule still
latches if the saved alarm was latched: its latch (level and since when), its
acknowledgement, and its live level as a restored level that the rule confirms or drops
(:mod:`.state`): the same episode is not raised again, an acknowledged one stays
acknowledged.  When the rule's levels changed since (its settings, or the baseline or zone
boundaries they are resolved against: a new calibration), a latch is restored (the levels
then were exceeded: someone still has to look) but the live level is judged afresh; a saved
alarm with no latch is then not restored.  A record without the baselines or zone
boundaries (written by a daemon that did not save them) is taken as resolved against the
present ones.  Anything not restored is said: one :class:`Resumed` record per saved alarm,
restored or not.  Times are stamps [ns] (of the live stream: the wall clock).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from cmsensord.config.alarms import LEVEL_KEYS, AlarmRuleConfig, AlarmsConfig

from .manager import Alarm, AlarmManager
from .state import LEVELS

__all__ = ["Resumed", "snapshot", "check", "resume", "level_settings", "resolved_against", "MAX_STAMP_NS",
           "latch_or_ack_changed"]

#: the latest stamp a record may hold: the ns an int64 holds (2262-04-11)
MAX_STAMP_NS = 2**63 - 1
_LEVEL_KEYS = ("alert", "danger", "alert_zone", "danger_zone", "alert_x_baseline", "danger_x_baseline")


@dataclass(frozen=True)
class Resumed:
    """What became of one saved alarm: restored or not, and the line that says it."""

    alarm: str
    channel: str | None
    restored: bool
    message: str


def level_settings(rule: AlarmRuleConfig, resolved: dict[str, Any] | None = None) -> dict[str, Any]:
    """The rule's level settings as JSON gives them back (those given, and its speed bands), with
    ``resolved`` (:func:`resolved_against`)."""
    out: dict[str, Any] = {k: getattr(rule, k) for k in _LEVEL_KEYS if getattr(rule, k) is not None}
    if rule.bands:
        out["bands"] = [{k: v for k, v in dataclasses.asdict(b).items() if v is not None} for b in rule.bands]
    return json.loads(json.dumps({**out, **(resolved or {})}))


def resolved_against(mgr: AlarmManager, a: Alarm) -> dict[str, Any]:
    """What the levels of ``a``'s rule are resolved against: ``baselines``, the learned baseline
    of its indicator on each of its channels (None: not learned), when a level is given as k x a
    baseline; ``zone_boundaries`` [mm/s], when one is at a zone boundary."""
    srcs = (a.rule, *a.rule.bands)
    out: dict[str, Any] = {}
    if any(getattr(src, k) is not None for src in srcs for k in ("alert_x_baseline", "danger_x_baseline")):
        out["baselines"] = {ch: mgr.cfg.baseline(ch, a.rule.indicator) for ch in a.channels}
    if any(getattr(src, k) is not None for src in srcs for k in ("alert_zone", "danger_zone")):
        out["zone_boundaries"] = [float(z) for z in mgr.zones]
    return out


def snapshot(mgr: AlarmManager) -> dict[str, dict[str, Any]]:
    """The saved record of each alarm showing a level or holding a latch, by alarm name (its live
    level: a restored one the rule has not confirmed yet counts, so a second restart keeps it, and
    so does an acknowledged one held while its on-delay runs)."""
    out: dict[str, dict[str, Any]] = {}
    for a in mgr.alarms.values():
        s = a.state
        if s.level == 0 and s.latched == 0:
            continue
        live = max(s.live, s.restored, s.latched if s.acknowledged else 0)
        rec: dict[str, Any] = {"rule": a.rule.name, "indicator": a.rule.indicator, "latch": a.rule.latch,
                               "levels": level_settings(a.rule, resolved_against(mgr, a)), "level": LEVELS[s.level],
                               "live": LEVELS[live], "latched": LEVELS[s.latched],
                               "acknowledged": s.acknowledged}
        for key, value in (("since_ns", s.changed_ns), ("acked_ns", s.acked_ns), ("acked_by", s.acked_by),
                           ("alert_level", a.levels[0]), ("danger_level", a.levels[1])):
            if value is not None:
                rec[key] = value
        out[a.id] = rec
    return out


#: what a saved alarm keeps that its next values cannot give back: the latch and the acknowledgement
_LASTING = (("latched", "normal"), ("acknowledged", False), ("acked_ns", None), ("acked_by", None))


def latch_or_ack_changed(old: dict[str, dict[str, Any]], new: dict[str, dict[str, Any]]) -> bool:
    """True when an alarm's latch or acknowledgement differs between two snapshots (an alarm
    absent from one counts as normal, not latched, not acknowledged); False when only levels
    that the next values judge again changed."""
    for name in old.keys() | new.keys():
        a, b = old.get(name, {}), new.get(name, {})
        if any(a.get(k, d) != b.get(k, d) for k, d in _LASTING):
            return True
    return False


def check(alarms: Any) -> dict[str, dict[str, Any]]:
    """``alarms`` if it is a mapping of alarm names to saved records; ValueError naming what is
    wrong otherwise."""
    if not isinstance(alarms, dict):
        raise ValueError("'alarms' is not an object")
    want = {"rule": str, "indicator": str, "latch": bool, "levels": dict, "acknowledged": bool}
    for name, rec in alarms.items():
        if not isinstance(rec, dict):
            raise ValueError(f"alarm {name!r} is not an object")
        for key, kind in want.items():
            if not isinstance(rec.get(key), kind):
                raise ValueError(f"alarm {name!r}: {key} missing or not a {kind.__name__}")
        for key in ("level", "live", "latched"):
            if rec.get(key) not in LEVELS:
                raise ValueError(f"alarm {name!r}: {key} is not one of {', '.join(LEVELS)}")
        for key, kind in (("since_ns", int), ("acked_ns", int), ("acked_by", str)):
            if key in rec and (not isinstance(rec[key], kind) or isinstance(rec[key], bool)):
                raise ValueError(f"alarm {name!r}: {key} is not a {kind.__name__}")
        for key in ("since_ns", "acked_ns"):
            if key in rec and not 0 <= rec[key] <= MAX_STAMP_NS:
                raise ValueError(f"alarm {name!r}: {key} {rec[key]} is out of range (a stamp in ns, 1970 to 2262)")
        for key in ("alert_level", "danger_level"):
            if key in rec and (not isinstance(rec[key], (int, float)) or isinstance(rec[key], bool)
                               or not math.isfinite(rec[key])):
                raise ValueError(f"alarm {name!r}: {key} is not a finite number")
    return alarms


def when(stamp_ns: int) -> str:
    """A stamp as local date and time to the second."""
    return datetime.fromtimestamp(stamp_ns // 1_000_000_000).strftime("%Y-%m-%d %H:%M:%S")


def describe(name: str, rec: dict[str, Any]) -> str:
    """One saved alarm in words: ``sev/ch0: danger latched since 2026-11-30 13:20:05 (not acknowledged)``."""
    text = f"{name}: {rec['level']}" + (" latched" if rec["latched"] != "normal" else "")
    if "since_ns" in rec:
        text += f" since {when(rec['since_ns'])}"
    if rec["live"] != rec["level"]:
        text += f", {rec['live']} at the stop"
    if not rec["acknowledged"]:
        return text + " (not acknowledged)"
    ack = " ".join(["acknowledged", *((when(rec["acked_ns"]),) if "acked_ns" in rec else ()),
                    *((f"by {rec['acked_by']}",) if "acked_by" in rec else ())])
    return f"{text} ({ack})"


def _changed(old: dict[str, Any], new: dict[str, Any]) -> str:
    """How the levels ``new`` differ from the saved ``old`` (empty: not at all): the settings, and
    what they are resolved against where both hold it."""
    keys = [k for k in (*_LEVEL_KEYS, "bands") if old.get(k) != new.get(k)]
    out = [f"{k} {json.dumps(old.get(k))} -> {json.dumps(new.get(k))}" for k in keys]
    was, now = old.get("baselines"), new.get("baselines")
    if isinstance(was, dict) and isinstance(now, dict):
        out += [f"baseline on {ch} {_number(was.get(ch))} -> {_number(now.get(ch))}"
                for ch in dict.fromkeys([*was, *now]) if was.get(ch) != now.get(ch)]
    was, now = old.get("zone_boundaries"), new.get("zone_boundaries")
    if was is not None and now is not None and was != now:
        out.append(f"zone boundaries {_number(was)} -> {_number(now)} mm/s")
    return ", ".join(out)


def _number(x: Any) -> str:
    """A saved baseline (none: not learned) or zone boundaries (B/C/D) as the messages show them."""
    if isinstance(x, list):
        return "/".join(_number(v) for v in x)
    return "none" if x is None else json.dumps(x)


def _refused(mgr: AlarmManager, name: str, rec: dict[str, Any]) -> str | None:
    """Why saved alarm ``name`` cannot go back into ``mgr``'s alarm of that name, or None."""
    a = mgr.alarms.get(name)
    if a is None:
        same = [x for x in mgr.alarms.values() if x.rule.name == rec["rule"]]
        if not same:
            return f"the configuration has no rule {rec['rule']} now"
        watched = dict.fromkeys(ch for x in same for ch in x.channels)
        return (f"rule {rec['rule']} now makes no alarm {name} (it watches {', '.join(watched)}, "
                f"vote {same[0].rule.vote})")
    if a.rule.name != rec["rule"]:
        return f"alarm {name!r} is now of rule {a.rule.name!r}, not {rec['rule']!r}"
    if a.rule.indicator != rec["indicator"]:
        return f"rule {a.rule.name} now watches {a.rule.indicator}, not {rec['indicator']}"
    if rec["latched"] != "normal" and not a.rule.latch:
        return f"rule {a.rule.name} no longer latches (latch: false)"
    return None


def resume(mgr: AlarmManager, saved: dict[str, dict[str, Any]]) -> list[Resumed]:
    """Put ``saved`` (by :func:`check`) back into ``mgr`` (see module docstring): what became of each."""
    out: list[Resumed] = []
    for name, rec in saved.items():
        a = mgr.alarms.get(name)
        said = describe(name, rec)
        why = _refused(mgr, name, rec)
        changed = (_changed(rec["levels"], level_settings(a.rule, resolved_against(mgr, a)))
                   if a is not None and why is None else "")
        if changed and rec["latched"] == "normal":
            why = f"its levels changed since ({changed}): judged afresh against them"
        if a is None or why is not None:
            out.append(Resumed(name, a.channel if a else None, False, f"{said} not restored: {why}"))
            continue
        live = 0 if changed else LEVELS.index(rec["live"])
        a.state.resume(live, LEVELS.index(rec["latched"]), rec["acknowledged"], rec.get("since_ns"),
                       (rec.get("acked_ns"), rec.get("acked_by")))
        mgr.resumed = mgr.resumed or live > 0
        note = f"; its levels changed since ({changed}): the latch is kept, the value judged afresh" if changed else ""
        out.append(Resumed(name, a.channel, True, said + note))
    return out


def shown(rec: dict[str, Any]) -> str:
    """The level a saved record shows: its latch, else its level."""
    return LEVELS[max(LEVELS.index(rec["level"]), LEVELS.index(rec["latched"]))]


def _saved_level(rec: dict[str, Any], which: str) -> float | str | None:
    """The ``which`` (alert, danger) level of a saved alarm as the table shows it: the one in
    force at its last value when saved, else the one its settings give with what they were resolved
    against (a zone boundary, its channel's baseline), else what it depends on (``by speed``: a
    rule with speed bands; ``2xbase``, ``zone C``: a baseline or zone boundaries not saved); None:
    no such level (none given, or its baseline not learned)."""
    if f"{which}_level" in rec:
        return float(rec[f"{which}_level"])
    levels = rec["levels"]
    value, zone, k = (levels.get(key) for key in LEVEL_KEYS[which])
    if levels.get("bands"):
        return "by speed"
    if isinstance(value, (int, float)):
        return float(value)
    bounds, baselines = levels.get("zone_boundaries"), levels.get("baselines")
    if zone in ("B", "C", "D"):
        ok = isinstance(bounds, list) and len(bounds) == 3 and all(isinstance(b, (int, float)) for b in bounds)
        return float(bounds["BCD".index(zone)]) if ok else f"zone {zone}"
    if isinstance(k, (int, float)):
        # the baseline of each of the alarm's channels (None: not learned, no level): one, or a
        # voting alarm's, all the same
        base = list(baselines.values()) if isinstance(baselines, dict) else []
        one = base[0] if base and all(b == base[0] for b in base) else ""
        if one is None:
            return None
        return k * one if isinstance(one, (int, float)) and not isinstance(one, bool) else f"{k:g}xbase"
    return None


def _as_configured(name: str, rec: dict[str, Any], cfg: AlarmsConfig) -> dict[str, Any] | None:
    """``rec`` with the levels the configuration ``cfg`` gives its rule now: itself when the rule's
    level settings and the baselines they are resolved against are those saved; else its levels
    replaced by the rule's (its saved levels in force dropped: the rule was edited between the
    runs, and its next value is judged against the new ones); None when ``cfg`` has no rule of that
    name on that indicator (the alarm is not restored: it has no level)."""
    rule = next((r for r in cfg.rules if r.name == rec["rule"]), None)
    if rule is None or rule.indicator != rec["indicator"]:
        return None
    saved = rec["levels"]
    resolved: dict[str, Any] = {}
    keys = ("alert_x_baseline", "danger_x_baseline")
    if any(getattr(src, k) is not None for src in (rule, *rule.bands) for k in keys):
        was = saved.get("baselines")
        channels = list(was) if isinstance(was, dict) and was else [name.rpartition("/")[2]]
        resolved["baselines"] = {ch: cfg.baseline(ch, rule.indicator) for ch in channels}
    if "zone_boundaries" in saved:
        resolved["zone_boundaries"] = saved["zone_boundaries"]
    now = level_settings(rule, resolved)
    # an older file holds no baselines: what it holds is compared
    compared = (*_LEVEL_KEYS, "bands", *(["baselines"] if "baselines" in saved else []))
    if all(now.get(k) == saved.get(k) for k in compared):
        return rec
    return {k: v for k, v in rec.items() if k not in ("alert_level", "danger_level")} | {"levels": now}


def saved_rows(saved: dict[str, dict[str, Any]], cfg: AlarmsConfig | None = None) -> list[dict[str, Any]]:
    """Rows of the alarm table for saved records not put back yet (no data has come): flag
    ``saved``; no ``live`` level (with no value yet it is not known: absent, as every value not
    known); the alert and danger levels as :func:`_saved_level` gives them (``alert_level``,
    ``danger_level`` a number as a live row's; a text, what it depends on, as ``alert_on``,
    ``danger_on``), under the configuration ``cfg`` when given (:func:`_as_configured`: a rule
    edited between the runs shows its levels now, a rule gone none)."""
    rows = []
    for name, saved_rec in saved.items():
        now = saved_rec if cfg is None else _as_configured(name, saved_rec, cfg)
        rec = saved_rec if now is None else now
        row = {"id": name, "rule": rec["rule"], "indicator": rec["indicator"], "level": shown(rec),
               "latched": rec["latched"] != "normal", "acknowledged": rec["acknowledged"], "saved": True}
        for which in ("alert", "danger") if now is not None else ():
            lv = _saved_level(rec, which)
            if lv is not None:
                row[f"{which}_level" if isinstance(lv, float) else f"{which}_on"] = \
                    round(lv, 9) if isinstance(lv, float) else lv
        if "since_ns" in rec:
            row["since"] = {"sec": rec["since_ns"] // 1_000_000_000, "nsec": rec["since_ns"] % 1_000_000_000}
        rows.append(row)
    return rows


def ack_saved(saved: dict[str, dict[str, Any]], which: str | None, t_ns: int,
              by: str | None) -> list[tuple[str, str, str]]:
    """Acknowledge saved records before they are put back, as :meth:`AlarmState.ack` would: the
    latch drops to the level active at the stop, acknowledged when that is above normal, else the
    record goes. ``which``: a name (KeyError if not saved) or None (each not acknowledged yet).
    Returns (name, level before, level after) of each."""
    if which is not None and which not in saved:
        raise KeyError(which)
    names = [which] if which is not None else [n for n, r in saved.items() if not r["acknowledged"]]
    out = []
    for name in names:
        rec = saved[name]
        before = shown(rec)
        rec["latched"] = "normal"
        if rec["live"] == "normal":
            del saved[name]
        else:
            rec.update(level=rec["live"], acknowledged=True, acked_ns=t_ns,
                       **({"acked_by": by} if by is not None else {}))
        out.append((name, before, rec["live"]))
    return out
