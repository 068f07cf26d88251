"""The amplitude spectrum of a captured signal: Welch's average of Hann-windowed segments.

``amplitude_spectrum(x, fs)`` gives (f, A) with A the RMS amplitude per bin (a sine
of RMS a shows as a at its frequency): the square root of scipy's Welch
``scaling="spectrum"`` estimate over segments of at most ``MAX_SEGMENT`` samples with
half overlap, so a 20-s capture at 25 kHz gives 4097 bins 3.05 Hz apart.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import welch

__all__ = ["amplitude_spectrum", "MAX_SEGMENT"]

MAX_SEGMENT = 8192


def amplitude_spectrum(x: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(f [Hz], RMS amplitude per bin) of the 1-D signal x sampled at fs."""
    x = np.asarray(x, dtype=np.float64)
    n = int(min(MAX_SEGMENT, max(8, x.size)))
    f, P = welch(x, fs=fs, window="hann", nperseg=min(n, x.size), scaling="spectrum")
    return f, np.sqrt(P)
