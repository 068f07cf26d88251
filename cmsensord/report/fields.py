"""The fields a report draws, read from one message of cmsensord's topics with their types checked.

A report reads cmsensord's logs, and logs that only look like them (another program's MCAP on
``/cm/...`` topics, a damaged or edited log). Each reader here returns the fields a report draws
from a message, or None when one of them is not of the type its schema gives
(:mod:`cmsensord.sinks.schemas`, :mod:`~cmsensord.sinks.indicator_schema`,
:mod:`~cmsensord.sinks.capture_schema`, :mod:`~cmsensord.sinks.alarm_schema`): a number that is a
string, an object, null, not finite (``NaN``, ``1e999``) or past ``LIMIT``; a text that is not a
string; an object or an array that is something else. Such a message is left out whole and
counted (:class:`~cmsensord.report.log_data.FileInfo`), as one that is no JSON object is. A field
that is absent is no fault (cmsensord leaves a missing value out).

The 1-Hz topics (severity, indicators, diagnostics) are read by the fields drawn, not decoded
whole (:func:`severity`, :func:`indicators`, :func:`diagnostics`): json.loads of every message
costs more than the rest of a week's report together. The others are decoded and checked
(:func:`checked`).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["LIMIT", "severity", "indicators", "diagnostics", "checked"]

#: the largest magnitude of a number drawn: past it a figure's axes cannot hold it (a sensor's
#: reading, a counter, a frequency is far below; float32, the captures' samples, ends at 3.4e38)
LIMIT = 1e30
# after a field's name: its value when a number (its text, as float() reads it: no NaN, no
# Infinity, no string), an array of no strings, arrays or objects, or an object of no objects
# (the name with no colon after it is no field's: a string in an array, say)
_SCALAR = rb'\s*:\s*(?:(-?[0-9][0-9.eE+-]*)(?=[\s,}\]]))?'
_LIST = rb'\s*:\s*(\[[^\[\]{}"]*\])?'
_OBJECT = rb'\s*:\s*(\{[^{}]*\})?'
_ITEMS = re.compile(rb'[\s0-9.eE+,-]*')        # an array's numbers (no NaN, no Infinity)
_Field = tuple[str, bytes, re.Pattern[bytes]]
_NUMBERS = (int, float)


def _fields(after: bytes, *names: str) -> tuple[_Field, ...]:
    """(name, ``"name"``, the field and its value as ``after`` reads it) of each of ``names``."""
    return tuple((name, f'"{name}"'.encode(), re.compile(f'"{name}"'.encode() + after)) for name in names)


_SEVERITY = _fields(_SCALAR, "severity_index", "level_ratio", "level_alert", "level_danger")
_INDICATOR = _fields(_SCALAR, "velocity_rms_mm_s", "accel_rms", "envelope_rms", "kurtosis", "crest_factor",
                     "velocity_alarm_mm_s", "interval_s")
_DIAG = _fields(_SCALAR, "queue_depth", "queue_drops", "lag_s", "uptime_s")
_BEARINGS = re.compile(rb'"bearings"\s*:\s*(\[)?')
_AMPLITUDE, _LINK = _fields(_SCALAR, "amplitude")[0][2], _fields(_OBJECT, "link")[0]
#: arrays of numbers, and how many numbers each holds (None: any)
_ARRAYS = tuple(zip(_fields(_LIST, "anomaly", "zone_boundaries_mm_s", "velocity_band_hz"), (None, 3, 2)))
# a bearing of "bearings" (its name and its "lines" object: one level of objects inside), and
# a line's amplitude in that object; bearing names are letters, digits, _ and . (the config's)
_BEARING = re.compile(rb'\{\s*"name"\s*:\s*"([A-Za-z0-9_.]+)"[^{}\[\]]*"lines"\s*:\s*\{((?:[^{}]|\{[^{}]*\})*)\}')
_LINE = re.compile(rb'"([a-z0-9_]+)"\s*:\s*\{[^{}]*?"amplitude"' + _SCALAR)


def _value(text: bytes | None) -> float | None:
    """A number's text (:data:`_SCALAR`) as a float; None for none, or past LIMIT (1e999)."""
    try:
        v = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):                 # no text (None), or b"1.2.3"
        return None
    return v if abs(v) <= LIMIT else None


