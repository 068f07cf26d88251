"""Velocity RMS in mm/s from acceleration, by integration in the frequency domain.

ISO 10816-3 / ISO 20816-3 grade the broadband velocity RMS over 10-1000 Hz, and
over 2-1000 Hz for machines "approaching or below 600 r/min": here at 600 rpm and below
(:func:`velocity_band`), so a 600-rpm machine's 1x (10 Hz) is inside the band, not on its
edge.  Each bin of the acceleration power spectrum (:mod:`.spectrum`, m^2/s^4) divided by
(2 pi f)^2 is the velocity power of that bin; the velocity RMS is the root of their sum over
the bins with lo <= f <= hi (both edges included, rectangular: the band is the standard's, not a
filter's -3 dB points), times 1000 for mm/s.  Above fs / 2 nothing is measured, so
the upper edge is min(hi, fs / 2).  A tone n bins (of 1 / record length Hz) above 0 Hz
reads high, its Hann side bins weighted by 1 / (2 pi f)^2 (+6.6 % at 3 bins, +0.5 % at 10,
about +50 / n^2 %), and a tone on the band's lower edge low, its lower side bin left out
(-10 % for 10 Hz in 1 s): the README's "Velocity RMS at low frequencies and short intervals".
"""

from __future__ import annotations

import numpy as np

from .spectrum import band_mask

__all__ = ["ISO_BAND_HZ", "SLOW_ISO_BAND_HZ", "SLOW_RPM", "velocity_band", "velocity_rms_mm_s"]

#: ISO 10816-3 measurement band, and for machines at or below SLOW_RPM
ISO_BAND_HZ = (10.0, 1000.0)
SLOW_ISO_BAND_HZ = (2.0, 1000.0)
SLOW_RPM = 600.0


def velocity_band(rpm: float | None, configured: tuple[float, float] | None = None) -> tuple[float, float]:
    """The band: as configured, else 2-1000 Hz at ``rpm`` <= 600 and 10-1000 Hz above (no
    speed known: 10-1000 Hz)."""
    if configured is not None:
        return configured
    return SLOW_ISO_BAND_HZ if rpm is not None and 0 < rpm <= SLOW_RPM else ISO_BAND_HZ


def velocity_rms_mm_s(f: np.ndarray, P: np.ndarray, band: tuple[float, float]) -> np.ndarray:
    """Velocity RMS [mm/s] in ``band`` from the acceleration power spectrum P (..., bins) at
    frequencies f: the one-sided Hann power per bin of :mod:`.spectrum` (m^2/s^4, summing to
    the record's mean square), each bin with lo <= f <= hi and f > 0 weighted by 1 / (2 pi f)^2."""
    m = band_mask(f, band[0], band[1]) & (f > 0)
    w = 1.0 / (2.0 * np.pi * f[m]) ** 2
    return 1000.0 * np.sqrt((P[..., m] * w).sum(axis=-1))     # not @: no BLAS threads
