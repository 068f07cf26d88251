"""Times for people: nanoseconds since the Unix epoch as ISO 8601 in the machine's local zone."""

from __future__ import annotations

from datetime import datetime

__all__ = ["iso_local", "local_datetime", "local_text"]


def local_datetime(ns: int) -> datetime:
    """``ns`` (Unix epoch nanoseconds) as an aware datetime in the local time zone."""
    return datetime.fromtimestamp(ns / 1e9).astimezone()


def iso_local(ns: int | None, *, ms: bool = False) -> str:
    """``ns`` as ISO 8601 local time with its UTC offset (``2026-11-26T17:47:02+01:00``);
    ``ms``: with milliseconds. ``None`` gives ``-``."""
    if ns is None:
        return "-"
    return local_datetime(int(ns)).isoformat(timespec="milliseconds" if ms else "seconds")


def local_text(ns: int | None, *, ms: bool = False) -> str:
    """``ns`` as local time for a table or a card, ``2026-11-26 17:47:02`` (the page states the
    offset once); ``None`` gives ``-``."""
    return "-" if ns is None else iso_local(ns, ms=ms).replace("T", " ")[: 23 if ms else 19]
