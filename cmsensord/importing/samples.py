"""The recording's samples while an import runs: in memory up to a bound, beyond it on disk,
so that an import's memory does not grow with the recording.

A :class:`SampleStore` takes each file's channels as they are read (:meth:`~SampleStore.append`,
float64 m/s²), keeps each channel's peak |x| and its count of missing values (NaN) on the
way, and gives back any stretch of samples (:meth:`~SampleStore.read`). Up to ``memory_mb``
of samples stay in memory; past that, all of them go to an unnamed temporary file in the output's directory (8 bytes a
sample a channel, beside the capture's 2), which goes when the store is closed or when the
process ends however it ends, so an import never leaves it behind. A disk without that room
ends the import with a one-line :class:`~.errors.ImportFailure`.
"""

from __future__ import annotations

import bisect
import os
import tempfile
from pathlib import Path
from typing import BinaryIO

import numpy as np

from .errors import cannot_write, no_room

__all__ = ["MEMORY_MB", "SampleStore"]

MEMORY_MB = 64.0
_ITEM = np.dtype(np.float64).itemsize


class SampleStore:
    """Samples of ``n_channels`` channels, appended in order and read back by sample index."""

    def __init__(self, n_channels: int, out: str, memory_mb: float = MEMORY_MB):
        self.n_channels = n_channels
        self.n_samples = 0
        self.peak = np.zeros(n_channels)
        self.missing = np.zeros(n_channels, dtype=np.int64)     # NaN samples of each channel
        self._out = out
        self._memory_bytes = memory_mb * 1e6
        self._parts: list[np.ndarray] = []  # in memory: (C, n) arrays end to end
        self._ends: list[int] = []          # sample index after each part
        self._file: BinaryIO | None = None
        if not Path(out).resolve().parent.is_dir():
            raise cannot_write(out, "No such file or directory")

    @property
    def on_disk(self) -> bool:
        return self._file is not None

    def append(self, x: np.ndarray) -> None:
        """Add ``x`` (n_channels, n) at the end."""
        if x.shape[0] != self.n_channels:
            raise ValueError(f"{x.shape[0]} channels, the store holds {self.n_channels}")
        if not x.shape[1]:
            return
        np.fmax(self.peak, np.fmax.reduce(np.abs(x), axis=1), out=self.peak)     # NaN (missing) not counted
        self.missing += np.isnan(x).sum(axis=1)
        self.n_samples += x.shape[1]
        if self._file is None and self.n_samples * self.n_channels * _ITEM <= self._memory_bytes:
            self._parts.append(np.asarray(x, dtype=np.float64))
            self._ends.append(self.n_samples)
            return
        if self._file is None:
            self._spill()
        self._write(x)

    def _spill(self) -> None:
        """Move what is in memory to a new unnamed file beside the output."""
        try:
            self._file = tempfile.TemporaryFile(dir=Path(self._out).resolve().parent)
        except OSError as exc:
            raise cannot_write(self._out, exc.strerror or str(exc)) from None
        parts, self._parts, self._ends = self._parts, [], []
        for part in parts:
            self._write(part)

    def _write(self, x: np.ndarray) -> None:
        assert self._file is not None
        try:
            self._file.write(np.ascontiguousarray(x.T, dtype=np.float64).tobytes())
        except OSError as exc:
            mb = self.n_samples * self.n_channels * _ITEM / 1e6
            where = (f"{self._out}: no room on its disk for the samples read so far ({mb:,.1f} MB, 8 bytes a "
                     "sample a channel, held there until the capture is written)")
            raise no_room(where, exc.strerror or str(exc)) from None

    def read(self, a: int, b: int) -> np.ndarray:
        """Samples ``a`` to ``b`` (not included), float64 (n_channels, b - a)."""
        if not 0 <= a <= b <= self.n_samples:
            raise IndexError(f"samples {a}..{b} of {self.n_samples}")
        if self._file is None:
            return self._read_memory(a, b)
        self._file.flush()
        row = self.n_channels * _ITEM
        out = bytearray((b - a) * row)
        view, done = memoryview(out), 0
        while done < len(out):
            n = os.preadv(self._file.fileno(), [view[done:]], a * row + done)
            if n <= 0:
                raise OSError(f"the samples' file ends at byte {a * row + done}")
            done += n
        return np.frombuffer(out, dtype=np.float64).reshape(b - a, self.n_channels).T

    def _read_memory(self, a: int, b: int) -> np.ndarray:
        k = bisect.bisect_right(self._ends, a)
        pieces = []
        while a < b:
            start = self._ends[k - 1] if k else 0
            stop = min(b, self._ends[k])
            pieces.append(self._parts[k][:, a - start:stop - start])
            a, k = stop, k + 1
        if len(pieces) == 1:
            return pieces[0]
        return np.concatenate(pieces, axis=1) if pieces else np.empty((self.n_channels, 0))

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
        self._parts, self._ends = [], []

    def __enter__(self) -> SampleStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
