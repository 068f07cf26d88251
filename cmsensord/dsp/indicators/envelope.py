"""Acceleration enveloping (demodulation) and the envelope spectrum at defect frequencies.

The impacts of a bearing defect excite structural resonances of a few kHz; their
repetition rate (BPFO, BPFI, ...) shows in the *envelope* of the band around
the resonance, not in the raw spectrum (Randall & Antoni 2011, envelope analysis).  Here,
for one record of N samples at fs, all in the frequency domain (numpy FFT, no
filter design):

1. band-pass: the bins of X = rfft(x) in [lo, hi] (rectangular, zero-phase);
2. Hilbert: those bins alone, doubled, are the analytic signal of the band; its
   magnitude is the envelope.  The band is moved to 0 Hz before the inverse FFT
   (a frequency shift leaves the magnitude unchanged) and the inverse FFT has only
   M = 2 x (bins in the band) points, rounded up to a fast length: the envelope
   comes out decimated to fs_env = M / T (T = N / fs), with room for its own
   spectrum up to fs_env / 2 ~ the bandwidth.  A band of one bin is a single tone, whose
   analytic signal has a constant magnitude whatever the signal: it carries no modulation (the
   envelope spectrum of a band reaches no further than its width, Randall & Antoni 2011), and
   the indicators give no envelope of it, as of a band of none (``IndicatorRecord.envelope_rms``
   NaN);
3. envelope RMS: the RMS of the envelope minus its mean (m/s^2);
4. envelope spectrum: Hann-windowed amplitude spectrum of the envelope minus its
   mean, scaled so that a modulation m cos(2 pi f t) of the envelope reads m at f
   (0-peak; on a bin, and up to the Hann scalloping loss, at most 1.4 dB midway between
   bins, off it);
5. the amplitude at a defect frequency f0: the largest bin within f0 (1 +/- slip)
   (at least +/- one bin), its scalloping loss corrected by the two-bin interpolation
   for the Hann window (Grandke 1983, :func:`hann_peak_amplitude`: a single tone between
   bins reads its 0-peak amplitude m), and ``ratio``: that amplitude over the median of
   the envelope spectrum from 0.5 f0 to 1.5 f0 (how far the line stands out of the
   floor around it).

Default band: 0.08 fs .. 0.4 fs (2-10 kHz at 25 kHz), :func:`default_band`.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from .spectrum import bin_range, hann, hann_sums, rfft_freqs

__all__ = ["default_band", "envelope_band", "Envelope", "envelope", "envelope_of_rfft", "envelopes_of_rfft",
           "centred_envelopes", "envelope_spectrum",
           "centred_envelope_spectrum", "LinePeak", "line_peak", "hann_peak_amplitude"]


def default_band(fs: float) -> tuple[float, float]:
    """The resonance band demodulated by default: 0.08 fs .. 0.4 fs (2-10 kHz at 25 kHz)."""
    return 0.08 * fs, 0.4 * fs


def envelope_band(fs: float, configured: tuple[float, ...] | None = None) -> tuple[float, float]:
    """The band demodulated at fs: ``configured`` (``indicators.envelope_band_hz``, [lo, hi] Hz),
    else :func:`default_band`; the indicators' envelope and the captures' envelope spectrum
    both demodulate this one."""
    return (float(configured[0]), float(configured[1])) if configured else default_band(fs)


@lru_cache(maxsize=32)
def _fast_len(n: int) -> int:
    """The smallest 2^a 3^b 5^c >= n (a fast FFT length)."""
    best = 1 << max(0, (n - 1).bit_length())
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            m = p35
            while m < n:
                m *= 2
            best = min(best, m)
            p35 *= 3
        p5 *= 5
    return best


class Envelope(NamedTuple):
    env: np.ndarray       # (M,) envelope [m/s^2], decimated
    fs_env: float         # its sample rate [Hz]
    band: tuple[float, float]   # the band demodulated [Hz] (within 0 .. fs/2)


def _band_bins(n_bins: int, N: int, fs: float, band: tuple[float, float]) -> tuple[int, int, int, float]:
    """(lo, hi, M, T): the bins lo..hi of the band, the inverse transform's length, the record's."""
    T = N / fs
    lo = max(1, int(np.ceil(band[0] * T)))
    hi = min(n_bins - 1, int(np.floor(band[1] * T)))
    return lo, hi, _fast_len(max(2 * max(0, hi - lo + 1), 2)), T


def envelope(x: np.ndarray, fs: float, band: tuple[float, float]) -> Envelope:
    """The decimated envelope of the band [lo, hi] Hz of the 1-D record x (steps 1-2)."""
    x = np.asarray(x, dtype=np.float64)
    N = x.size
    X = np.fft.rfft(x)
    lo, hi, M, T = _band_bins(len(X), N, fs, band)
    K = max(0, hi - lo + 1)
    Z = np.zeros(M, dtype=np.complex128)
    Z[:K] = X[lo:hi + 1]
    z = np.fft.ifft(Z) * (2.0 * M / N)       # the analytic signal of the band, shifted to 0 Hz
    return Envelope(np.abs(z), M / T, (lo / T, hi / T))


def envelope_of_rfft(X: np.ndarray, N: int, fs: float, band: tuple[float, float]) -> Envelope:
    """:func:`envelope` of the record of N samples whose ``np.fft.rfft`` is X (the same
    numbers up to rounding): the inverse transform unscaled and padded by numpy, the scale
    applied to the magnitude, fewer passes over the M points."""
    lo, hi, M, T = _band_bins(X.shape[-1], N, fs, band)
    if hi < lo:
        return Envelope(np.zeros(M), M / T, (lo / T, hi / T))
    env = np.abs(np.fft.ifft(X[lo:hi + 1], n=M, norm="forward"))
    env *= 2.0 / N
    return Envelope(env, M / T, (lo / T, hi / T))


def envelopes_of_rfft(X: np.ndarray, N: int, fs: float, band: tuple[float, float]) -> list[Envelope]:
    """:func:`envelope_of_rfft` of each row of X (R, K), the ``np.fft.rfft`` of records of N
    samples: the same envelopes bit for bit, their inverse transforms in one call (numpy
    transforms the rows one by one, each as a call of its own would)."""
    env, fs_env, edges = _envelope_rows(X, N, fs, band)
    return [Envelope(e, fs_env, edges) for e in env]


def centred_envelopes(X: np.ndarray, N: int, fs: float,
                      band: tuple[float, float]) -> tuple[list[Envelope], list[float]]:
    """:func:`envelopes_of_rfft` of the rows of X with each envelope's mean removed
    (``env - env.mean()``), and each one's RMS (``sqrt(mean(e * e))``, the envelope RMS of
    step 3): the numbers of those two steps row by row, bit for bit (each row's sums are
    numpy's pairwise sums of that row), in one pass over all rows each."""
    env, fs_env, edges = _envelope_rows(X, N, fs, band)
    env -= env.mean(axis=1, keepdims=True)
    rms = np.sqrt(np.mean(env * env, axis=1)).tolist()
    return [Envelope(e, fs_env, edges) for e in env], rms


def _envelope_rows(X: np.ndarray, N: int, fs: float,
                   band: tuple[float, float]) -> tuple[np.ndarray, float, tuple[float, float]]:
    """The envelopes (R, M) of the rows of X (R, K) in one inverse transform, as
    :func:`envelope_of_rfft` makes each (zeros when the band holds no bin), their rate and
    the band's edges [Hz]."""
    lo, hi, M, T = _band_bins(X.shape[-1], N, fs, band)
    edges = (lo / T, hi / T)
    if hi < lo:
        return np.zeros((len(X), M)), M / T, edges
    env = np.abs(np.fft.ifft(X[:, lo:hi + 1], n=M, axis=-1, norm="forward"))
    env *= 2.0 / N
    return env, M / T, edges


def envelope_spectrum(env: np.ndarray, fs_env: float) -> tuple[np.ndarray, np.ndarray]:
    """(f, A): the amplitude spectrum of the envelope minus its mean (step 4)."""
    return centred_envelope_spectrum(env - env.mean(), fs_env)


def centred_envelope_spectrum(e: np.ndarray, fs_env: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`envelope_spectrum` of an envelope whose mean is already removed (e = env - mean);
    f is read-only (shared between calls of one length)."""
    w = hann(e.size)
    A = np.abs(np.fft.rfft(e * w))
    A *= 2.0 / hann_sums(e.size)[0]
    return rfft_freqs(e.size, float(fs_env)), A


class LinePeak(NamedTuple):
    amplitude: float      # 0-peak amplitude of the window's largest bin, interpolated [m/s^2]
    freq_hz: float        # that bin's frequency
    ratio: float          # amplitude over the median of the spectrum in 0.5 f0 .. 1.5 f0


def hann_peak_amplitude(A: np.ndarray, i: int) -> float:
    """The amplitude of a tone whose largest bin of the Hann-windowed amplitude spectrum A is
    i, corrected for the tone's offset from the bin (Grandke 1983, the Hann window): with
    alpha the larger neighbour over A[i], the tone lies delta = (2 alpha - 1) / (alpha + 1)
    bins from i towards that neighbour (clipped to 0 .. 0.5), and A[i] is its amplitude times
    the Hann kernel there, sin(pi delta) / (pi delta (1 - delta^2)); so A[i] / kernel is exact
    for a single tone, +0 % on a bin to +17.8 % midway.  A[i] itself when it is not a local
    maximum (the skirt of a line beyond it) or is 0."""
    a = float(A[i])
    left = float(A[i - 1]) if i > 0 else 0.0
    right = float(A[i + 1]) if i + 1 < A.shape[-1] else 0.0
    side = max(left, right)
    if not a > 0.0 or side > a:
        return a
    alpha = side / a
    delta = min(max((2.0 * alpha - 1.0) / (alpha + 1.0), 0.0), 0.5)
    if delta == 0.0:
        return a
    x = math.pi * delta
    return a * x * (1.0 - delta * delta) / math.sin(x)


def line_peak(f: np.ndarray, A: np.ndarray, f0: float, slip: float) -> LinePeak | None:
    """The envelope spectrum's line near f0 (step 5); None when the window reaches beyond
    the spectrum or f0 is not positive."""
    df = f[1] - f[0] if f.size > 1 else 0.0
    half = max(slip * f0, df)
    if not (f0 > 0 and df > 0 and f0 + half <= f[-1]):
        return None
    a, b = bin_range(f, f0 - half, f0 + half)        # f ascending: the bins of the window
    i = a + int(np.argmax(A[a:b]))
    lo, hi = bin_range(f, 0.5 * f0, 1.5 * f0)
    floor = float(np.median(A[lo:hi]))
    amp = hann_peak_amplitude(A, i)
    return LinePeak(amp, float(f[i]), amp / floor if floor > 0 else float("nan"))
