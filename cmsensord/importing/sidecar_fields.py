"""The fields of an imported capture's sidecar, checked once where it is read.

A sidecar is JSON a person may edit (or a tool damage): each field a replay, ``calibrate``,
``vkf`` or the acoustic calibration takes from it is checked for what they need of it (a
sampling rate a positive number, the snapshots a list of objects whose board starts increase
and fit their lengths, a date that is a date), and a field that is not is left out with one
line naming it; the run goes on with the rest. The capture's STATUS frames, not the sidecar,
say its sampling rate: a sidecar ``fs`` that differs is replaced by the STATUS rate, with a
line naming both; the snapshots are kept when their board starts fit their lengths at that
rate (an ``fs`` edited alone), else left out too (they rest on another rate). They say how many
channels it holds too: ``channel_names`` past that count (past a board's 8 when no STATUS
frame is read) name no channel of it, and are left out with one line.
"""

from __future__ import annotations

import json
import math
import os
import stat
from collections.abc import Callable
from datetime import datetime, timedelta
from pathlib import Path

from cmsensord.config import MAX_CHANNELS
from cmsensord.protocol import Decoder, FrameType, Status, decode_status

__all__ = ["CAPTURE_UNITS", "capture_status", "checked"]

#: the units a capture holds its channels in (an accelerometer's, a microphone's)
CAPTURE_UNITS = ("m/s2", "Pa")
#: bytes of a capture read for its first STATUS frame (an import writes it first)
_HEAD_BYTES = 1 << 16
#: seconds in the recording past which a time is no time (about 3,000 years)
_MAX_S = 1e11
#: samples past which a snapshot's length is no length (the most a float holds exactly)
_MAX_SAMPLES = 1 << 53


def capture_status(capture: str | Path) -> Status | None:
    """The capture's first STATUS frame with a positive rate (None: no readable one in its first
    ``_HEAD_BYTES``, or the capture is no regular file: a FIFO is not read, never waited on)."""
    try:
        fd = os.open(capture, os.O_RDONLY | os.O_NONBLOCK)
        with open(fd, "rb") as f:
            head = f.read(_HEAD_BYTES) if stat.S_ISREG(os.fstat(fd).st_mode) else b""
    except (OSError, ValueError):
        return None
    for frame in Decoder().feed(head):
        if frame.type == FrameType.STATUS:
            try:
                status = decode_status(frame.payload)
            except ValueError:
                continue
            return status if status.fs > 0 else None
    return None


def _shown(value: object) -> str:
    """A field's value as the sidecar writes it, cut to a few dozen characters."""
    text = json.dumps(value, allow_nan=True, default=str)
    return text if len(text) <= 40 else text[:37] + "..."


