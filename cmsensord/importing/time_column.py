"""A time column in a text table: the time base, not a vibration channel, and the sampling rate.

Data loggers and oscilloscopes often write a time column before the signals (``Time (s),Acc X
(g)``, ``t,x,y,z``). A column is the time base when its header names it (a word for time --
``t``, ``time``, ``timestamp`` (or ``Time Stamp``, ``time_stamp``, ``time-stamp``),
``elapsed``, ``zeit``, ``temps``, ``tiempo``, LabVIEW's ``X_Value`` -- then at most a
unit: ``Time (s)``, ``time_ms``, ``t [us]``) and its values increase, or, in a table without a
header, when the first column increases evenly (a vibration signal never does). Its unit comes
from the label: seconds unless it says ms, us (µs) or ns.

Columns of the time of day -- hour, minute, second and microsecond, or hour, minute and
seconds with their fraction, the first three or four of the table (the FEMTO/PRONOSTIA
bearing files' ``9,39,39,65664,0.552,-0.146``) -- are the time base too, when the hours and
minutes are whole numbers in range and the time they make increases evenly; each file's first
time is then its snapshot's time of day (``Table.times``, ``clock``).

A first column of row numbers -- a pandas ``DataFrame.to_csv`` index: its header cell empty
(read as ``col0``), ``Unnamed: 0`` or ``index``, or the table without a header -- is a row index
when its values are exactly 0, 1, 2, ... (or 1, 2, 3, ...): whole numbers, one apart, from the
first row to the last. It is no channel by default and no time base (it does not give the
rate: ``--fs`` does); a time column after it is still found. So a headerless file of seconds
at 1 Hz (``0,...``, ``1,...``) needs ``--fs 1``; one whose column is labelled ``t`` or ``time``
does not.

A first column of dates and times (``2023-05-01 12:00:00.125``, ISO 8601 without a zone) is
the time base too, whatever its label; each file's first date and time is then its
snapshot's (``Table.times``, ``dated``), and the recording's start.

When the times are evenly spaced -- each within half a step of the straight line from the first
to the last, as printed times rounded to a few decimals are -- they give the sampling rate,
one over the least-squares step, rounded to a whole number of Hz when within 0.01 % of one.
A column labelled as time (or of dates) printed with fewer decimals than the rate needs
(``0.0000, 0.0000, 0.0001, ...`` at 25.6 kHz) repeats each value in runs whose lengths differ
by at most two: the time base too, and without a gap its rate is fitted to the rows where the
values change (each a rounding boundary).
The import then takes every other column as a channel by default and needs no ``--fs``
(:class:`~.table.Table` ``time_columns`` and ``fs``). Unevenly spaced times (gaps, a restart)
still mark the time base, without a rate: ``--fs`` gives it; so does a column labelled as time
whose values step back at a few places (a logger's clock set back), with a note naming the first.
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from .table import Table

__all__ = ["whole_hz", "with_time_column"]

_LABEL = re.compile(
    r"\s*(t|times?|time[ _-]?stamps?|elapsed(?:[ _-]?time)?|zeit|temps|tiempo|x_value)"
    r"(?:\s*[_ ]?\s*[(\[]?\s*(s|sec|secs|seconds|ms|msec|us|µs|μs|usec|ns)?\s*[)\]]?)?\s*", re.I)
_UNIT_S = {"ms": 1e-3, "msec": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "usec": 1e-6, "ns": 1e-9}
#: a rate this close to a whole number of Hz is that number (relative)
WHOLE_HZ = 1e-4


def with_time_column(t: Table, has_header: bool, dated: bool = False) -> Table:
    """``t`` with its time column(s) and the rate they give marked (see the module docstring),
    or ``t`` itself when it has none; ``dated``: its first column holds dates and times (as
    seconds since the Unix epoch), the time base whatever its label."""
    if dated:
        return _dated(t)
    if t.data.shape[0] != 1 or t.data.shape[1] < 3 or t.data.shape[2] < 2:
        return t
    if _row_index(t, has_header):
        return _after_index(t, has_header)
    clock = _clock(t)
    if clock is not None:
        cols, of_day = clock
        rate = _rate(of_day)
        note = (f"columns {cols[0]}-{cols[-1]} are the time of day ({', '.join(_CLOCK_NAMES[:len(cols)])}): "
                f"{rate:g} Hz from their steps; they are not imported as channels")
        return replace(t, time_columns=cols, fs=t.fs or rate, time_note=note, times=of_day[:1], clock=True)
    found = _labelled(t) if has_header else (0, 1.0) if _even(t.data[0, :, 0]) else None
    if found is None:
        return (_set_back(t) if has_header else None) or t
    col, unit_s = found
    return _time_base(t, col, np.multiply(t.data[0, :, col], unit_s, dtype=np.float64), "is the time base", "its")


#: what a header names a row index (lower case; ``col0``: an empty header cell)
_INDEX_NAMES = ("col0", "unnamed: 0", "index")


def _row_index(t: Table, has_header: bool) -> bool:
    """Whether the first column is a row index (see the module docstring)."""
    if has_header and t.columns[0].strip().lower() not in _INDEX_NAMES:
        return False
    x = t.data[0, :, 0]
    if x[0] not in (0, 1) or x[-1] != x[0] + x.size - 1:
        return False
    return all(bool(np.array_equal(x[a:a + _STRETCH], x[0] + np.arange(a, min(a + _STRETCH, x.size))))
               for a in _stretches(x.size))


def _after_index(t: Table, has_header: bool) -> Table:
    """``t`` with its first column a row index (no channel, no rate), and a time column after it
    marked too: said by ``time_note`` alone, or by ``layout_note`` beside a time column's."""
    first = int(t.data[0, 0, 0])
    note = (f"column {t.columns[0]!r} (0) holds the row numbers {first}, {first + 1}, {first + 2}, ...: a row "
            "index, not times; it is not imported as a channel")
    found = _labelled(t, 1) if has_header else (1, 1.0) if t.data.shape[2] > 2 and _even(t.data[0, :, 1]) else None
    if found is None:
        return replace(t, time_columns=(0,), time_note=note)
    col, unit_s = found
    timed = _time_base(t, col, np.multiply(t.data[0, :, col], unit_s, dtype=np.float64), "is the time base", "its")
    return replace(timed, time_columns=(0, col), layout_note=note)


