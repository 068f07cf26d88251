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

__all__ = ["WaveformStats", "waveform_stats", "centred_stats", "centred_stats_rows"]


class WaveformStats(NamedTuple):
    rms: float
    peak: float
    crest_factor: float
    kurtosis: float


def waveform_stats(x: np.ndarray) -> WaveformStats:
    """The statistics of the finite samples of x (1-D); NaN for all four when fewer than
    2 samples or a zero signal."""
    x = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(x)
    if not ok.all():
        x = x[ok]
    if x.size < 2:
        nan = float("nan")
        return WaveformStats(nan, nan, nan, nan)
    return centred_stats(x - x.mean())


def centred_stats(d: np.ndarray) -> WaveformStats:
    """The statistics of finite samples d (1-D, at least 2) whose mean is already removed
    (``d = x - x.mean()``): the numbers of :func:`waveform_stats` (x), bit for bit, in
    fewer passes (the peak from the largest and smallest sample, not from ``|d|``)."""
    d2 = d * d                  # sums, not np.dot: BLAS threads stall on a busy machine
    m2 = float(d2.sum()) / d.size
    d2 *= d2
    return _of_sums(m2, float(d2.sum()) / d.size, float(d.max()), float(d.min()))


def centred_stats_rows(D: np.ndarray) -> list[WaveformStats]:
    """:func:`centred_stats` of each row of D (R, N), C-contiguous, each row's mean already
    removed: the same numbers bit for bit (each row's sums are numpy's pairwise sums of that
    row, as of the row alone) in one pass per quantity over all rows instead of one per row."""
    N = D.shape[1]
    D2 = D * D
    s2 = D2.sum(axis=1).tolist()
    D2 *= D2
    s4 = D2.sum(axis=1).tolist()
    return [_of_sums(sum2 / N, sum4 / N, hi, lo)
            for sum2, sum4, hi, lo in zip(s2, s4, D.max(axis=1).tolist(), D.min(axis=1).tolist())]


def _of_sums(m2: float, m4: float, hi: float, lo: float) -> WaveformStats:
    """The statistics of centred samples from their mean square m2, mean fourth power m4,
    largest and smallest value (a silent record, m2 0: rms and peak 0, the ratios NaN)."""
    if m2 <= 0.0:
        return WaveformStats(0.0, 0.0, float("nan"), float("nan"))
    rms = m2 ** 0.5
    peak = max(hi, -lo)
    return WaveformStats(rms, peak, peak / rms, m4 / (m2 * m2))
