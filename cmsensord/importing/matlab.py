"""MATLAB reader: ``.mat`` v4/v5/v7 through ``scipy.io.loadmat`` (choose with ``--variable``).

Without ``--variable`` the one numeric variable with at least two elements is
the data; scalars named like a sampling rate (``fs``, ``Fs``, ``sample_rate``)
or a speed (``rpm``) are read as such. v7.3 files are HDF5, which scipy does not
read: the error says how to re-save them. Axes: see :func:`.table.as_snapshot_array`.
"""

from __future__ import annotations

import numpy as np

from .arrays import pick_data, scalar_named
from .errors import ImportFailure
from .table import FS_KEYS, RPM_KEYS, Table, as_snapshot_array

__all__ = ["read_mat"]


def read_mat(path: str, variable: str | None) -> Table:
    import scipy.io  # 0.3 s to import: only when a .mat file is read

    try:
        m = scipy.io.loadmat(path)
    except NotImplementedError:
        raise ImportFailure(f"{path}: a MATLAB v7.3 (HDF5) file, which scipy.io cannot read; in MATLAB "
                            "re-save it with save(FILE, VAR, '-v7') or export it as CSV") from None
    except (ValueError, TypeError, OSError, scipy.io.matlab.MatReadError) as exc:
        raise ImportFailure(f"{path}: not a readable MATLAB file ({' '.join(str(exc).split())})") from None
    arrays = {k: v for k, v in m.items() if not k.startswith("__")}
    name = pick_data(path, arrays, variable, "--variable", "variable")
    v = arrays[name]
    if not isinstance(v, np.ndarray) or v.dtype.kind not in "iufb":
        kind = "a struct" if getattr(v, "dtype", None) is not None and v.dtype.names else \
            f"of type {getattr(v, 'dtype', type(v).__name__)}"
        raise ImportFailure(f"{path}: variable {name!r} is {kind}, not a numeric array; "
                            "choose a numeric one with --variable")
    data = as_snapshot_array(path, f"variable {name!r}", v)
    cols = [name] if data.shape[2] == 1 else [f"{name}_{i}" for i in range(data.shape[2])]
    return Table(path=path, data=data, columns=cols, kind="column",
                 fs=scalar_named(arrays, tuple(k.lower() for k in FS_KEYS)),
                 rpm=scalar_named(arrays, RPM_KEYS))
