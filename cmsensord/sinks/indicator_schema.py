"""The JSON schema of ``/cm/<channel>/indicators`` (cmsensord.Indicators).

One record per channel per ``indicators.interval_s`` of board time
(:mod:`cmsensord.monitor.indicators`).  No union types: a value that was not
computed (no speed, missing samples, RMS mode) is absent, and named in
``unavailable``; every present number is finite.  :mod:`.schemas` registers it,
giving the shared time and object builders.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["indicators_schema", "DEFECT_LINES"]

#: the envelope-spectrum lines of each bearing: the defect frequencies and their 2nd harmonics
DEFECT_LINES = ("ftf", "ftf_2x", "bpfo", "bpfo_2x", "bpfi", "bpfi_2x", "bsf", "bsf_2x")


def _n(description: str, minimum: float | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "number", "description": description}
    if minimum is not None:
        out["minimum"] = minimum
    return out


def _pair(description: str, n: int = 2) -> dict[str, Any]:
    return {"type": "array", "items": {"type": "number"}, "minItems": n, "maxItems": n,
            "description": description}


def _line() -> dict[str, Any]:
    return {"type": "object", "description": "the envelope spectrum's largest bin within the slip window",
            "properties": {"amplitude": _n("envelope-spectrum 0-peak amplitude [m/s^2] (a modulation m cos(2 pi f t) "
                                          "of the envelope reads m), the bin's Hann scalloping corrected by "
                                          "two-bin interpolation (Grandke 1983)", 0),
                           "freq_hz": _n("frequency of that bin [Hz]", 0),
                           "ratio": _n("amplitude over the median of the envelope spectrum from 0.5 to "
                                       "1.5 x the line's frequency (absent when that median is 0)", 0)},
            "required": ["amplitude", "freq_hz"]}


def _bearing() -> dict[str, Any]:
    props: dict[str, Any] = {"name": {"type": "string", "description": "configured bearing name"}}
    for k, what in (("ftf", "cage (fundamental train)"), ("bpfo", "ball pass, outer race"),
                    ("bpfi", "ball pass, inner race"), ("bsf", "ball spin (a ball defect shows at 2 x)")):
        props[f"{k}_hz"] = _n(f"{what} frequency at this record's speed [Hz]", 0)
    props["lines"] = {"type": "object",
                      "description": "envelope-spectrum lines: each defect frequency and its 2nd harmonic "
                                     "(<name>_2x); absent without a speed, beyond the envelope's bandwidth, "
                                     "or not resolved by the spectrum's bins (then in unavailable)",
                      "properties": {k: _line() for k in DEFECT_LINES}}
    return {"type": "object", "properties": props, "required": ["name", "lines"]}


def indicators_schema(time: dict[str, Any], obj: Callable[..., dict]) -> dict[str, Any]:
    """The schema, built with the shared ``time`` object and ``obj`` builder of :mod:`.schemas`."""
    return obj(
        "cmsensord.Indicators",
        "Vibration indicators of one channel over one interval of board time: acceleration statistics, "
        "velocity RMS and its ISO 10816-3 zone, envelope RMS and bearing defect lines, band RMS.",
        {
            "timestamp": time,
            "channel": {"type": "string", "description": "configured channel name"},
            "mode": {"type": "string", "enum": ["raw", "rms"],
                     "description": "raw: from RAW samples (all indicators); rms: from the board's "
                                    "100 Hz block RMS (accel_rms only)"},
            "interval_s": _n("length of the interval [s]; the record is stamped at its end", 0),
            "missing_fraction": _n("fraction of the interval's samples (rms: blocks) missing", 0),
            "accel_rms": _n("acceleration RMS, mean removed (rms mode: the board's, with it) [m/s^2]", 0),
            "accel_peak": _n("largest |acceleration - mean| [m/s^2]", 0),
            "crest_factor": _n("accel_peak / accel_rms", 0),
            "kurtosis": _n("mean(x^4) / mean(x^2)^2 of the acceleration minus its mean (3: Gaussian)", 0),
            "velocity_rms_mm_s": _n("velocity RMS over velocity_band_hz [mm/s], integrated in the "
                                    "frequency domain", 0),
            "velocity_band_hz": _pair("[lo, hi] of the velocity RMS [Hz]: indicators.velocity_band_hz, else "
                                      "by the record's speed (speed_rpm, else indicators.rpm): 2-1000 at or "
                                      "below 600 rpm, 10-1000 above or without a speed"),
            "zone": {"type": "string", "enum": ["A", "B", "C", "D"],
                     "description": "ISO 10816-3 / 20816-3 zone of velocity_rms_mm_s"},
            "zone_boundaries_mm_s": _pair("A/B, B/C, C/D boundaries of the machine group and "
                                          "foundation [mm/s]", 3),
            "velocity_alarm_mm_s": _n("ISO 10816-3 alarm level from indicators.velocity_baseline_mm_s: "
                                      "baseline + 0.25 x B/C, at most 1.25 x B/C [mm/s]", 0),
            "envelope_rms": _n("RMS of the envelope (minus its mean) of envelope_band_hz [m/s^2]", 0),
            "envelope_band_hz": _pair("[lo, hi] demodulated [Hz]"),
            "speed_rpm": _n("shaft speed of the interval [rpm]", 0),
            "speed_source": {"type": "string", "enum": ["tacho", "config"],
                             "description": "tacho (mean causal speed, measured) or config (indicators.rpm, "
                                            "or an imported capture's constant speed: given, not measured)"},
            "bearings": {"type": "array", "description": "the bearings the channel sees",
                         "items": _bearing()},
            "bands": {"type": "array", "description": "band RMS (order bands only with a speed)",
                      "items": {"type": "object", "properties": {
                          "name": {"type": "string", "description": "configured band name"},
                          "lo_hz": _n("lower edge [Hz]", 0), "hi_hz": _n("upper edge [Hz]", 0),
                          "rms": _n("acceleration RMS in the band [m/s^2]", 0)},
                          "required": ["name", "lo_hz", "hi_hz", "rms"]}},
            "unavailable": {"type": "array", "items": {"type": "string"},
                            "description": "indicators this record cannot carry (rms mode, missing "
                                           "samples), that lack a speed (speed), or bearing lines "
                                           "(<bearing>.<line>) its envelope spectrum's bins do not resolve: "
                                           "a window of +/-max(slip, 1 bin) wider than +/-10 % of the line, "
                                           "or overlapping another line's of the bearing"},
            "signal_lost": {"type": "boolean",
                            "description": "true when the severity decision this record goes out with has no "
                                           "signal (monitor.signal_floor, monitor.flat_signal), or a block of "
                                           "the channel whose samples are all one count (monitor.flat_signal): "
                                           "the alarms do not judge it"},
        },
        ["timestamp", "channel", "mode", "interval_s", "missing_fraction"],
    )
