"""Acceleration waveform statistics of one interval: RMS, peak, crest factor, kurtosis.

Over the interval's samples with their mean removed (an accelerometer's DC
offset is no vibration):

* RMS = sqrt(mean(x^2)), peak = max |x| (m/s^2);
* crest factor = peak / RMS (sqrt(2) for a sine; impacts of a damaged bearing raise it);
* kurtosis = mean(x^4) / mean(x^2)^2, not the excess (3 for Gaussian noise, 1.5 for a
  sine; impacts raise it).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["WaveformStats", "waveform_stats"]


class WaveformStats(NamedTuple):
    rms: float
    peak: float
    crest_factor: float
    kurtosis: float


def waveform_stats(x: np.ndarray) -> WaveformStats:
    """The statistics of the finite samples of x (1-D); NaN for all four when fewer than
    2 samples or a zero signal."""
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size < 2:
        nan = float("nan")
        return WaveformStats(nan, nan, nan, nan)
    d = x - x.mean()
    d2 = d * d                  # sums, not np.dot: BLAS threads stall on a busy machine
    m2 = float(d2.sum()) / d.size
    if m2 <= 0.0:
        return WaveformStats(0.0, 0.0, float("nan"), float("nan"))
    m4 = float((d2 * d2).sum()) / d.size
    rms = m2 ** 0.5
    peak = float(np.max(np.abs(d)))
    return WaveformStats(rms, peak, peak / rms, m4 / (m2 * m2))
