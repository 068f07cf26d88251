"""NumPy reader: ``.npy`` (one array) and ``.npz`` (choose the array with ``--array``).

In an ``.npz`` archive without ``--array``, the one array with at least two
dimensions is the data (a single 1-D array otherwise; :mod:`.variables` for
``--array A,B`` and patterns); scalars named like a
sampling rate (``fs``, ``fs_hz``, ``sample_rate``, ...) or a speed (``rpm``),
and a 1-D array of snapshot start times (``t``, ``t_s``, ``time``, ...) whose
length is the number of snapshots, are read as such. Axes: see
:func:`.table.as_snapshot_array` (a 3-D array is snapshots x samples x channels).
"""

from __future__ import annotations

import struct
import zipfile
import zlib

import numpy as np

from .errors import ImportFailure
from .table import FS_KEYS, TIME_KEYS, Table, as_snapshot_array
from .variables import rpm_named, scalar_named, selected

__all__ = ["read_npy", "read_npz"]


def _load(path: str, mmap: bool = False):
    try:
        return np.load(path, allow_pickle=False, mmap_mode="r" if mmap else None)
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        raise ImportFailure(f"{path}: not a readable NumPy file ({' '.join(str(exc).split())})") from None


def _columns(name: str, n: int) -> list[str]:
    return [name] if n == 1 else [f"{name}_{i}" for i in range(n)]


def read_npy(path: str) -> Table:
    """The array of an .npy file, a memory map of the file (the import converts a stretch at a time)."""
    a = _load(path, mmap=True)
    data = as_snapshot_array(path, "the array", a)
    return Table(path=path, data=data, columns=_columns("ch", data.shape[2]), kind="channel")


def read_npz(path: str, array: tuple[str, ...] | None, slow: str | None = None) -> Table:
    """The arrays ``array`` of an .npz archive side by side (``slow``: the speed column,
    :func:`~.variables.selected`), and the rate, times and speed it holds. An array stored
    uncompressed (``np.savez``) is a memory map of the archive, so one long array is converted
    a stretch at a time, as an .npy file's; a compressed one is read."""
    with _load(path) as z:
        try:
            arrays = {k: z[k] if (m := _mapped(path, z.zip, k)) is None else m for k in z.files}
        except (OSError, zipfile.BadZipFile, EOFError, zlib.error) as exc:
            raise ImportFailure(f"{path}: an array cannot be read ({' '.join(str(exc).split())}): the archive is "
                                "corrupt or cut short; copy it again") from None
        except ValueError as exc:
            raise ImportFailure(f"{path}: an array cannot be read ({' '.join(str(exc).split())}); "
                                "save the archive with numeric arrays only") from None
    data, columns, note = selected(path, arrays, array, "--array", "array", slow)
    times = None
    for k, v in arrays.items():
        if k.lower() in TIME_KEYS and v.ndim == 1 and v.size == data.shape[0] \
                and v.dtype.kind in "iuf" and data.shape[0] > 1:
            times = v.astype(np.float64)
    return Table(path=path, data=data, columns=columns, kind="channel", layout_note=note,
                 fs=scalar_named(arrays, FS_KEYS), times=times, rpm=rpm_named(arrays, path))


#: arrays smaller than this are read, not mapped
MAP_BYTES = 1 << 20


def _mapped(path: str, zf: zipfile.ZipFile, name: str) -> np.memmap | None:
    """Member ``name`` (``A.npy``'s ``A``) of the archive as a read-only memory map, when it is
    stored uncompressed, numeric, in an .npy format version numpy reads publicly and at least
    MAP_BYTES long; else None (read it)."""
    info = zf.getinfo(f"{name}.npy") if f"{name}.npy" in zf.NameToInfo else zf.getinfo(name)
    if info.compress_type != zipfile.ZIP_STORED or info.file_size < MAP_BYTES:
        return None
    with open(path, "rb") as f:
        f.seek(info.header_offset)
        local = f.read(30)                  # the local file header: its name and extra field follow
        if len(local) < 30 or local[:4] != b"PK\x03\x04":
            return None
        name_len, extra_len = struct.unpack("<HH", local[26:30])
        f.seek(info.header_offset + 30 + name_len + extra_len)
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
        else:
            return None
        offset = f.tell()
    if dtype.hasobject or dtype.kind not in "iufb" or not shape:
        return None
    return np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=shape, order="F" if fortran else "C")
