"""The date and time a text table's preamble gives its recording's start.

LabVIEW's measurement files (``.lvm``) begin with a header of settings, one a line, key and
value by a tab, among them ``Date`` (``2024/03/05``) and ``Time`` (``10:15:02.1234567``): when
the measurement began. A logger that writes one such file per snapshot so dates every
snapshot. Other loggers write one line, ``Start Time: 2024-03-05 10:15:02`` or ``Trigger time
= ...``. The first date with the first time (or the first line that holds both) is the file's
start, read as the clock gave it (seconds since the Unix epoch, no zone applied), as the
dates in file names and in a first column are.
"""

from __future__ import annotations

import re
from datetime import datetime, timezone

__all__ = ["preamble_start"]

_KEY_VALUE = re.compile(r"\s*([A-Za-z][A-Za-z _]*?)\s*(?:[\t:=;,]\s*)+(.+?)[\t ;,]*$")
_DATE = re.compile(r"(\d{4})[/.-](\d{1,2})[/.-](\d{1,2})")
_TIME = re.compile(r"(\d{1,2}):(\d{2})(?::(\d{2})(?:[.,](\d+))?)?")  # LabVIEW writes 10:15:02,5 too
_START_KEYS = ("start time", "start", "trigger time", "recording start", "start date", "datetime", "date time")


def preamble_start(lines: tuple[str, ...] | list[str]) -> float | None:
    """Seconds since the Unix epoch of the start the preamble ``lines`` give, or None."""
    date = clock = None
    for line in lines:
        m = _KEY_VALUE.fullmatch(line)
        if m is None:
            continue
        key, value = m[1].strip().lower(), m[2]
        if key in _START_KEYS:
            d = _DATE.search(value)
            c = _TIME.search(value, d.end()) if d else None
            if d and c:
                return _epoch(d, c)
        elif key == "date" and date is None:
            date = _DATE.fullmatch(value.strip())
        elif key == "time" and clock is None:
            clock = _TIME.fullmatch(value.strip())
    return _epoch(date, clock) if date and clock else None


def _epoch(date: re.Match, clock: re.Match) -> float | None:
    try:
        whole = datetime(int(date[1]), int(date[2]), int(date[3]), int(clock[1]), int(clock[2]),
                         int(clock[3] or 0), tzinfo=timezone.utc)
    except ValueError:
        return None
    return whole.timestamp() + (float(f"0.{clock[4]}") if clock[4] else 0.0)
