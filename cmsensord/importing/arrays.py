"""NumPy reader: ``.npy`` (one array) and ``.npz`` (choose the array with ``--array``).

In an ``.npz`` archive without ``--array``, the one array with at least two
dimensions is the data (a single 1-D array otherwise); scalars named like a
sampling rate (``fs``, ``fs_hz``, ``sample_rate``, ...) or a speed (``rpm``),
and a 1-D array of snapshot start times (``t``, ``t_s``, ``time``, ...) whose
length is the number of snapshots, are read as such. Axes: see
:func:`.table.as_snapshot_array` (a 3-D array is snapshots x samples x channels).
"""

from __future__ import annotations

import zipfile

import numpy as np

from .errors import ImportFailure
from .table import FS_KEYS, RPM_KEYS, TIME_KEYS, Table, as_snapshot_array

__all__ = ["read_npy", "read_npz", "pick_data", "scalar_named"]


def _load(path: str):
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        raise ImportFailure(f"{path}: not a readable NumPy file ({' '.join(str(exc).split())})") from None


def _columns(name: str, n: int) -> list[str]:
    return [name] if n == 1 else [f"{name}_{i}" for i in range(n)]


def read_npy(path: str) -> Table:
    a = _load(path)
    data = as_snapshot_array(path, "the array", a)
    return Table(path=path, data=data, columns=_columns("ch", data.shape[2]), kind="channel")


def scalar_named(arrays: dict, keys: tuple[str, ...]) -> float | None:
    """The value of the first numeric scalar whose (lower-case) name is one of ``keys``."""
    for name, v in arrays.items():
        if name.lower() in keys:
            v = np.asarray(v)
            if v.size == 1 and v.dtype.kind in "iuf":
                return float(v.reshape(()))
    return None


def pick_data(path: str, arrays: dict, chosen: str | None, option: str, what: str) -> str:
    """The name of the data array/variable: ``chosen``, else the only candidate."""
    numeric = {k: v for k, v in arrays.items() if isinstance(v, np.ndarray) and v.dtype.kind in "iufb"}
    if chosen is not None:
        if chosen not in arrays:
            raise ImportFailure(f"{path}: no {what} {chosen!r} ({what}s: {', '.join(arrays) or 'none'}); "
                                f"use {option}")
        return chosen
    multi = [k for k, v in numeric.items() if v.ndim >= 2 and min(v.shape) >= 1 and v.size > 1]
    if len(multi) != 1:
        multi = [k for k, v in numeric.items() if v.size > 1]
    if len(multi) == 1:
        return multi[0]
    listing = ", ".join(f"{k} {tuple(np.shape(v))}" for k, v in arrays.items()) or "none"
    raise ImportFailure(f"{path}: {'no numeric ' + what if not multi else 'several ' + what + 's'} "
                        f"to import ({what}s: {listing}); choose one with {option}")


def read_npz(path: str, array: str | None) -> Table:
    with _load(path) as z:
        try:
            arrays = {k: z[k] for k in z.files}
        except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
            raise ImportFailure(f"{path}: an array cannot be read ({' '.join(str(exc).split())}); "
                                "save the archive with numeric arrays only") from None
    name = pick_data(path, arrays, array, "--array", "array")
    data = as_snapshot_array(path, f"array {name!r}", arrays[name])
    times = None
    for k, v in arrays.items():
        if k != name and k.lower() in TIME_KEYS and v.ndim == 1 and v.size == data.shape[0] \
                and v.dtype.kind in "iuf" and data.shape[0] > 1:
            times = v.astype(np.float64)
    return Table(path=path, data=data, columns=_columns(name, data.shape[2]), kind="channel",
                 fs=scalar_named(arrays, FS_KEYS), times=times, rpm=scalar_named(arrays, RPM_KEYS))
