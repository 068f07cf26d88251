"""A time column in a text table: the time base, not a vibration channel, and the sampling rate.

Data loggers and oscilloscopes often write a time column before the signals (``Time (s),Acc X
(g)``, ``t,x,y,z``). A column is the time base when its header names it (a word for time --
``t``, ``time``, ``timestamp``, ``elapsed``, ``zeit``, ``temps``, ``tiempo`` -- then at most a
unit: ``Time (s)``, ``time_ms``, ``t [us]``) and its values increase, or, in a table without a
header, when the first column increases evenly (a vibration signal never does). Its unit comes
from the label: seconds unless it says ms, us (µs) or ns.

When the times are evenly spaced -- each within half a step of the straight line from the first
to the last, as printed times rounded to a few decimals are -- they give the sampling rate,
``(n - 1) / (t_last - t_first)``, rounded to a whole number of Hz when within 0.01 % of one.
The import then takes every other column as a channel by default and needs no ``--fs``
(:class:`~.table.Table` ``time_column`` and ``fs``). Unevenly spaced times (gaps, a restart)
still mark the time base, without a rate: ``--fs`` gives it.
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from .table import Table

__all__ = ["with_time_column"]

_LABEL = re.compile(
    r"\s*(t|time|times|timestamp|time_?stamp|elapsed(?:[ _]?time)?|zeit|temps|tiempo)"
    r"(?:\s*[_ ]?\s*[(\[]?\s*(s|sec|secs|seconds|ms|msec|us|µs|μs|usec|ns)?\s*[)\]]?)?\s*", re.I)
_UNIT_S = {"ms": 1e-3, "msec": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "usec": 1e-6, "ns": 1e-9}
#: a rate this close to a whole number of Hz is that number (relative)
WHOLE_HZ = 1e-4


def with_time_column(t: Table, has_header: bool) -> Table:
    """``t`` with its time column and the rate it gives marked (see the module docstring), or
    ``t`` itself when it has none."""
    if t.data.shape[0] != 1 or t.data.shape[1] < 3 or t.data.shape[2] < 2:
        return t
    found = _labelled(t) if has_header else (0, 1.0) if _even(t.data[0, :, 0]) else None
    if found is None:
        return t
    col, unit_s = found
    times = t.data[0, :, col].astype(np.float64) * unit_s
    fs = _rate(times) if _even(times) else None
    what = f"column {t.columns[col]!r} ({col}) is the time base"
    note = (f"{what}: {fs:g} Hz from its steps; it is not imported as a channel" if fs else
            f"{what}, not evenly spaced ({_gap(times)}): it is not imported as a channel")
    return replace(t, time_column=col, fs=t.fs or fs, time_note=note)


def _labelled(t: Table) -> tuple[int, float] | None:
    """(column, seconds a unit of it) of the first column labelled as time whose values increase."""
    for i, name in enumerate(t.columns):
        m = _LABEL.fullmatch(name)
        if m and bool(np.all(np.diff(t.data[0, :, i]) > 0)):
            return i, _UNIT_S.get((m[2] or "s").lower(), 1.0)
    return None


def _even(x: np.ndarray) -> bool:
    """Strictly increasing, each value within half a mean step of the straight line."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < 3 or not bool(np.all(np.diff(x) > 0)):
        return False
    step = (x[-1] - x[0]) / (x.size - 1)
    return bool(np.abs(x - (x[0] + step * np.arange(x.size))).max() <= 0.5 * step)


def _rate(times: np.ndarray) -> float:
    fs = (times.size - 1) / (times[-1] - times[0])
    return float(round(fs)) if abs(fs - round(fs)) <= WHOLE_HZ * fs else float(fs)


def _gap(times: np.ndarray) -> str:
    """The largest step, and where (file line counted from the first row of numbers)."""
    d = np.diff(times)
    k = int(np.argmax(d))
    return f"a step of {d[k]:.6g} s after row {k + 1}, the median step {float(np.median(d)):.6g} s"
