"""What an indicator chain says once about a channel's bearing lines, with its first record.

:func:`line_notes` gives, per bearing of a record, a ``lines_unresolved`` event (a warning) for the
lines its envelope spectrum's bins do not resolve (:mod:`cmsensord.dsp.indicators.resolution`), the
first time that set of lines is, a ``band_too_narrow`` event (a warning) for the lines past the
envelope spectrum, which reaches about the envelope band's width, and a ``line_harmonics`` event
(a warning) when a line's window holds the third harmonic of another defect frequency of the bearing
(:func:`~cmsensord.dsp.indicators.resolution.harmonic_overlaps`: at every speed alike, so once per
channel and bearing); each names the alarm rules on those lines (their amplitudes and ratios).
"""

from __future__ import annotations

from cmsensord.config import Config
from cmsensord.dsp.indicators import IndicatorRecord, Setup
from cmsensord.dsp.indicators.resolution import harmonic_line, harmonic_overlaps, line_freqs, unresolved_line
from cmsensord.monitor.events import Event

__all__ = ["line_notes"]


def line_notes(cfg: Config, channel: str, r: IndicatorRecord, setup: Setup, df: float, stamp: int,
               told: set, longest_s: float) -> list[Event]:
    """A ``lines_unresolved`` event (a warning) for each bearing of record ``r`` of ``channel``
    with lines its envelope spectrum's bins of ``df`` Hz do not resolve, the first time that
    set of lines is (``told``: the (channel, bearing, lines) said already): the one line of
    :func:`~cmsensord.dsp.indicators.resolution.unresolved_line`, naming the rules on them
    (``longest_s``: the longest record the set-up can have); then those of :func:`_harmonic_notes`."""
    out = []
    for b in r.bearings:
        key = (channel, b.name, b.unresolved)
        if not b.unresolved or b.freqs is None or key in told:
            continue
        told.add(key)
        names = {f"{b.name}.{k}{ratio}" for k in b.unresolved for ratio in ("", "_ratio")}
        rules = tuple(dict.fromkeys(rule.name for rule in cfg.alarms.rules if rule.indicator in names
                                    and (not rule.channels or channel in rule.channels)))
        text = unresolved_line(b.name, channel, b.unresolved, line_freqs(b.freqs), setup.slip, df, rules,
                               longest_s)
        out.append(Event("lines_unresolved", channel, text, stamp,
                         {"details": {"bearing": b.name, "lines": list(b.unresolved), "bin_hz": round(float(df), 9)}}))
    return out + _beyond_notes(cfg, channel, r, stamp, told) + _harmonic_notes(cfg, channel, r, setup, stamp, told)


def _rules_on(cfg: Config, channel: str, bearing: str, lines: tuple[str, ...]) -> tuple[str, ...]:
    """The alarm rules of ``cfg`` on ``channel`` that watch one of ``lines`` of ``bearing`` (their
    amplitudes or ratios)."""
    names = {f"{bearing}.{k}{ratio}" for k in lines for ratio in ("", "_ratio")}
    return tuple(dict.fromkeys(rule.name for rule in cfg.alarms.rules if rule.indicator in names
                               and (not rule.channels or channel in rule.channels)))


def _beyond_notes(cfg: Config, channel: str, r: IndicatorRecord, stamp: int, told: set) -> list[Event]:
    """A ``band_too_narrow`` warning for each bearing of record ``r`` of ``channel`` with lines
    past its envelope spectrum, which reaches about the envelope band's width (Randall & Antoni
    2011: the envelope of a band carries modulation up to its width), the first time that set of
    lines is: they are unavailable, the rules on them do not fire, and the width that reads them."""
    out = []
    for b in r.bearings:
        key = (channel, b.name, "beyond", b.beyond)
        if not b.beyond or b.freqs is None or key in told:
            continue
        told.add(key)
        lines = line_freqs(b.freqs)
        lo, hi = r.envelope_band
        rules = _rules_on(cfg, channel, b.name, b.beyond)
        what = f"rule(s) {', '.join(rules)} on them do not fire" if rules else "an alarm rule on them would never fire"
        need = max(lines[k] for k in b.beyond) * 1.1
        out.append(Event("band_too_narrow", channel, (
            f"{channel}: indicators.envelope_band_hz {lo:g}-{hi:g} Hz is too narrow for bearing {b.name}'s line(s) "
            f"{', '.join(f'{k} {lines[k]:.4g} Hz' for k in b.beyond)}: the envelope of a band carries modulation up "
            f"to about its width; listed unavailable in /cm/{channel}/indicators, no number; {what}; widen the band "
            f"to a width of at least {need:.3g} Hz"), stamp,
            {"details": {"band": "indicators.envelope_band_hz", "bearing": b.name, "lines": list(b.beyond)}}))
    return out


def _harmonic_notes(cfg: Config, channel: str, r: IndicatorRecord, setup: Setup, stamp: int,
                    told: set) -> list[Event]:
    """A ``line_harmonics`` event (a warning) for each bearing of record ``r`` of ``channel``
    whose lines' windows hold a harmonic of another of its lines (at every speed alike: said
    once per channel and bearing), naming the rules on those lines."""
    out = []
    for b in r.bearings:
        if b.freqs is None or (channel, b.name, "harmonics") in told:
            continue
        told.add((channel, b.name, "harmonics"))
        overlaps = harmonic_overlaps(b.freqs, setup.slip, b.unresolved + b.beyond)
        if overlaps:
            names = {f"{b.name}.{k}{ratio}" for k, _, _ in overlaps for ratio in ("", "_ratio")}
            rules = tuple(rule.name for rule in cfg.alarms.rules if rule.indicator in names
                          and (not rule.channels or channel in rule.channels))
            text = harmonic_line(b.name, channel, overlaps, line_freqs(b.freqs), setup.slip, rules)
            out.append(Event("line_harmonics", channel, text, stamp, {"details": {
                "bearing": b.name, "lines": [k for k, _, _ in overlaps],
                "harmonic_of": [d for _, d, _ in overlaps]}}))
    return out
