"""The decimator's anti-alias low-pass, designed in numpy (no scipy.signal).

A Chebyshev type II low-pass (flat, monotonic pass band) in second-order sections:
:func:`cheb2ord` and :func:`cheby2_sos` follow scipy.signal's cheb2ord,
cheby2(output="sos") and zpk2sos(pairing="nearest") step by step, in the same
arithmetic, so the sections are scipy's to rounding (compared in
tests/test_order_tracker.py).  The daemon does not import scipy.signal: it costs
~70 MB of resident memory and ~0.9 s for three small functions.  Also the
sections' response, group delay at DC and how many outputs one missing
(zero-filled) input spoils (:func:`missing_window_of`).  See docs/order_tracker.md
(§4 Decimation, §5 Missing samples).
"""

from __future__ import annotations

import math

import numpy as np

try:  # the compiled kernel is optional: the impulse response then comes from a Python loop
    from cmsensord.dsp import _trackerkernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _trackerkernel = None


def cheb2ord(f_pass: float, f_stop: float, gpass: float, gstop: float, fs: float) -> tuple[int, float]:
    """Lowest order and stop-band edge [Hz] of the digital Chebyshev type II low-pass
    that loses at most ``gpass`` dB up to f_pass and at least ``gstop`` dB from f_stop."""
    passb = math.tan(math.pi * (2.0 * f_pass / fs) / 2.0)     # pre-warped edges
    stopb = math.tan(math.pi * (2.0 * f_stop / fs) / 2.0)
    nat = abs(stopb / passb)
    GSTOP = 10 ** (0.1 * abs(gstop))
    GPASS = 10 ** (0.1 * abs(gpass))
    v_pass_stop = math.acosh(math.sqrt((GSTOP - 1.0) / (GPASS - 1.0)))
    order = int(math.ceil(v_pass_stop / math.acosh(nat)))
    new_freq = 1.0 / math.cosh(1.0 / order * v_pass_stop)  # where the prototype loses gpass
    wn = math.atan(passb / new_freq) * 2.0 / math.pi
    return order, wn * fs / 2


def cheby2_sos(order: int, gstop: float, f_edge: float, fs: float) -> np.ndarray:
    """Second-order sections (rows b0 b1 b2 1 a1 a2) of the digital Chebyshev type II
    low-pass of this order, ``gstop`` dB down from its stop-band edge f_edge [Hz]."""
    N = int(order)
    # analog prototype (scipy's cheb2ap): stop-band edge at 1 rad/s
    de = 1.0 / math.sqrt(10 ** (0.1 * gstop) - 1)
    mu = math.asinh(1.0 / de) / N
    if N % 2:
        m = np.concatenate((np.arange(-N + 1, 0, 2, dtype=np.float64),
                            np.arange(2, N, 2, dtype=np.float64)))
    else:
        m = np.arange(-N + 1, N, 2, dtype=np.float64)
    z = 1j / np.sin(m * np.pi / (2 * N))
    theta1 = np.pi * np.arange(-N + 1, N, 2, dtype=np.float64) / (2 * N)
    p = -1 / np.sinh(mu + 1j * theta1)
    k = np.real(np.prod(-p, axis=0) / np.prod(-z, axis=0))
    # to the pre-warped edge (lp2lp_zpk), then the bilinear transform (at fs = 2)
    warped = 2 * 2.0 * math.tan(math.pi * (f_edge / (fs / 2)) / 2.0)
    degree = len(p) - len(z)
    z, p, k = warped * z, warped * p, k * warped ** degree
    fs2 = 4.0
    z_z = np.concatenate(((fs2 + z) / (fs2 - z), -np.ones(degree)))
    p_z = (fs2 + p) / (fs2 - p)
    k_z = k * np.real(np.prod(fs2 - z) / np.prod(fs2 - p))
    return _zpk2sos(z_z, p_z, float(k_z))


