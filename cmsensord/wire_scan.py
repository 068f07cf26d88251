"""The decoder's scan of a receive buffer in one call of the compiled wire kernel.

``cmsensord._wirekernel`` (``cmsensord/_wirekernel.c``, built by ``pip install`` when a C
compiler is present) runs the frame-by-frame loop of
:class:`cmsensord.protocol.Decoder` (docs/PROTOCOL.md receiver rules 1-5: the sync hunt,
header checks, each frame's CRC-32 on its own bytes, seq gaps, t0 unwrapping, the
counters) over a whole buffer and writes every good frame's fields as one column of ten
int64 rows: a :class:`~cmsensord.frame_batch.Columns`, what the numpy run path
(:mod:`cmsensord.frame_runs`) builds for runs of back-to-back frames; or, asked for
frames (a live read of a few), makes the :class:`~cmsensord.protocol.Frame` tuples itself.  The frames, byte
offsets and counters are those of the plain loop (``Decoder(runs=False)``); only the
Python work per frame (a CRC call, a header unpack, a tuple) is gone.  Without the
kernel (:func:`have_kernel` False) the decoder runs its Python loop and numpy runs.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cmsensord.frame_batch import Columns

try:
    from cmsensord import _wirekernel  # type: ignore[attr-defined]
except ImportError:             # not built (no compiler at install): the Python loop runs
    _wirekernel = None

__all__ = ["KernelScan", "WireScanner", "have_kernel"]

_ROWS = len(Columns._fields)
_MIN_FRAME = 18                 # header and CRC: no frame is shorter


def have_kernel() -> bool:
    """Whether ``cmsensord._wirekernel`` is built (importable)."""
    return _wirekernel is not None


class KernelScan(NamedTuple):
    """What one scan of a buffer found, and the receiver's state after it."""

    frames: Columns | list | None   # the good frames: columns, Frame tuples when asked (None: none)
    consumed: int               # bytes of the buffer done with (frames and discarded bytes)
    discarded: int
    header_rejects: int
    crc_failures: int
    lost: int                   # frames lost by seq gaps (rule 3)
    overruns: int               # frames carrying FLAG_OVERRUN
    by_code: tuple[int, ...]    # good frames per type code (index 0 unused)
    last_seq: int | None
    last_t0: int
    last_unw: int


class WireScanner:
    """Scans buffers with the compiled kernel, into scratch rows kept between calls (one
    decoder's: not shared between threads)."""

    def __init__(self, version: int, max_type: int, max_payload: int):
        if _wirekernel is None:
            raise ImportError("cmsensord._wirekernel is not built: install a C compiler and reinstall")
        self._params = (version, max_type, max_payload)
        self._rows = np.empty((_ROWS, 0), dtype=np.int64)

    def scan(self, buf: bytearray, final: bool, base: int, last_seq: int | None, last_t0: int,
             last_unw: int, make: tuple[type, tuple] | None = None) -> KernelScan:
        """Frame every complete candidate of ``buf`` (stream offset ``base``) after a frame of
        ``last_seq``/``last_t0``/``last_unw`` (None: no frame yet); with ``final``, incomplete
        candidates are not frames (their first sync byte is dropped, as at the end of a stream).
        ``make`` (the Frame class, the type of each code by index): the frames as a list of
        Frame tuples instead of columns."""
        state = (base, -1 if last_seq is None else last_seq, last_t0, last_unw)
        if make is not None:
            frames, *found = _wirekernel.scan(buf, final, *self._params, *state, None, *make)
            return KernelScan(frames or None, *found)
        need = len(buf) // _MIN_FRAME + 1
        if self._rows.shape[1] < need:
            self._rows = np.empty((_ROWS, max(need, 2 * self._rows.shape[1])), dtype=np.int64)
        k, *found = _wirekernel.scan(buf, final, *self._params, *state, self._rows, None, None)
        return KernelScan(Columns(*self._rows[:, :k].copy()) if k else None, *found)
