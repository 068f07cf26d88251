"""Band RMS: the acceleration RMS in a frequency band, fixed in Hz or in orders of the shaft speed.

The root of the sum of the Hann power spectrum (:mod:`.spectrum`) over the bins
with lo <= f <= hi (summed by :func:`~.interval.compute`); an order band [lo, hi] x
shaft speed in Hz (:func:`order_band_hz`).  The sum of band RMS^2 over bands tiling
0-fs/2 is the overall mean square.
"""

from __future__ import annotations

__all__ = ["order_band_hz"]


def order_band_hz(lo_order: float, hi_order: float, shaft_hz: float) -> tuple[float, float]:
    """An order band in Hz at the shaft speed ``shaft_hz``."""
    return lo_order * shaft_hz, hi_order * shaft_hz
