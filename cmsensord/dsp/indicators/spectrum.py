"""The one-sided power spectrum that the velocity and band indicators read.

A periodic Hann window, the record's mean removed first; the power of bin k is
scaled so that the sum over all bins is the record's mean square (Parseval with
the window's power, ``sum(w^2)``, divided out), so a band sum is a mean square
in the band whatever the record length:

    P_k = c_k |X_k|^2 / (N sum(w^2)),   c_k = 2 except at DC and Nyquist (1).

Resolution 1 / T (T the record length, 1 Hz for the default 1-s interval); the
Hann main lobe is 4 bins wide, so a tone within 2 bins of a band edge is partly
counted on the other side.

:func:`hann_power_bins` gives the same P_k for a range of bins from the transform
of the record *without* the window (the one the envelope reads too): the periodic
Hann window is three lines in frequency, so the windowed transform is

    Y_k = X_k / 2 - (X_{k-1} + X_{k+1}) / 4

(X_{-k} = conj X_k, X_{N-k} = conj X_k), the same numbers as the P_k above of the
windowed record's transform up to rounding (~1e-16 of the spectrum's largest bins), at a
few operations per bin read instead of a second transform of the whole record.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["hann", "hann_sums", "rfft_freqs", "band_mask", "bin_range", "hann_power_bins"]


@lru_cache(maxsize=8)
def hann(N: int) -> np.ndarray:
    """The periodic Hann window of N samples (``0.5 - 0.5 cos(2 pi n / N)``), read-only: the
    same few lengths come every interval, so each is computed once."""
    w = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(N) / N)
    w.setflags(write=False)
    return w


@lru_cache(maxsize=8)
def hann_sums(N: int) -> tuple[float, float]:
    """``(sum(w), sum(w^2))`` of :func:`hann` (N), computed once per length."""
    w = hann(N)
    return float(w.sum()), float((w * w).sum())


@lru_cache(maxsize=16)
def rfft_freqs(N: int, fs: float) -> np.ndarray:
    """``np.fft.rfftfreq(N, 1 / fs)``, read-only, computed once per (N, fs)."""
    f = np.fft.rfftfreq(N, 1.0 / fs)
    f.setflags(write=False)
    return f


def band_mask(f: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Bins with lo <= f <= hi."""
    return (f >= lo) & (f <= hi)


def bin_range(f: np.ndarray, lo: float, hi: float) -> tuple[int, int]:
    """(a, b): the bins a..b-1 are those of :func:`band_mask` (f, lo, hi), f ascending
    (b == a when none is)."""
    a = int(np.searchsorted(f, lo, "left"))
    return a, max(a, int(np.searchsorted(f, hi, "right")))


def hann_power_bins(X: np.ndarray, N: int, a: int, b: int) -> np.ndarray:
    """The one-sided Hann power P_k = c_k |Y_k|^2 / (N sum(w^2)) (module docstring: the power
    per bin of the mean-removed record with the periodic Hann window, summing to its mean
    square) for the bins k = a..b-1 (0 <= a <= b <= N // 2 + 1) of the mean-removed record of
    N samples whose ``np.fft.rfft`` without a window is X."""
    K = X.shape[-1]
    if a >= b:
        return np.zeros(0)
    if a >= 1 and b < K:
        Xe = X[a - 1:b + 1]                      # X_{a-1} .. X_b, a view
    else:                                        # the bins beyond either end, by symmetry
        Xe = np.concatenate((np.conj(X[1:2]), X, np.conj(X[N - K:N - K + 1])))[a:b + 2]
    Y = Xe[1:-1] * 0.5
    Y -= (Xe[:-2] + Xe[2:]) * 0.25
    P = Y.real ** 2
    P += Y.imag ** 2
    P /= N * hann_sums(N)[1]
    lo2, hi2 = max(a, 1), min(b, (N + 1) // 2)  # doubled: not DC, not Nyquist
    if hi2 > lo2:
        P[lo2 - a:hi2 - a] *= 2.0
    return P