def _dated(t: Table) -> Table:
    """The first column's dates and times: the time base, its rate when evenly spaced, and the
    file's first date and time (``times``, ``dated``)."""
    epoch = t.data[0, :, 0]
    return replace(_time_base(t, 0, epoch - epoch[0], "holds dates and times", "their"), times=epoch[:1],
                   dated=True)


def _time_base(t: Table, col: int, times: np.ndarray, what: str, whose: str) -> Table:
    """``t`` with column ``col`` (``times``, seconds) its time base: the rate when evenly spaced,
    and the note that says so."""
    fs = _rate(times) if _even(times) else _printed_rate(times)
    what = f"column {t.columns[col]!r} ({col}) {what}"
    note = (f"{what}: {fs:g} Hz from {whose} steps; it is not imported as a channel" if fs else
            f"{what}, not evenly spaced ({_gap(times)}): it is not imported as a channel")
    return replace(t, time_columns=(col,), fs=t.fs or fs, time_note=note)


_CLOCK_NAMES = ("hour", "minute", "second", "microsecond")
#: rows a table's time-of-day columns are first told by
_HEAD_ROWS = 4096


def _clock(t: Table) -> tuple[tuple[int, ...], np.ndarray] | None:
    """(columns, seconds of the day) of time-of-day columns at the table's start, or None (told
    by the first rows first: a long table's columns are copied only when those are times)."""
    if t.data.shape[1] > _HEAD_ROWS and _clock(replace(t, data=t.data[:, :_HEAD_ROWS])) is None:
        return None
    assert isinstance(t.data, np.ndarray), "a text table's numbers are in memory (or mapped)"
    a = t.data[0]
    for width in (4, 3):
        if a.shape[1] <= width:
            continue
        c = a[:, :width].astype(np.float64)
        whole = c[:, :2] if width == 3 else c[:, :3]
        if not (np.array_equal(whole, np.round(whole)) and c[:, 0].min() >= 0 and c[:, 0].max() < 24
                and c[:, 1].min() >= 0 and c[:, 1].max() < 60 and c[:, 2].min() >= 0 and c[:, 2].max() < 61):
            continue
        seconds = c[:, 0] * 3600 + c[:, 1] * 60 + c[:, 2]
        if width == 4:
            if c[:, 3].min() < 0 or c[:, 3].max() >= 1e6:
                continue
            seconds = seconds + c[:, 3] * 1e-6
        if _even(seconds):
            return tuple(range(width)), seconds
    return None


def _labelled(t: Table, start: int = 0) -> tuple[int, float] | None:
    """(column, seconds a unit of it) of the first column from ``start`` labelled as time whose
    values increase (a value may repeat: times printed with fewer decimals than the rate needs)."""
    for i, name in enumerate(t.columns[start:], start):
        m = _LABEL.fullmatch(name)
        if m and (_increasing(t.data[0, :, i]) or _printed(t.data[0, :, i]) is not None):
            return i, _UNIT_S.get((m[2] or "s").lower(), 1.0)
    return None