def _scalars(fields: tuple[_Field, ...], data: bytes, out: dict[str, Any]) -> bool:
    """The numbers of ``fields`` (:func:`_fields`) into ``out``, those ``data`` has; False when
    one is no number. (Each name looked for with ``in`` first: many times faster than a search.)"""
    for name, key, pattern in fields:
        m = pattern.search(data) if key in data else None
        if m is not None:
            v = _value(m.group(1))
            if v is None:
                return False
            out[name] = v
    return True


def _arrays(data: bytes, out: dict[str, Any]) -> bool:
    """The arrays of numbers (:data:`_ARRAYS`) into ``out``, those ``data`` has; False when one
    is no such array."""
    for (name, key, pattern), size in _ARRAYS:
        m = pattern.search(data) if key in data else None
        if m is None:
            continue
        body = m.group(1)[1:-1] if m.group(1) is not None else b"x"
        try:
            items = list(map(float, body.split(b","))) if _ITEMS.fullmatch(body) and body.strip() else None
        except ValueError:                          # b"1-2"
            return False
        if items is None and body.strip():
            return False
        items = items or []
        if (size is not None and len(items) != size) or max(map(abs, items), default=0.0) > LIMIT:
            return False
        out[name] = items
    return True


def severity(data: bytes) -> dict[str, Any] | None:
    """A severity message's severity_index, anomaly flags (``anomaly``: any of them set, 0 or
    1) and level ratios (the combined severity's), those it has; None: one of a wrong type."""
    out: dict[str, Any] = {}
    if not (_scalars(_SEVERITY, data, out) and _arrays(data, out)):
        return None
    if "anomaly" in out:
        out["anomaly"] = 1.0 if any(out["anomaly"]) else 0.0
    return out


def indicators(data: bytes) -> dict[str, Any] | None:
    """An indicator record's trends (``INDICATOR_FIELDS`` of :mod:`.log_data`, and each bearing
    line's amplitude as ``<bearing>.<line>``), velocity alarm level, interval, zone boundaries
    and velocity band, those it has; None: one of a wrong type (or zone boundaries not ascending
    from 0)."""
    out: dict[str, Any] = {}
    if not (_scalars(_INDICATOR, data, out) and _arrays(data, out)):
        return None
    zones = out.get("zone_boundaries_mm_s")
    if zones is not None and not 0 <= zones[0] <= zones[1] <= zones[2]:
        return None                 # the zones' letters would go off the axes (past what can be drawn)
    if b'"bearings"' in data:
        m = _BEARINGS.search(data)
        if (m is not None and m.group(1) is None) or any(_value(t or None) is None for t in _AMPLITUDE.findall(data)):
            return None
        out.update((f"{name.decode()}.{line.decode()}", float(v))
                   for name, lines in _BEARING.findall(data) for line, v in _LINE.findall(lines))
    return out


def diagnostics(data: bytes) -> dict[str, Any] | None:
    """A diagnostics message's queue_depth, queue_drops, lag_s, uptime_s and its ``link``
    counters (an object of numbers), those it has; None: one of a wrong type."""
    out: dict[str, Any] = {}
    if not _scalars(_DIAG, data, out):
        return None
    m = _LINK[2].search(data) if _LINK[1] in data else None
    if m is not None:
        try:
            link = json.loads(m.group(1)) if m.group(1) is not None else None
        except ValueError:
            link = None
        if link is None or not all(_number(v) for v in link.values()):
            return None
        out["link"] = link
    return out


