"""What a reader returns: the file's raw columns, and what the file itself says.

A :class:`Table` holds one file's numbers before any unit or channel choice:
``data`` is (snapshots, samples, columns) in the file's own dtype (perhaps a memory map of
the file: a WAV's, an NPY's), ``(data - zero) * gain`` in its unit,
one snapshot for a plain 2-D table, several for a 3-D array (the FEMTO archives)
or a multi-snapshot file. ``fs``, ``times`` (each snapshot's start, seconds),
``rpm`` and ``time_columns`` are set when the file carries them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .columns import Columns
from .errors import ImportFailure

__all__ = ["Table", "as_snapshot_array", "FS_KEYS", "TIME_KEYS", "RPM_KEYS"]

#: names of a scalar that gives the sampling rate in Hz (NPZ arrays, MATLAB variables)
FS_KEYS = ("fs", "fs_hz", "sample_rate", "sampling_rate", "samplerate", "sr")
#: names of a 1-D array that gives each snapshot's start time in seconds
TIME_KEYS = ("t", "t_s", "time", "times", "time_s", "timestamps")
#: names of a scalar that gives the shaft speed in rpm
RPM_KEYS = ("rpm", "speed_rpm")


@dataclass
class Table:
    path: str
    data: np.ndarray | Columns  # (snapshots, samples, columns); Columns: read a stretch at a time
    columns: list[str]  # one name per column
    kind: str = "column"  # what the user calls a column of this file in messages
    fs: float | None = None
    times: np.ndarray | None = None  # (snapshots,) seconds
    rpm: float | None = None
    notes: list[str] = field(default_factory=list)  # what the reader noticed (a file cut short)
    time_columns: tuple[int, ...] = ()  # columns of times (:mod:`.time_column`): no channels by default
    clock: bool = False  # ``times`` are times of day (seconds after midnight, the day not known)
    dated: bool = False  # ``times`` are dates and times (seconds since the Unix epoch, the zone not known)
    time_note: str | None = None  # what the import says of it, once
    head_note: str | None = None  # lines skipped before the numbers (a text table's preamble), said once
    layout_note: str | None = None  # what the reader made of the columns (a slower speed interpolated), said once
    gain: float = 1.0  # ``data`` in the file's unit: (data - zero) * gain (a WAV's PCM to fractions of full scale)
    zero: float = 0.0
    units: list[str | None] | None = None  # what the file says each column's unit is (None: the names say)

    @property
    def name(self) -> str:
        return Path(self.path).name


def as_snapshot_array(path: str, what: str, a: np.ndarray) -> np.ndarray:
    """A numeric array as (snapshots, samples, columns): 1-D is one column; in 2-D and
    3-D arrays the longer of the last two axes is time (samples)."""
    if a.dtype.kind not in "iufb":
        raise ImportFailure(f"{path}: {what} holds {a.dtype} values, not numbers; choose a numeric one")
    if a.ndim == 1:
        a = a[None, :, None]
    elif a.ndim == 2:
        a = a[None] if a.shape[0] >= a.shape[1] else a.T[None]
    elif a.ndim == 3:
        if a.shape[2] > a.shape[1]:
            a = np.swapaxes(a, 1, 2)
    else:
        raise ImportFailure(f"{path}: {what} has {a.ndim} dimensions {a.shape}; expected samples, "
                            "(samples, channels) or (snapshots, samples, channels)")
    if a.shape[1] == 0:
        raise ImportFailure(f"{path}: {what} holds no samples")
    return a
