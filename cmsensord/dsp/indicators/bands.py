"""Band RMS: the acceleration RMS in a frequency band, fixed in Hz or in orders of the shaft speed.

The root of the sum of the Hann power spectrum (:mod:`.spectrum`) over the bins
with lo <= f <= hi; an order band [lo, hi] x shaft speed in Hz.  The sum of band
RMS^2 over bands tiling 0-fs/2 is the overall mean square.
"""

from __future__ import annotations

import numpy as np

from .spectrum import band_mask

__all__ = ["band_rms", "order_band_hz"]


def band_rms(f: np.ndarray, P: np.ndarray, lo: float, hi: float) -> float:
    """RMS of the power spectrum P (bins at f) between lo and hi Hz (0 when no bin is in it)."""
    return float(np.sqrt(P[band_mask(f, lo, hi)].sum()))


def order_band_hz(lo_order: float, hi_order: float, shaft_hz: float) -> tuple[float, float]:
    """An order band in Hz at the shaft speed ``shaft_hz``."""
    return lo_order * shaft_hz, hi_order * shaft_hz