def _cplxreal(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One root of each conjugate pair (positive imaginary part, averaged with its
    partner) and the real roots, sorted as scipy.signal's _cplxreal sorts them."""
    z = np.atleast_1d(z)
    if z.size == 0:
        return z, z
    tol = 100 * np.finfo(np.float64).eps
    z = z[np.lexsort((abs(z.imag), z.real))]
    real = abs(z.imag) <= tol * abs(z)
    zr = z[real].real
    if len(zr) == len(z):
        return np.array([]), zr
    z = z[~real]
    zp, zn = z[z.imag > 0], z[z.imag < 0]
    if len(zp) != len(zn):
        raise ValueError("complex root without its conjugate")
    same_real = np.diff(zp.real) <= tol * abs(zp[:-1])        # runs sorted by |imag|
    diffs = np.diff(np.concatenate(([0], same_real, [0])))
    for start, stop in zip(np.nonzero(diffs > 0)[0], np.nonzero(diffs < 0)[0] + 1):
        for chunk in (zp[start:stop], zn[start:stop]):
            chunk[...] = chunk[np.lexsort([abs(chunk.imag)])]
    if np.any(abs(zp - zn.conj()) > tol * abs(zn)):
        raise ValueError("complex root without its conjugate")
    return (zp + zn.conj()) / 2, zr


def _nearest(fro: np.ndarray, to, which: str) -> int:
    """Index of the root in ``fro`` nearest ``to`` (of the kind ``which``)."""
    order = np.argsort(np.abs(fro - to))
    if which == "any":
        return int(order[0])
    mask = np.isreal(fro[order])
    if which == "complex":
        mask = ~mask
    return int(order[np.nonzero(mask)[0][0]])


def _section(z, p) -> np.ndarray:
    """One section with up to two zeros and two poles, gain 1 (scipy's _single_zpksos)."""
    sos = np.zeros(6)
    b = np.poly(np.asarray(z)) if len(z) else np.ones(1)
    a = np.poly(np.asarray(p)) if len(p) else np.ones(1)
    sos[3 - len(b):3] = np.real(b)
    sos[6 - len(a):6] = np.real(a)
    return sos


def _zpk2sos(z: np.ndarray, p: np.ndarray, k: float) -> np.ndarray:
    """Digital zeros, poles, gain -> sections, scipy.signal.zpk2sos with pairing
    "nearest": the pole nearest the unit circle goes with the zeros nearest it,
    and such sections come last."""
    p = np.concatenate((p, np.zeros(max(len(z) - len(p), 0))))
    z = np.concatenate((z, np.zeros(max(len(p) - len(z), 0))))
    n_sections = (max(len(p), len(z)) + 1) // 2
    if len(p) % 2 == 1:
        p = np.concatenate((p, [0.0]))
        z = np.concatenate((z, [0.0]))
    z = np.concatenate(_cplxreal(z))
    p = np.concatenate(_cplxreal(p))
    sos = np.zeros((n_sections, 6))
    for si in range(n_sections - 1, -1, -1):
        p1_idx = int(np.argmin(np.abs(1 - np.abs(p))))         # the "worst" pole left
        p1 = p[p1_idx]
        p = np.delete(p, p1_idx)
        if np.isreal(p1) and np.isreal(p).sum() == 0:          # the last real pole
            z1_idx = _nearest(z, p1, "real")
            z1 = z[z1_idx]
            z = np.delete(z, z1_idx)
            sos[si] = _section([z1, 0], [p1, 0])
        elif (len(p) + 1 == len(z) and not np.isreal(p1) and np.isreal(p).sum() == 1
              and np.isreal(z).sum() == 1):                     # must take a complex zero
            z1_idx = _nearest(z, p1, "complex")
            z1 = z[z1_idx]
            z = np.delete(z, z1_idx)
            sos[si] = _section([z1, z1.conj()], [p1, p1.conj()])
        else:
            if np.isreal(p1):
                preal = np.flatnonzero(np.isreal(p))
                p2_idx = int(preal[np.argmin(np.abs(1 - np.abs(p[preal])))])
                p2 = p[p2_idx]
                p = np.delete(p, p2_idx)
            else:
                p2 = p1.conj()
            if len(z) > 0:
                z1_idx = _nearest(z, p1, "any")
                z1 = z[z1_idx]
                z = np.delete(z, z1_idx)
                if not np.isreal(z1):
                    sos[si] = _section([z1, z1.conj()], [p1, p2])
                elif len(z) > 0:
                    z2_idx = _nearest(z, p1, "real")
                    z2 = z[z2_idx]
                    z = np.delete(z, z2_idx)
                    sos[si] = _section([z1, z2], [p1, p2])
                else:
                    sos[si] = _section([z1], [p1, p2])
            else:
                sos[si] = _section([], [p1, p2])
    sos[0][:3] *= k
    return sos


def sos_response(sos: np.ndarray, f, fs: float) -> np.ndarray:
    """Complex frequency response of the sections at frequencies f [Hz]."""
    zi = np.exp(-2j * np.pi * np.asarray(f, dtype=np.float64) / fs)
    h = np.ones(zi.shape, dtype=complex)
    for b0, b1, b2, a0, a1, a2 in sos:
        h = h * (b0 + zi * (b1 + zi * b2)) / (a0 + zi * (a1 + zi * a2))
    return h


def sos_dc_delay(sos: np.ndarray) -> float:
    """Group delay at DC [samples] of the sections: per polynomial Σ k c_k / Σ c_k
    (d arg / dω at ω = 0), numerator minus denominator, summed over the sections."""
    k = np.arange(3.0)
    return float(sum(np.dot(k, s[:3]) / s[:3].sum() - np.dot(k, s[3:]) / s[3:].sum() for s in sos))


MISSING_TAIL = 1e-3
"""L1 tail of the anti-alias filter's impulse response beyond which a missing input
no longer spoils its outputs (see :func:`missing_window_of` and docs/order_tracker.md
§5 Missing samples)."""


def _sos_impulse(sos: np.ndarray) -> np.ndarray:
    """Impulse response of the sections (direct form II transposed, the decimator's
    arithmetic), until it has decayed to about 1e-17 of its start: the largest pole
    radius ρ sets the length, log(1e-17)/log ρ + 64 samples (at most 2^20)."""
    rho = max(float(np.max(np.abs(np.roots(s[3:])))) if np.any(s[4:]) else 0.0 for s in sos)
    n = 64 if rho <= 0.0 else min(1 << 20, math.ceil(math.log(1e-17) / math.log(rho)) + 64)
    if _trackerkernel is not None:          # the decimator's own loop: the same operations
        unit = np.zeros((n, 1))
        unit[0, 0] = 1.0
        out = np.empty((n, 1))
        _trackerkernel.sosfilt(np.ascontiguousarray(sos, dtype=np.float64), unit,
                               np.zeros((len(sos), 2, 1)), out, 0, 1)
        return out[:, 0]
    rows = [tuple(float(v) for v in s) for s in sos]
    z = [[0.0, 0.0] for _ in rows]
    h = np.empty(n)
    x0 = 1.0
    for i in range(n):
        x = x0
        for (b0, b1, b2, _, a1, a2), zz in zip(rows, z):
            y = b0 * x + zz[0]
            zz[0] = b1 * x - a1 * y + zz[1]
            zz[1] = b2 * x - a2 * y
            x = y
        h[i] = x
        x0 = 0.0
    return h


def missing_window_of(sos: np.ndarray | None, tail: float = MISSING_TAIL) -> int:
    """W: how many outputs of the anti-alias filter one missing (zero-filled) input
    spoils, the input's own output included: the smallest W with
    Σ_{m >= W} |h(m)| <= ``tail``.  From output W on, the zero fill changes an output
    by at most ``tail`` times the peak of the missing input, whatever the signal.
    1 without a filter (D = 1)."""
    if sos is None:
        return 1
    h = _sos_impulse(sos)
    rest = np.cumsum(np.abs(h)[::-1])[::-1]                 # rest[m] = Σ_{i >= m} |h(i)|
    ok = np.flatnonzero(rest <= tail)
    return int(ok[0]) if ok.size else len(h)
