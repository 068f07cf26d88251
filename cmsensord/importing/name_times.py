"""Snapshot times from the files' names: loggers that write one file per snapshot often name it
by the time it was taken (the IMS bearing rig: ``2004.02.12.10.32.39``).

A name holds a date and time as ``YYYY MM DD HH MM SS`` with one of ``.``, ``-``, ``_``,
``T`` or a space between the fields (``2004.02.12.10.32.39``, ``2004-02-12_10-32-39``), or
as ``YYYYMMDD`` then ``HHMMSS`` (``20040212T103239``, ``20040212_103239``).  The times are
used only when every file's name holds exactly one valid date and time, and they increase
from file to file in the import's order: then each snapshot's time in the original recording
is its file's time, in seconds after the first file's (one file: no times).
"""

from __future__ import annotations

import re
from datetime import datetime
from pathlib import Path

__all__ = ["NameTimes", "times_from_names"]

_SPACED = re.compile(r"(?<!\d)(\d{4})[-._ T](\d{2})[-._ T](\d{2})[-._ T](\d{2})[-._ T](\d{2})[-._ T](\d{2})(?!\d)")
_COMPACT = re.compile(r"(?<!\d)(\d{4})(\d{2})(\d{2})[-_T]?(\d{2})(\d{2})(\d{2})(?!\d)")


class NameTimes:
    """The files' times by their names: ``seconds`` after the first file's, and ``first`` and
    ``last`` as dates and times."""

    def __init__(self, stamps: list[datetime]):
        self.first, self.last = stamps[0], stamps[-1]
        self.seconds = [(s - self.first).total_seconds() for s in stamps]

    def note(self) -> str:
        """What the import says of them (terminal and sidecar)."""
        return (f"snapshot times from the file names: {self.first:%Y-%m-%d %H:%M:%S} to "
                f"{self.last:%Y-%m-%d %H:%M:%S} ({self.seconds[-1] / 3600:.4g} h); "
                "--snapshot-interval S sets them instead")


def _stamp(name: str) -> datetime | None:
    """The one date and time in a file's name (None: none, several, or not a valid date)."""
    stem = Path(name).name
    found = {m.groups() for rx in (_SPACED, _COMPACT) for m in rx.finditer(stem)}
    if len(found) != 1:
        return None
    y, mo, d, h, mi, s = (int(v) for v in found.pop())
    try:
        return datetime(y, mo, d, h, mi, s)
    except ValueError:
        return None


def times_from_names(files: list[str]) -> NameTimes | None:
    """The files' times by their names (see module docstring); None unless there are several
    files, every name holds one and they increase."""
    if len(files) < 2:
        return None
    stamps: list[datetime] = []
    for f in files:
        s = _stamp(f)
        if s is None or (stamps and s <= stamps[-1]):
            return None
        stamps.append(s)
    return NameTimes(stamps)