def _set_back(t: Table) -> Table | None:
    """``t`` with its first column labelled as time whose values increase but for a few steps
    back (a logger's clock set back) marked its time base, without a rate, and a note naming
    the first step back; None when it has none."""
    for i, name in enumerate(t.columns):
        if not _LABEL.fullmatch(name):
            continue
        x = np.asarray(t.data[0, :, i], dtype=np.float64)
        d = np.diff(x)
        back = np.flatnonzero(d < 0)
        if 0 < back.size <= max(1, x.size // 1000) and int((d > 0).sum()) * 2 > d.size:
            k = int(back[0])
            note = (f"column {name!r} ({i}) is named as time but steps back {back.size} time(s), the first after row "
                    f"{k + 1} ({x[k]:g} -> {x[k + 1]:g}): not a time base that gives the rate; it is not imported "
                    "as a channel")
            return replace(t, time_columns=(i,), time_note=note)
    return None


#: values a long column is checked a stretch at a time by (no column-long temporaries)
_STRETCH = 1 << 20


def _stretches(n: int):
    return range(0, n, _STRETCH)


def _increasing(x: np.ndarray) -> bool:
    return all(bool(np.all(np.diff(x[a:a + _STRETCH + 1]) > 0)) for a in _stretches(x.size))


def _even(x: np.ndarray) -> bool:
    """Strictly increasing, each value within half a mean step of the straight line."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < 3 or not _increasing(x):
        return False
    step = (x[-1] - x[0]) / (x.size - 1)
    return all(float(np.abs(x[a:a + _STRETCH] - (x[0] + step * np.arange(a, min(a + _STRETCH, x.size)))).max())
               <= 0.5 * step for a in _stretches(x.size))


def _changes(x: np.ndarray) -> np.ndarray | None:
    """The rows where a column that never decreases takes a new value (None: it decreases
    somewhere, or never rises)."""
    parts = []
    for a in _stretches(x.size):
        d = np.diff(x[a:a + _STRETCH + 1])
        if (d < 0).any():
            return None
        parts.append(np.flatnonzero(d > 0) + a + 1)
    rows = np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)
    return rows if rows.size else None


def _printed(x: np.ndarray) -> tuple[np.ndarray, float] | None:
    """(rows where each new value starts, the printed resolution) of times printed with fewer
    decimals than the rate needs (``0.0000, 0.0000, 0.0001, ...`` at 25.6 kHz): values that
    repeat in runs whose lengths differ by at most two (a value on a rounding boundary goes
    either way), apart from a run a gap ends (a rise past the resolution); None for anything
    else (a warm-up's temperature rises unevenly)."""
    v = np.asarray(x, dtype=np.float64)
    rows = _changes(v)
    if rows is None or rows.size < 3 or rows.size == v.size - 1:
        return None
    rises = v[rows] - v[rows - 1]
    quantum = float(rises.min())
    runs = np.diff(rows)
    kept = runs[rises[1:] <= quantum * (1 + 1e-6)]            # the runs no gap ends
    if kept.size < 2 or int(kept.max()) - int(kept.min()) > 2 + 0.001 * float(np.median(kept)):
        return None
    return rows, quantum


def _printed_rate(x: np.ndarray) -> float | None:
    """The rate of times :func:`_printed` gives, when no gap is between them (else None): one
    over the least-squares step of the rows where a new value starts (each a rounding boundary,
    its time known to within a step) against their values."""
    found = _printed(x)
    if found is None:
        return None
    rows, quantum = found
    v = np.asarray(x, dtype=np.float64)
    if float(v[rows[-1]] - v[rows[0]]) > quantum * (rows.size - 1) * (1 + 1e-6):
        return None                                             # a gap: more than one resolution per rise
    k = rows.astype(np.float64) - rows.mean()
    return whole_hz(float((k * k).sum() / (k * (v[rows] - v[rows].mean())).sum()))


def _rate(times: np.ndarray) -> float:
    """1 / the least-squares step of evenly spaced times (printed times are rounded: the fit
    averages that away, the two ends alone do not), whole Hz when within ``WHOLE_HZ``."""
    n, mid = times.size, (times.size - 1) / 2
    mean = sum(float(times[a:a + _STRETCH].sum()) for a in _stretches(n)) / n
    num = den = 0.0
    for a in _stretches(n):
        k = np.arange(a, min(a + _STRETCH, n), dtype=np.float64) - mid
        num += float((k * k).sum())
        den += float((k * (times[a:a + k.size] - mean)).sum())
    fs = num / den
    return whole_hz(fs)


def whole_hz(fs: float) -> float:
    """``fs`` as a whole number of Hz when within ``WHOLE_HZ`` of one (a rate from printed times,
    or from a waveform's time step)."""
    return float(round(fs)) if abs(fs - round(fs)) <= WHOLE_HZ * fs else fs


def _gap(times: np.ndarray) -> str:
    """The largest step, and where (file line counted from the first row of numbers)."""
    d = np.diff(times)
    if not d.size:
        return "a single row"
    k = int(np.argmax(d))
    rises = d[d > 0]
    if rises.size < d.size:             # values repeat: times printed coarser than their step
        return f"a step of {d[k]:.6g} s after row {k + 1}, in times printed to {float(rises.min()):.6g} s"
    return f"a step of {d[k]:.6g} s after row {k + 1}, the median step {float(np.median(d)):.6g} s"
