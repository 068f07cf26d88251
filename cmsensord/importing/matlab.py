"""MATLAB reader: ``.mat`` v4/v5/v7 through ``scipy.io.loadmat`` (choose with ``--variable``).

Without ``--variable`` the one numeric variable with at least two elements is
the data; a struct's fields are variables ``struct.field``; scalars named like a
sampling rate (``fs``, ``Fs``, ``sample_rate``, ``sr``) or a speed (``rpm``,
``X097RPM``; a struct's ``rate`` beside its ``sr``, the shaft's Hz as MFPT's) are read as
such (:mod:`.variables`, also for ``--variable A,B``
and patterns such as ``*_DE_time``). v7.3 files are HDF5, which scipy does not
read: with the optional ``mat73`` extra (h5py) their numeric variables, structs' fields and
arrays of structs' are read as loadmat would give the same variables of a v7 file (MATLAB stores them
transposed; text and cell arrays are left out); without it the error says how to re-save
them. Axes: see :func:`.table.as_snapshot_array`.
"""

from __future__ import annotations

import zlib

import numpy as np

from .errors import ImportFailure
from .table import FS_KEYS, Table
from .variables import flatten, rpm_named, scalar_named, selected, shaft_rate

__all__ = ["read_mat"]


def read_mat(path: str, variable: tuple[str, ...] | None, slow: str | None = None, rpm_given: bool = False) -> Table:
    """The variables ``variable`` of a .mat file side by side (``slow``: the speed column,
    :func:`~.variables.selected`), and the rate and speed it names (a speed read from a struct's
    ``rate`` with a note, unless ``rpm_given``: ``--rpm`` gives it)."""
    import scipy.io  # 0.3 s to import: only when a .mat file is read

    try:
        m = scipy.io.loadmat(path)
    except NotImplementedError:
        m = _read_v73(path)
    except zlib.error as exc:
        raise ImportFailure(f"{path}: a compressed variable is damaged ({exc}): the file is corrupt or cut "
                            "short; copy it again") from None
    except (ValueError, TypeError, OSError, scipy.io.matlab.MatReadError) as exc:
        raise ImportFailure(f"{path}: not a readable MATLAB file ({' '.join(str(exc).split())})") from None
    arrays = flatten({k: v for k, v in m.items() if not k.startswith("__")})
    data, columns, note = selected(path, arrays, variable, "--variable", "variable", slow)
    fs_keys = tuple(k.lower() for k in FS_KEYS)
    rpm = rpm_named(arrays, path)
    if rpm is None and (shaft := shaft_rate(arrays, fs_keys)) is not None:
        name, hz, sr = shaft
        rpm = 60.0 * hz
        said = (f"{name} {hz:g} beside the sampling rate {sr}: taken as the shaft's speed in Hz, {rpm:g} rpm "
                "(the MFPT bearing files' layout); --rpm gives another")
        note = note if rpm_given else f"{note}; {said}" if note else said
    return Table(path=path, data=data, columns=columns, kind="column", layout_note=note,
                 fs=scalar_named(arrays, fs_keys), rpm=rpm)


def _read_v73(path: str) -> dict:
    """A MATLAB v7.3 (HDF5) file's numeric variables, ``struct.field`` for a struct's, each
    transposed back to MATLAB's axes (as loadmat gives them); an array of structs (its fields
    references to each element's value) as the record array loadmat gives, which
    :func:`~.variables.flatten` names by its elements' ``Name`` (text as a string)."""
    try:
        import h5py
    except ImportError:
        raise ImportFailure(f"{path}: a MATLAB v7.3 (HDF5) file: reading it needs h5py (pip install "
                            "'cmsensord[mat73]'); or in MATLAB re-save it with save(FILE, VAR, '-v7'), or "
                            "export it as CSV") from None
    out: dict = {}
    arrays: dict[str, dict] = {}        # an array of structs: its fields' references, by its name

    def take(name: str, obj) -> None:
        kind = _class(obj.attrs) if isinstance(obj, h5py.Dataset) else b"group"
        if name.startswith("#") or kind == b"group":
            return
        if h5py.check_ref_dtype(obj.dtype) is not None and _class(obj.parent.attrs) == b"struct":
            arrays.setdefault(obj.parent.name.strip("/").replace("/", "."), {})[name.rsplit("/", 1)[-1]] = obj
        elif kind not in (b"char", b"cell") and obj.dtype.kind in "iufb":
            out[name.replace("/", ".")] = obj[()].T

    try:
        with h5py.File(path, "r") as f:
            f.visititems(take)
            for name, fields in arrays.items():
                out[name] = _records(f, fields)
    except (OSError, ValueError, KeyError, RuntimeError) as exc:      # h5py's words for damaged bytes
        raise ImportFailure(f"{path}: a MATLAB v7.3 (HDF5) file that cannot be read "
                            f"({' '.join(str(exc).split())})") from None
    return out


def _class(attrs) -> bytes:
    kind = attrs.get("MATLAB_class", b"")
    return kind.encode() if isinstance(kind, str) else bytes(kind)


def _records(f, fields: dict) -> np.ndarray:
    """An array of structs of a v7.3 file as a record array: each element's field the value its
    reference leads to, numeric transposed, text a one-element string array, else None."""
    refs = {k: v[()].T.reshape(-1) for k, v in fields.items()}
    n = min(r.size for r in refs.values())
    recs = np.empty(n, dtype=[(k, "O") for k in refs])
    for k, r in refs.items():
        for i in range(n):
            target = f[r[i]]
            value = target[()] if hasattr(target, "dtype") else None
            if value is not None and _class(target.attrs) == b"char":
                value = np.array(["".join(map(chr, np.asarray(value).reshape(-1)))])
            elif value is not None and value.dtype.kind in "iufb":
                value = value.T
            else:
                value = None
            recs[i][k] = value
    return recs
