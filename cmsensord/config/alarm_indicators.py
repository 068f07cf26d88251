"""The indicator names an alarm rule can watch, and the configuration rule that refuses any other.

A rule watches a value under its stable name (:mod:`cmsensord.monitor.alarms` reads them):
an indicator record's :data:`RECORD_VALUES` (``zone`` as 0-3), a configured bearing's lines
(``<bearing>.bpfo``, ... and their ``_2x``: :data:`BEARING_LINES`; each line's amplitude, and
with ``_ratio`` how far it stands out of the envelope spectrum around it: :data:`BEARING_VALUES`), a configured band
(``band.<name>``), the severity index (``severity_index``) or a configured order component's
RMS (``order.<component>``).  The indicator records are written only with ``indicators.enabled``,
the orders only with ``orders.enabled``.  A rule naming anything else would never see a value,
so it never fires: :func:`rules_see_indicators` refuses it with the names it could mean (and
``alarms.operating.level_indicator``, which an indicator record must carry, likewise; and
``source: speed``, whose speed comes with the indicator records).  A learned baseline
(``alarms.baselines``) must name an indicator a rule could watch under the configured bearings,
bands and components, else no rule can use it.

:func:`unit_of` and :func:`what_is` give each name's unit and what it is, for the lines that quote
a value (alarm events, ``cmsensord status``): the one table of them, :data:`QUANTITIES`.

An RMS-mode board's indicator records carry ``accel_rms`` only (:data:`RMS_MODE_VALUES`, beside
the severity index); :func:`raw_only_rules` names the rules that then never fire.
"""

from __future__ import annotations

from typing import Any

from .validation import did_you_mean

__all__ = ["RECORD_VALUES", "BEARING_LINES", "BEARING_VALUES", "RMS_MODE_VALUES", "indicator_names",
           "unknown_indicator", "rules_see_indicators", "raw_only_rules", "QUANTITIES", "unit_of", "what_is"]

#: the scalar values of a /cm/<ch>/indicators record a rule can watch (zone A-D as 0-3)
RECORD_VALUES = ("velocity_rms_mm_s", "accel_rms", "accel_peak", "crest_factor", "kurtosis",
                 "envelope_rms", "zone")
#: a bearing's lines: each defect frequency and its second harmonic
BEARING_LINES = tuple(f"{d}{h}" for d in ("ftf", "bpfo", "bpfi", "bsf") for h in ("", "_2x"))
#: a bearing's values a rule can watch: each line's amplitude [m/s^2] (``bpfo``) and its ratio to
#: the median of the envelope spectrum from 0.5 to 1.5 x the line (``bpfo_ratio``, unitless)
BEARING_VALUES = BEARING_LINES + tuple(f"{line}_ratio" for line in BEARING_LINES)
#: (unit, what it is) of each name a rule can watch, by its form: a record value's own name;
#: ``<bearing>.<line>``, ``<bearing>.<line>_ratio``, ``band.<name>``, ``order.<name>`` by the key
#: in brackets ({b} the bearing, {line} the line, {n} the band or component); "" unitless
QUANTITIES = {
    "velocity_rms_mm_s": ("mm/s", "velocity RMS"),
    "accel_rms": ("m/s²", "acceleration RMS"),
    "accel_peak": ("m/s²", "acceleration 0-pk"),
    "crest_factor": ("", "crest factor"),
    "kurtosis": ("", "kurtosis"),
    "envelope_rms": ("m/s²", "envelope RMS"),
    "zone": ("", "ISO 10816-3 zone, A-D as 0-3"),
    "severity_index": ("", "severity index, 0-1"),
    "[line]": ("m/s²", "{line} of bearing {b}, envelope 0-pk"),
    "[ratio]": ("", "{line} of bearing {b} over the envelope spectrum around it"),
    "[band]": ("m/s²", "acceleration RMS in band {n}"),
    "[order]": ("m/s²", "order {n} RMS"),
}


def _quantity(name: str) -> tuple[str, str]:
    """(unit, what it is) of indicator ``name`` from :data:`QUANTITIES`; ("", "") for none of its forms."""
    if name in QUANTITIES:
        return QUANTITIES[name]
    head, _, rest = name.partition(".")
    if head in ("band", "order") and rest:
        unit, what = QUANTITIES[f"[{head}]"]
        return unit, what.format(n=rest)
    bearing, _, line = name.rpartition(".")
    if bearing and line in BEARING_VALUES:
        key = "[ratio]" if line.endswith("_ratio") else "[line]"
        base = line.removesuffix("_ratio")
        shown = base.upper() if "_" not in base else f"{base.split('_')[1]} {base.split('_')[0].upper()}"
        unit, what = QUANTITIES[key]
        return unit, what.format(line=shown, b=bearing)
    return "", ""


