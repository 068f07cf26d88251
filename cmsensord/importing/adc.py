"""The board's 12-bit ADC for imported data: full-scale range, scale/offset, counts.

A channel with full-scale range R (m/s², the counts cover -R .. +R) gets

    scale  = float32(R / 2048)   m/s² per count (what STATUS carries)
    offset = 2048                counts at 0 m/s²
    count  = clip(rint(x / scale + offset), 0, 4095)

computed with the float32 scale, as the board does, so that ``(count - offset)
* scale`` with the STATUS values is exactly the value the count stands for and
lies within half a count of the imported sample unless it clipped. A block in
which a sample sits at 0 or 4095 is a clipped block (docs/PROTOCOL.md, flags
bit 1).

The default range is ``max |x| x 1.25`` rounded up to the next value of a
1-1.2-1.5-2-2.5-3-4-5-6-8 series (a decade of "nice" full scales), so a
default import never clips.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ADC_MAX", "OFFSET", "HEADROOM", "MAX_RANGE", "nice_range", "scale_for", "to_counts", "clipped"]

ADC_MAX = 4095
OFFSET = 2048.0
#: the largest full scale whose scale STATUS carries (a float32, m/s² a count)
MAX_RANGE = float(np.finfo(np.float32).max) * OFFSET
HEADROOM = 1.25
_NICE = (1.0, 1.2, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0)


def nice_range(max_abs: float) -> float:
    """The smallest value of the 1-1.2-1.5-2-...-8 series >= ``max_abs`` x HEADROOM (1.0 for silence)."""
    want = float(max_abs) * HEADROOM
    if not want > 0 or not math.isfinite(want):
        return 1.0
    decade = 10.0 ** math.floor(math.log10(want))
    for m in _NICE:
        r = float(f"{m * decade:.6g}")  # 1.2e-05, not 1.2000000000000002e-05
        if r >= want * (1 - 1e-12):
            return r
    return 10.0 * decade  # pragma: no cover - 10.0 closes the series


def scale_for(full_scale: float) -> float:
    """m/s² per count for a full-scale range of +-``full_scale``, rounded to float32 (STATUS)."""
    return float(np.float32(full_scale / OFFSET))


def to_counts(x: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """uint16 counts of ``x`` (C, ...) in m/s² with per-channel ``scale`` (C,) and offset 2048."""
    s = np.asarray(scale, dtype=np.float64).reshape((-1,) + (1,) * (x.ndim - 1))
    with np.errstate(over="ignore"):     # a value far past the range: clipped as any past it
        y = x / s
    y += OFFSET
    np.rint(y, out=y)
    np.clip(y, 0, ADC_MAX, out=y)
    return y.astype(np.uint16)


def clipped(counts: np.ndarray) -> np.ndarray:
    """bool, the last axis reduced: a sample of the block sits at 0 or 4095."""
    return ((counts == 0) | (counts == ADC_MAX)).any(axis=-1)
