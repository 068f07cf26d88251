"""The snapshots' times in the original recording, and the date and time they count from.

In order of precedence: every ``--snapshot-interval``; the files' time columns
(:mod:`.time_column`: times of day, or dates and times), counted from the first snapshot;
the dates and times in the files' names (:mod:`.name_times`) when no file gave its own;
else the times the files gave (an archive's ``t_s``), or none. Each source but the interval
leaves a note that says where the times came from and their span; several files with none
leave a note that says so and which option gives them.
"""

from __future__ import annotations

from datetime import datetime, timezone

import numpy as np

from .name_times import times_from_names
from .options import ImportOptions
from .recording import Snapshot

__all__ = ["retimed"]


def retimed(snaps: list[Snapshot], origins: list[tuple[int, int]], files: list[str], opts: ImportOptions,
            fs: float, own_times: bool, clock: str, notes: list[str]) -> tuple[list[Snapshot], str | None]:
    """The snapshots' times in the original recording, and the date and time they count from
    (None: not known): every ``--snapshot-interval``; else from the files' time columns
    (``clock`` "day": times of day; "date": dates and times; :func:`_from_clock`); else, when
    no file gave its own, by the files' names (:mod:`.name_times`, with a note), a snapshot
    ``a`` samples into its file ``a / fs`` after the file's time; else as read. ``origins``:
    per snapshot, its file and its first sample in the file."""
    if opts.snapshot_interval is not None:
        return [Snapshot(s.source, s.start, s.length, i * opts.snapshot_interval)
                for i, s in enumerate(snaps)], None
    if clock:
        return _from_clock(snaps, origins, fs, notes, clock == "date")
    named = None if own_times else times_from_names(files)
    if named is None:
        if not own_times and len(files) > 1:
            notes.append(f"the {len(files)} files carry no times (no time column, no date and time in their "
                         "names): their snapshots lie end to end, the time between them in the recording "
                         "unknown; --snapshot-interval S gives it")
        return snaps, None
    notes.append(named.note())
    return [Snapshot(s.source, s.start, s.length, named.seconds[fi] + a / fs)
            for s, (fi, a) in zip(snaps, origins)], named.first.isoformat()


def _from_clock(snaps: list[Snapshot], origins: list[tuple[int, int]], fs: float, notes: list[str],
                dated: bool) -> tuple[list[Snapshot], str | None]:
    """Snapshot times from the files' time columns (:mod:`.time_column`), counted from the
    first snapshot, and its date and time when ``dated``; times of day: a time more than 12 h
    before the one before it is on the next day. A note says the span, or, when a file had no
    time column that increases evenly, or a snapshot's time is not after the one before it (files
    in another order than their times, a logger that stamps every file alike), which (no times
    then)."""
    lacking = [s.source for s in snaps if s.source_time_s is None]
    if lacking:
        notes.append(f"{lacking[0]}{f' and {len(lacking) - 1} more' if len(lacking) > 1 else ''}: no "
                     f"{'date and time' if dated else 'time of day'} that increases evenly, as the other files "
                     "have: the snapshots have no times; --snapshot-interval S gives them")
        return [Snapshot(s.source, s.start, s.length, None) for s in snaps], None
    at = np.array([s.source_time_s for s in snaps], dtype=np.float64) + np.array([a for _, a in origins]) / fs
    days = np.zeros(at.size) if dated else np.concatenate([[0], np.cumsum(np.diff(at) < -43200)])
    t = at + 86400 * days - at[0]
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0]) + 1
        notes.append(f"{snaps[k].source}: its {'date and time' if dated else 'time of day'} ({_when(at[k], dated)}) is "
                     f"not after {snaps[k - 1].source}'s ({_when(at[k - 1], dated)}), at {back.size} place(s): the "
                     "snapshots have no times; --snapshot-interval S gives them")
        return [Snapshot(s.source, s.start, s.length, None) for s in snaps], None
    start = datetime.fromtimestamp(at[0], timezone.utc).replace(tzinfo=None).isoformat() if dated else None
    what = "dates and times" if dated else "time-of-day columns"
    if len(snaps) == 1:
        notes.append(f"the recording starts at {_when(at[0], dated)} (the file's {what})")
    else:
        notes.append(f"snapshot times from the files' {what}: {_when(at[0], dated)} to {_when(at[-1], dated)} "
                     f"({t[-1] / 3600:.4g} h{', past midnight' if days[-1] else ''}); --snapshot-interval S sets "
                     "them instead")
    return [Snapshot(s.source, s.start, s.length, float(ti)) for s, ti in zip(snaps, t)], start


def _when(at: float, dated: bool) -> str:
    """A file's time as it said it: a date and time (seconds since the epoch), or a time of day."""
    return f"{datetime.fromtimestamp(at, timezone.utc):%Y-%m-%d %H:%M:%S}" if dated else _hms(at)


def _hms(seconds: float) -> str:
    s = int(seconds) % 86400
    return f"{s // 3600:02d}:{s % 3600 // 60:02d}:{s % 60:02d}"
