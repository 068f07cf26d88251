"""The process heap of a replay or the live daemon: freed memory kept for the next allocation.

glibc's malloc serves a request above its mmap threshold (128 KiB at start, raised
as such blocks are freed) with a fresh ``mmap`` and gives it back at the ``free``,
and returns the free top of the heap to the system above its trim threshold: a
replay, whose chain makes and frees arrays of 0.1-1 MB every call (an interval of
samples, its transforms, a read's blocks), then pays a page fault per 4 KiB page of
each new array (the kernel zeroes it) again and again: ~18,000 of the ~26,000 page
faults of a 120-s RAW replay.  :func:`keep_freed_memory` raises both thresholds, so
such arrays come from the heap and their pages are reused; the process's peak
resident memory is what it was (the same arrays at once), the memory it frees stays
with it until it exits.  The live daemon makes the same arrays every 100-ms call (an
indicator interval's transforms once a second): RAW 1 channel + tacho live at 1x used
~7 % less CPU with it (``bench/bench_live.py``, two side-by-side runs), peak RSS 47-49 MB.
A no-op where the C library has no ``mallopt`` (not glibc).
"""

from __future__ import annotations

import ctypes

__all__ = ["keep_freed_memory", "MMAP_THRESHOLD", "TRIM_THRESHOLD"]

#: requests up to this size come from the heap (not a fresh mmap)
MMAP_THRESHOLD = 32 << 20
#: the free top of the heap is returned to the system only above this size
TRIM_THRESHOLD = 64 << 20
#: glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds for this process (see module docstring);
    True when they were set, False where the C library does not take them."""
    try:
        mallopt = ctypes.CDLL(None).mallopt       # the C library the interpreter runs on
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
