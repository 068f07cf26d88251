"""The simulator's low-order IIR filters (a resonance, one-pole low-passes) without scipy.signal.

:func:`lfilter` is ``scipy.signal.lfilter(b, a, x)`` for a 1-D ``x`` from rest and at most
second order, computed by the order tracker's compiled SOS loop (one section, direct form II
transposed: for the one-coefficient numerators the scenarios use, lfilter's arithmetic and bits;
for a full biquad the same to rounding, tests/test_sim_iir.py).  Importing
scipy.signal costs ~0.65 s of CPU, most of a simulated board's start-up; it is imported only
when the compiled kernels are not built.
"""

from __future__ import annotations

import numpy as np

try:  # built with the package when a C compiler is present
    from cmsensord.dsp import _trackerkernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _trackerkernel = None


def lfilter(b, a, x) -> np.ndarray:
    """``scipy.signal.lfilter(b, a, x)`` (zero initial state) for ``len(a), len(b) <= 3``."""
    b = np.asarray(b, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    if _trackerkernel is None or len(a) > 3 or len(b) > 3 or x.ndim != 1:
        from scipy.signal import lfilter as scipy_lfilter

        return np.asarray(scipy_lfilter(b, a, x))
    sos = np.zeros((1, 6))
    sos[0, : len(b)] = b / a[0]
    sos[0, 3 : 3 + len(a)] = a / a[0]
    out = np.empty((len(x), 1))
    _trackerkernel.sosfilt(sos, np.ascontiguousarray(x).reshape(-1, 1), np.zeros((1, 2, 1)), out, 0, 1)
    return out[:, 0]