# ---------------------------------------------------------------------------------------------
# decoded messages: a check per field drawn


def _number(v: Any) -> bool:
    return type(v) in _NUMBERS and -LIMIT <= v <= LIMIT        # not a bool; NaN fails the range


def _text(v: Any) -> bool:
    return type(v) is str


def _flag(v: Any) -> bool:
    return type(v) is bool


def _object(spec: dict[str, Callable[[Any], bool]], *required: str) -> Callable[[Any], bool]:
    """An object whose fields of ``spec`` pass its checks (``required``: present)."""
    return lambda v: type(v) is dict and _fits(v, spec) and all(k in v for k in required)


def _array(item: Callable[[Any], bool]) -> Callable[[Any], bool]:
    return lambda v: type(v) is list and all(map(item, v))


def _fits(msg: dict[str, Any], spec: dict[str, Callable[[Any], bool]]) -> bool:
    return all(key not in msg or check(msg[key]) for key, check in spec.items())


def _orders(v: Any) -> bool:
    """The orders of an Orders message: objects whose name is a string, rms and freq_hz numbers
    (written out, not through :func:`_object`: ten messages a second a channel)."""
    return type(v) is list and all(type(o) is dict and type(o.get("name", "")) is str
                                   and _number(o.get("rms", 0)) and _number(o.get("freq_hz", 0)) for o in v)


_TRIGGER = _object({"kind": _text, "message": _text})
_CAPTURE = {"trigger": _TRIGGER, "unit": _text, "source": _text, "sample_rate_hz": _number, "pre_s": _number,
            "missing": _number, "freq_start_hz": _number, "freq_step_hz": _number, "shaft_speed_rpm": _number,
            "speed_source": _text,
            "marks": _array(_object({"label": _text, "kind": _text, "freq_hz": _number}, "label", "freq_hz"))}
#: the fields drawn of each kind of message decoded (a capture's sample arrays: :func:`_samples`)
SPECS: dict[str, dict[str, Callable[[Any], bool]]] = {
    "events": {"kind": _text, "channel": _text, "message": _text, "alarm": _text},
    "alarms": {"alarms": _array(_object({"rule": _text, "indicator": _text, "channel": _text,
                                          "channels": _array(_text), "alert_level": _number,
                                          "danger_level": _number}))},
    "orders": {"speed_rpm": _number, "valid": _flag, "orders": _orders},
    "capture_waveform": _CAPTURE, "capture_spectrum": _CAPTURE, "capture_envelope": _CAPTURE,
}


def _samples(msg: dict[str, Any]) -> bool:
    """A capture's ``samples`` and ``amplitude`` as float32 arrays (a null item, a lost sample:
    NaN), its ``lost`` indices inside ``samples``; False when one is no array of numbers (as
    numpy reads them: a string of digits is read as its number)."""
    for key in ("samples", "amplitude"):
        if key not in msg:
            continue
        try:
            values = np.asarray(msg[key], dtype=np.float64)     # None: NaN
        except (TypeError, ValueError, OverflowError):
            return False
        if values.ndim != 1 or not bool(np.all(np.abs(values[~np.isnan(values)]) <= LIMIT)):
            return False
        msg[key] = values.astype(np.float32)
    lost, n = msg.get("lost", []), len(msg.get("samples", ()))
    return type(lost) is list and all(type(i) is int and 0 <= i < n for i in lost)


def checked(kind: str, msg: dict[str, Any]) -> dict[str, Any] | None:
    """A decoded message of ``kind`` (the topic's last part: ``events``, ``alarms``, ``orders``,
    ``capture_*``) when the fields drawn have their types (a capture's arrays then float32:
    :func:`_samples`); None when one has not."""
    spec = SPECS.get(kind)
    if spec is not None and not _fits(msg, spec):
        return None
    if kind.startswith("capture_") and not _samples(msg):
        return None
    return msg
