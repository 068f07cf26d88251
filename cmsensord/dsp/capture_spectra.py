"""The amplitude spectrum of a captured signal: Welch's average of Hann-windowed segments (numpy only).

``amplitude_spectrum(x, fs)`` gives (f, A) with A the RMS amplitude per bin (a sine
of RMS a shows as a at its frequency): the square root of the mean one-sided power
spectrum of segments of at most ``MAX_SEGMENT`` samples with half overlap, each with
its mean removed and a Hann window, scaled by 1 / (sum of the window)^2 (as scipy's
``welch(..., scaling="spectrum")``), so a 20-s capture at 25 kHz gives 4097 bins
3.05 Hz apart. numpy only: the daemon does not load scipy for it.

``envelope_rms_spectrum(x, fs, band)`` gives the envelope spectrum of the band in the
same unit, RMS per bin: the indicators' envelope spectrum
(:func:`~cmsensord.dsp.indicators.envelope.envelope_spectrum`, 0-peak: a modulation
m cos(2 pi f t) of the envelope reads m) divided by sqrt(2), so a modulation reads its RMS
m / sqrt(2), as ``envelope_rms`` of the indicators counts it.
"""

from __future__ import annotations

import numpy as np

from cmsensord.dsp.indicators.envelope import envelope, envelope_spectrum

__all__ = ["amplitude_spectrum", "envelope_rms_spectrum", "MAX_SEGMENT"]

MAX_SEGMENT = 8192


def amplitude_spectrum(x: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(f [Hz], RMS amplitude per bin) of the 1-D signal x sampled at fs."""
    x = np.asarray(x, dtype=np.float64)
    n = int(min(MAX_SEGMENT, max(8, x.size)))
    n = min(n, x.size)
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(n) / n)          # periodic Hann, as scipy's "hann"
    step = max(1, n // 2)
    P = np.zeros(n // 2 + 1)
    count = 0
    for a in range(0, x.size - n + 1, step):
        seg = x[a:a + n]
        P += np.abs(np.fft.rfft((seg - seg.mean()) * w)) ** 2
        count += 1
    P /= max(count, 1) * w.sum() ** 2
    P[1:n // 2 + (n % 2)] *= 2.0                                     # one-sided: all but DC (and Nyquist)
    return np.fft.rfftfreq(n, 1.0 / fs), np.sqrt(P)


def envelope_rms_spectrum(x: np.ndarray, fs: float,
                          band: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """(f [Hz], RMS amplitude per bin, the band demodulated [Hz]) of the envelope of ``band``
    of the 1-D signal x sampled at fs (one Hann-windowed transform of the whole envelope)."""
    env = envelope(x, fs, band)
    f, A = envelope_spectrum(env.env, env.fs_env)
    return f, A / np.sqrt(2.0), env.band