def unit_of(name: str) -> str:
    """The unit of indicator ``name`` (``mm/s``, ``m/s²``; "" when it has none)."""
    return _quantity(name)[0]


def what_is(name: str) -> str:
    """What indicator ``name`` is, in words (``velocity RMS``, ``BPFO of bearing de, envelope 0-pk``)."""
    return _quantity(name)[1]


#: the values a rule can watch on an RMS-mode board: its records' overall RMS, the severity index
RMS_MODE_VALUES = ("accel_rms", "severity_index")


def indicator_names(cfg: Any, *, records_only: bool = False, written: bool = True) -> list[str]:
    """Every name a rule of ``cfg`` can watch (``records_only``: those of the indicator records);
    ``written``: only those the chain writes, none of the records with ``indicators.enabled``
    false, no order with ``orders.enabled`` false."""
    names = []
    if cfg.indicators.enabled or not written:
        names += list(RECORD_VALUES)
        names += [f"{b.name}.{line}" for b in cfg.bearings for line in BEARING_VALUES]
        names += [f"band.{b.name}" for b in cfg.indicators.bands]
    if not records_only:
        names += ["severity_index"]
        if cfg.orders.enabled or not written:
            names += [f"order.{c.name}" for c in cfg.orders.components]
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
    return (f"{line!r} is not a line of bearing {bearing} (lines: {', '.join(BEARING_LINES)}; each also "
            "as <line>_ratio);")


def unknown_indicator(name: str, cfg: Any, *, records_only: bool = False, written: bool = True,
                      effect: str = "a rule on it never fires") -> str | None:
    """Why ``name`` is no indicator a rule of ``cfg`` can watch (``records_only``: no indicator
    record carries; ``written``: as :func:`indicator_names`), with the closest valid name or the
    valid ones, or the setting that turns it off, and ``effect``; None when it is one."""
    known = indicator_names(cfg, records_only=records_only, written=written)
    if name in known:
        return None
    if name in indicator_names(cfg, records_only=records_only, written=False):
        off = ("orders.enabled is false: no order is tracked" if name.startswith("order.")
               else "indicators.enabled is false: no indicator record is written")
        return f"{off}, {effect}"
    hint = did_you_mean(name, indicator_names(cfg, records_only=records_only, written=False))
    missing = None if records_only else _what_is_missing(name, cfg)
    if missing is not None:
        return f"{missing} {hint}" if missing.endswith(";") and hint else missing.rstrip(";")
    if hint is None:
        more = "" if records_only else ", <bearing>.<line>, band.<name>, severity_index, order.<component>"
        hint = f"indicators: {', '.join(RECORD_VALUES)}{more}"
    return f"unknown indicator ({hint}): {effect}"


def rules_see_indicators(cfg: Any) -> tuple[str, str, Any] | None:
    """Config rule: every alarm rule's indicator (and ``alarms.operating.level_indicator``, the
    speed of ``source: speed``) is one that the chain writes under this configuration; every
    learned baseline's, one a rule could watch."""
    for i, r in enumerate(cfg.alarms.rules):
        why = unknown_indicator(r.indicator, cfg)
        if why is not None:
            return f"alarms.rules[{i}].indicator", why, r.indicator
    if not cfg.orders.enabled:
        for i, c in enumerate(cfg.orders.components):
            if c.alarm_rms is not None:
                return (f"orders.components[{i}].alarm_rms", "orders.enabled is false: no order is tracked, "
                        "this order alarm never fires", c.alarm_rms)
    op = cfg.alarms.operating
    if op.source == "level":
        why = unknown_indicator(op.level_indicator, cfg, records_only=True,
                                effect="the machine would never be seen running")
        if why is not None:
            return "alarms.operating.level_indicator", why, op.level_indicator
    if op.source == "speed" and not cfg.indicators.enabled:
        return ("alarms.operating.source", "the shaft speed comes with the indicator records, and "
                "indicators.enabled is false: the machine would never be seen running", op.source)
    for i, b in enumerate(cfg.alarms.baselines):
        why = unknown_indicator(b.indicator, cfg, written=False, effect="no rule can use this baseline")
        if why is not None:
            return f"alarms.baselines[{i}].indicator", why, b.indicator
    return None


def raw_only_rules(rules: Any) -> list[str]:
    """``<rule> (<indicator>)`` of each of ``rules`` whose indicator an RMS-mode board does not
    give (:data:`RMS_MODE_VALUES`): such a rule never fires there."""
    return [f"{r.name} ({r.indicator})" for r in rules if r.indicator not in RMS_MODE_VALUES]
