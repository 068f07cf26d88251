"""The indicator names an alarm rule can watch, and the configuration rule that refuses any other.

A rule watches a value under its stable name (:mod:`cmsensord.monitor.alarms` reads them):
an indicator record's :data:`RECORD_VALUES` (``zone`` as 0-3), a configured bearing's lines
(``<bearing>.bpfo``, ... and their ``_2x``: :data:`BEARING_LINES`), a configured band
(``band.<name>``), the severity index (``severity_index``) or a configured order component's
RMS (``order.<component>``).  A rule naming anything else would never see a value, so it
never fires: :func:`rules_see_indicators` refuses it with the names it could mean (and
``alarms.operating.level_indicator``, which an indicator record must carry, likewise).
"""

from __future__ import annotations

from typing import Any

from .validation import did_you_mean

__all__ = ["RECORD_VALUES", "BEARING_LINES", "indicator_names", "unknown_indicator", "rules_see_indicators"]

#: the scalar values of a /cm/<ch>/indicators record a rule can watch (zone A-D as 0-3)
RECORD_VALUES = ("velocity_rms_mm_s", "accel_rms", "accel_peak", "crest_factor", "kurtosis",
                 "envelope_rms", "zone")
#: a bearing's lines: each defect frequency and its second harmonic
BEARING_LINES = tuple(f"{d}{h}" for d in ("ftf", "bpfo", "bpfi", "bsf") for h in ("", "_2x"))


def indicator_names(cfg: Any, *, records_only: bool = False) -> list[str]:
    """Every name a rule of ``cfg`` can watch (``records_only``: those of the indicator records)."""
    names = list(RECORD_VALUES)
    names += [f"{b.name}.{line}" for b in cfg.bearings for line in BEARING_LINES]
    names += [f"band.{b.name}" for b in cfg.indicators.bands]
    if not records_only:
        names += ["severity_index"] + [f"order.{c.name}" for c in cfg.orders.components]
    return names


def _listed(names: list[str]) -> str:
    return ", ".join(names) if names else "none configured"


def _what_is_missing(name: str, cfg: Any) -> str | None:
    """Why a ``band.``, ``order.`` or ``<bearing>.`` name is not one, the configured ones listed (a
    bearing's: ending in ``;`` for the closest name); None: not of those forms."""
    kind, dot, rest = name.partition(".")
    if kind == "band" and dot:
        bands = [b.name for b in cfg.indicators.bands]
        return f"no band {rest!r} in indicators.bands (bands: {_listed(bands)})"
    if kind == "order" and dot:
        comps = [c.name for c in cfg.orders.components]
        return f"no component {rest!r} in orders.components (components: {_listed(comps)})"
    bearing, dot, line = name.rpartition(".")
    if not dot:
        return None
    bearings = [b.name for b in cfg.bearings]
    if bearing not in bearings:
        return (f"names no bearing {bearing!r} (bearings: {_listed(bearings)}): add it under bearings "
                "(name, channel, geometry) or name one of them;")
    return f"{line!r} is not a line of bearing {bearing} (lines: {', '.join(BEARING_LINES)});"


def unknown_indicator(name: str, cfg: Any, *, records_only: bool = False,
                      effect: str = "a rule on it never fires") -> str | None:
    """Why ``name`` is no indicator a rule of ``cfg`` can watch (``records_only``: no indicator
    record carries), with the closest valid name or the valid ones, and ``effect``; None when it
    is one."""
    known = indicator_names(cfg, records_only=records_only)
    if name in known:
        return None
    hint = did_you_mean(name, known)
    missing = None if records_only else _what_is_missing(name, cfg)
    if missing is not None:
        return f"{missing} {hint}" if missing.endswith(";") and hint else missing.rstrip(";")
    if hint is None:
        more = "" if records_only else ", <bearing>.<line>, band.<name>, severity_index, order.<component>"
        hint = f"indicators: {', '.join(RECORD_VALUES)}{more}"
    return f"unknown indicator ({hint}): {effect}"


def rules_see_indicators(cfg: Any) -> tuple[str, str, Any] | None:
    """Config rule: every alarm rule's indicator (and ``alarms.operating.level_indicator``) is one
    that the chain writes under this configuration."""
    for i, r in enumerate(cfg.alarms.rules):
        why = unknown_indicator(r.indicator, cfg)
        if why is not None:
            return f"alarms.rules[{i}].indicator", why, r.indicator
    op = cfg.alarms.operating
    if op.source == "level":
        why = unknown_indicator(op.level_indicator, cfg, records_only=True,
                                effect="the machine would never be seen running")
        if why is not None:
            return "alarms.operating.level_indicator", why, op.level_indicator
    return None