def _number(value: object) -> bool:
    """Whether ``value`` is a finite number (a whole number past a float's range is not)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def _positive(value: object) -> str | None:
    return None if _number(value) and value > 0 else "not a positive number"  # type: ignore[operator]


def _text_list(value: object) -> str | None:
    ok = isinstance(value, list) and all(isinstance(v, str) for v in value)
    return None if ok else "not a list of texts"


def _units(value: object) -> str | None:
    units = value if isinstance(value, list) else [value]
    ok = all(isinstance(u, str) and u in CAPTURE_UNITS for u in units)
    return None if ok else f"not {' or '.join(CAPTURE_UNITS)}, one or one per channel"


def _optional(check: Callable[[object], str | None]) -> Callable[[object], str | None]:
    return lambda value: None if value is None else check(value)


def _text(value: object) -> str | None:
    return None if isinstance(value, str) else "not a text"


#: field -> (its check: why it is not usable, or None; what leaving it out leaves out)
_FIELDS: dict[str, tuple[Callable[[object], str | None], str]] = {
    "fs": (_positive, "its sampling rate is not used"),
    "board_seconds": (_optional(lambda v: None if _number(v) and v >= 0 else "not a number of seconds"),  # type: ignore[operator]
                      "its length is not used"),
    "channel_names": (_text_list, "its channel names are not used"),
    "unit": (_optional(_units), "its units are not used"),
    "rpm": (_optional(lambda v: None if _number(v) and v >= 0 else "not a speed in rpm"),  # type: ignore[operator]
            "its speed is not used"),                                       # 0: none known
    "rpm_source": (_optional(_text), "where its speed came from is not said"),
    "notes": (_optional(_text_list), "its notes are not used"),
    "source_start": (_optional(_text), "its date is not used"),
}
_SNAPSHOTS = "its snapshots (the records' length, the times in the recording) are not used"


def _snapshot(s: object) -> tuple[str, str] | None:
    """(the bad field of one snapshot, why), or None when it is usable."""
    if not isinstance(s, dict):
        return "", "not an object"
    for key, why in (("start_s", None if _number(s.get("start_s")) and 0 <= s["start_s"] < _MAX_S
                      else "not a board second"),
                     ("length", None if isinstance(s.get("length"), int) and not isinstance(s["length"], bool)
                      and 0 <= s["length"] <= _MAX_SAMPLES else "not a number of samples"),   # 0: shorter than a block
                     ("source", _text(s.get("source"))),
                     ("pct_of_record", None if _number(s.get("pct_of_record")) else "not a number"),
                     ("source_time_s", None if s.get("source_time_s") is None or _number(s["source_time_s"])
                      and abs(s["source_time_s"]) < _MAX_S else "not a number of seconds")):
        if why:
            return f".{key}", why
    return None


def _snapshots(meta: dict) -> str | None:
    """A line on the first thing that makes the snapshots unusable, or None."""
    snaps = meta["snapshots"]
    if not isinstance(snaps, list):
        return f"snapshots is {_shown(snaps)} (not a list): {_SNAPSHOTS}"
    for k, s in enumerate(snaps):
        bad = _snapshot(s)
        if bad:
            field, why = bad
            said = f"is {_shown(s[field[1:]])} ({why})" if isinstance(s, dict) and field[1:] in s else \
                f"is {_shown(s)} ({why})" if not field else "is missing"
            return f"snapshots[{k}]{field} {said}: {_SNAPSHOTS}"
    fs = meta.get("fs")
    for k, (a, b) in enumerate(zip(snaps, snaps[1:])):
        if fs and abs((b["start_s"] - a["start_s"]) * fs - a["length"]) > 0.5:
            return (f"snapshots[{k + 1}].start_s is {_shown(b['start_s'])} (snapshot {k} of {a['length']} samples "
                    f"from {a['start_s']:g} s ends at {a['start_s'] + a['length'] / fs:g} s at {fs:g} Hz): "
                    f"{_SNAPSHOTS}")
    return None


def _date(meta: dict) -> str | None:
    """A line when ``source_start`` is no date and time, or one its snapshots' times run past."""
    start = meta["source_start"]
    times = [s["source_time_s"] for s in meta.get("snapshots") or [] if s.get("source_time_s") is not None]
    try:
        at = datetime.fromisoformat(start)
        for t in (min(times, default=0.0), max(times, default=0.0)):
            at + timedelta(seconds=t, days=1)
    except ValueError as exc:
        why = str(exc)
    except OverflowError:
        why = "its snapshots' times run past the year 9999"
    else:
        return None
    return f"source_start is {_shown(start)} ({why}): {_FIELDS['source_start'][1]}"


def _names_past(meta: dict, status: Status | None) -> str | None:
    """A line when ``channel_names`` names more channels than the capture holds (``status``: its
    first STATUS frame; None: a board's most), which are then cut to that many."""
    names, held = meta["channel_names"], MAX_CHANNELS if status is None else status.n_channels
    if len(names) <= held:
        return None
    meta["channel_names"] = names[:held]
    holds = f"its STATUS frames' {held} channel(s)" if status else f"more than a board's {held} channels"
    return f"channel_names holds {len(names)} names, {holds}: the names past the first {held} are not used"


def checked(meta: dict, status: Status | None) -> tuple[dict, list[str]]:
    """``meta`` without the fields it cannot use, the rate of ``status`` (the capture's first
    STATUS frame; None: not known) as its ``fs``, its channel names no more than that frame's
    channels, and one line on each field left out, replaced or cut (see the module docstring)."""
    meta, lines = dict(meta), []
    fs = None if status is None else status.fs
    for key, (check, lost) in _FIELDS.items():
        why = check(meta[key]) if key in meta else None
        if why:
            lost = f"the STATUS frames' {fs} Hz is used" if key == "fs" and fs is not None else lost
            lines.append(f"{key} is {_shown(meta.pop(key))} ({why}): {lost}")
    line = _names_past(meta, status) if "channel_names" in meta else None
    lines += [line] if line else []
    if fs is not None and "fs" in meta and meta["fs"] != fs:
        lines.append(f"fs is {_shown(meta['fs'])} Hz, its STATUS frames' {fs} Hz: the STATUS rate is used")
    if fs is not None:
        meta["fs"] = fs
    if "snapshots" in meta:
        line = _snapshots(meta)
        if line:
            lines.append(line)
            del meta["snapshots"]
    if meta.get("source_start") is not None:
        line = _date(meta)
        if line:
            lines.append(line)
            del meta["source_start"]
    return meta, lines
