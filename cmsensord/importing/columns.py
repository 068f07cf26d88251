"""Columns read a stretch at a time: a file's channels as a table without reading them whole.

:class:`Columns` stands for a :class:`~.table.Table`'s ``data`` (one snapshot, ``n`` samples,
one column per channel) where each channel is read from its file on demand, a stretch of
samples at a time (a TDMS file's channels through npTDMS's streaming reader), so an import's
memory does not grow with the file. It answers what the import asks of ``data``: its
``shape``, ``[s, a:b, i]`` (one column's stretch) and ``[:, :, i]`` (one column whole, for a
tacho or speed column), and ``close()`` lets go of the file.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["Columns"]

#: reads samples a..b (not included) of one channel
Reader = Callable[[int, int], np.ndarray]


class Columns:
    """``len(readers)`` channels of ``n`` samples each, as a (1, n, C) table (see module docstring)."""

    def __init__(self, readers: Sequence[Reader], n: int, dtype: np.dtype,
                 close: Callable[[], None] = lambda: None):
        self.readers = list(readers)
        self.shape = (1, int(n), len(self.readers))
        self.dtype = np.dtype(dtype)
        self.ndim = 3
        self.close = close

    def __getitem__(self, key: tuple) -> np.ndarray:
        s, rows, col = key
        if not isinstance(col, (int, np.integer)) or not isinstance(rows, slice):
            raise TypeError(f"Columns[{key!r}]: one column and a slice of samples only")
        a, b, step = rows.indices(self.shape[1])
        if step != 1:
            raise TypeError("Columns: a stretch of consecutive samples only")
        x = np.asarray(self.readers[int(col)](a, b)) if b > a else np.empty(0, self.dtype)
        if x.shape != (max(0, b - a),):
            raise ValueError(f"column {int(col)}: read {x.shape[0]} samples of {a}..{b}")
        return x if isinstance(s, (int, np.integer)) else x[None]
