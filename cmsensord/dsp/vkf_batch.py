"""Batch (offline, zero-phase) Vold-Kalman order tracking filters.

Implements Tůma ("Vold-Kalman Order Tracking Filtration as a Tool
for Machine Diagnostics"): the first-generation filter of section 2, eqs. (1)-(11),
with its frequency response and selectivity, and the second-generation,
multi-order filter of section 3, eqs. (12)-(15).  Both are least-squares
problems over the whole record, solved at once as banded systems, so the
result is zero-phase and there is no slew-rate limit.  The per-block RMS and
the error measure are eq. (26) of Yeh, Pan & Le.

First generation (one order, the waveform itself is the unknown)::

    structural  x(n) - c(n) x(n-1) + x(n-2) = ε(n),  c(n) = 2 cos(ω Δt)      (2)
                A x = ε,  A: (N-2) x N, rows [.. 1  -c  1 ..]             (3)-(4)
    data        y(n) = x(n) + η(n),  y - x = η                         (6)-(8)
    loss        J = r² εᵀε + ηᵀη                                          (9)
    normal eq.  (r² AᵀA + E) x = y                                    (10)-(11)

r²AᵀA + E is symmetric positive definite and pentadiagonal; it is solved as a
banded Cholesky system (``scipy.linalg.solveh_banded``), never inverted.

For a stationary ω₀ and an infinite record the filter is zero-phase: a row
of (2) maps x(n) = e^{jωn} to e^{jω(n-1)} (2 cos ω - 2 cos ω₀), so (11) becomes::

    H(ω) = 1 / (1 + 4 r² (cos ω - cos ω₀)²),   ω in rad/sample            (R1)

For a finite record of N samples the response is computed numerically
(:func:`vkf1_response`); as r -> ∞ the solution becomes the least-squares fit of
one sinusoid of frequency ω₀ to the record (the null space of A), whose -3 dB
width is the rectangular-window resolution 0.886 fs/N.  That limit is the
selectivity statement of section 2: "the limit value of the weighting factor
is equal to 100 for the 100-sample waveform ... the larger the number of the
samples the better selectivity".

Second generation (K orders at once, complex envelopes are the unknowns)::

    phasor      Θ_k(n) = exp(j θ_k(n)),  θ_k = 2π o_k turns(n)  or  2π f_k t   (13)
    signal      x(n) = Σ_{±k} A_k(n) Θ_k(n),  A_{-k} = A_k*                  (12)
    structural  ∇^s A_k(n) = ε_k(n),  s = 1 or 2 poles                      (14)
    data        y(n) - Σ_k x_k(n) = η(n)                                    (15)
    loss        J = ηᵀη + Σ_k r_k² Σ_{±k} |∇^s A_{±k}|²                      (9)

The image (negative frequency) of each order is solved exactly, not neglected:
the unknowns are the envelopes a_k = 2 A_k as 2K real numbers (u_k, v_k) per
sample, a_k = u_k + j v_k, and x_k(n) = 2 Re{A_k Θ_k} = Re{a_k Θ_k} =
u_k cos θ_k - v_k sin θ_k.  This is the same least-squares problem as solving
eqs. (12)-(15) for both A_k and A_{-k} with the conjugate constraint.  (The
common shortcut — complex data y e^{-jθ} and a factor 2 — lets the image leak
in at 2 f_k from the carrier; it matters at low speed.)  |a_k| is therefore the
peak amplitude of order k and ``block_rms(x_k)`` its RMS, without correction.

With the weight r_k² on both members of the pair, an isolated order in a long
stationary record sees the envelope low-pass of the usual formulation::

    H_s(Δω) = 1 / (1 + r² (2 sin(Δω/2))^{2s}),   Δω offset from the carrier  (R2)

so the full -3 dB bandwidth B (Hz, f_k ± B/2) and r are related by
r = sqrt(√2 - 1) / (2 sin(π B / (2 fs)))^s (:func:`vkf_bandwidth`,
:func:`r_for_bandwidth`; Tůma cites this relation from its reference [3]
without giving it — derived here from (R2) and checked numerically in
tests/test_vkf_batch.py).

The normal equations, ordered sample by sample (unknown index 2K n + 2k + {0: u, 1: v}),
are block-banded with half-bandwidth 2K s: the data equation couples the 2K
unknowns of one sample through g(n) g(n)ᵀ, g = [cos θ_1, -sin θ_1, ...], and
the structural equation couples each unknown with itself s samples away.  The
banded Cholesky factorisation (``scipy.linalg.cholesky_banded``, in place)
costs O(N (2Ks)²) time and (2Ks + 1) 2K N doubles of memory (225 MB for the
whirl record, N = 360 000, K = 3, s = 2; about 390 MB peak in all, under 1.5 s).

Double precision limits narrow 2-pole filters: the normal matrix has
eigenvalues from ~1 (smooth envelopes, fixed by the data) to ~2^{2s} r²/2, and
the Cholesky solution carries a relative error of order r² ε in the smooth
envelope (2 poles, B = 0.25 Hz at fs = 2 kHz: r = 4e6 and 0.8 % RMS error).
:func:`vkf2` therefore refines the solution iteratively: the residual is
recomputed from the structure (the differences of eq. 14 are exact for smooth
envelopes) and corrected with the same factor until the correction is below
1e-10 of the envelope (3-6 steps for 2 poles and 0.25-2 Hz at 2 kHz; 1 for
1 pole).

Extension (not in Tůma): where the orders cannot be told apart by the data —
the shaft at standstill for a while (every θ_k constant, the same for all
orders), orders closer than the bandwidth for longer than the filter's memory
— the normal matrix is singular in exact arithmetic or numerically, and the
Cholesky factorisation fails or the refinement does not converge.  Only then
the loss gets a ridge (Tikhonov) term, J + μ Σ_n |z(n)|², with the smallest
μ = 10^{2j} ε λ_max (λ_max = K + 2^{2s} r²/2 bounds the eigenvalues) that lets
the factorisation through, and the refinement solves that regularised
system exactly.  Where the data decide the envelopes (1/2 per sample and
unknown) μ shrinks a steady envelope by μ/(1/2 + μ); μ is refused above
1e-3 (0.2 %).  Where they do not, the envelopes are the smallest ones that
explain the data.  ``VkfResult.ridge`` says which μ a solve took (0: the
paper's system as it is, which every record that the plain factorisation
handles keeps).  When r is too large even for that, it raises
``LinAlgError`` ("widen the bandwidth") instead of returning a wrong
envelope; so do two phase rows that are the same component (their difference
constant).  The limit depends on B/fs: 2 poles
with B = 0.07 Hz at 2 kHz (r = 5e7) still converge, 0.05 Hz does not; at
fs = 25 kHz the same limits are 0.9 and 0.6 Hz.

Reading the converted text of the paper (figures are missing, some equations garbled):

* Eq. (5) reads "x A^T A x"; it is xᵀ AᵀA x.  The number (9) is printed twice,
  for ηᵀη and for J; the loss is the second one.
* Eq. (2) writes c(n) beside x(n) and ε(n): the newest sample's ω when ω varies.
  Here c(n) = 2 cos(ω(n-1) Δt), the middle sample of the three (a stated
  deviation), so that the structural equation does not lag the frequency; for
  a stationary ω the choices are the same (for a 50-80 Hz sweep over 400
  samples at 1 kHz they differ by about 0.6 % of the peak).
* Fig. 1 (the frequency responses) is missing and the text does not say how
  the response of a finite record is measured.  Here |H(f)| is the RMS gain over
  the record for a complex exponential, ‖x‖/‖y‖ with y(n) = e^{j2πfn/fs}, which is
  the phase-averaged RMS gain for a real sinusoid.
* Eq. (14) appears as ∇^s A_k(n) = ε(n); the weighting (r² on the sum of
  squared ε) is not restated for the second generation and is taken from (9),
  applied to both A_k and A_{-k} as above.
* The "10 % bandwidth" of Fig. 7 (bandwidth proportional to the order's
  frequency) is not implemented: r is constant per order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded, solveh_banded
from scipy.optimize import brentq

from cmsensord.dsp.vkf_normal import ridge_solve, solve

__all__ = [
    "Hz",
    "VkfResult",
    "vkf1",
    "vkf1_response",
    "vkf1_bandwidth",
    "vkf2",
    "vkf_bandwidth",
    "r_for_bandwidth",
    "phases_for",
    "block_rms",
    "block_rms_error",
]

_SQRT_HALF = 1.0 / math.sqrt(2.0)
_G3 = math.sqrt(math.sqrt(2.0) - 1.0)   # |H| = 1/√2  <=>  r² q² = √2 - 1


# --------------------------------------------------------------------------
# first generation, eqs. (1)-(11)
# --------------------------------------------------------------------------

def _vkf1_bands(w: np.ndarray, r: float) -> np.ndarray:
    """r² AᵀA + E in upper banded form (3, N) for ω in rad/sample, eqs. (3), (11).

    Row i of A (i = 0..N-3) is [1, -c_i, 1] at columns i, i+1, i+2, with
    c_i = 2 cos ω(i+1) (the middle sample).  (AᵀA)[j, k] = Σ_i A[i, j] A[i, k].
    """
    N = w.shape[0]
    c = 2.0 * np.cos(w[1:N - 1])               # c_i, i = 0..N-3
    r2 = r * r
    ab = np.zeros((3, N))
    diag = ab[2]
    diag[:N - 2] += 1.0                          # A[i, i]² = 1
    diag[1:N - 1] += c * c                       # A[i, i+1]² = c_i²
    diag[2:] += 1.0                              # A[i, i+2]² = 1
    diag *= r2
    diag += 1.0                                  # + E
    ab[1, 1:N - 1] -= r2 * c                     # (i, i+1): 1 · (-c_i)
    ab[1, 2:] -= r2 * c                          # (i+1, i+2): (-c_i) · 1
    ab[0, 2:] = r2                               # (i, i+2): 1 · 1
    return ab


def _omega_per_sample(omega, n: int, fs: float) -> np.ndarray:
    w = np.asarray(omega, dtype=np.float64)
    if w.ndim == 0:
        return np.full(n, float(w) / fs)
    if w.shape != (n,):
        raise ValueError(f"omega: expected a scalar or shape ({n},), got {w.shape}")
    return w / fs


def _check_r(r: float, name: str = "r") -> float:
    r = float(r)
    if not (r > 0.0):
        raise ValueError(f"{name}: expected > 0, got {r}")
    return r


def vkf1(y: np.ndarray, omega, r: float, *, fs: float) -> np.ndarray:
    """First-generation VKF of one order, eq. (11): x = (r² AᵀA + E)⁻¹ y.

    y      : (N,) real samples.
    omega  : instantaneous angular frequency of the tracked component in rad/s
             (2π f), a scalar or one value per sample (N,).
    r      : weighting factor of eq. (9); large r = narrow passband, slow response.
    fs     : sampling frequency in Hz (Δt = 1/fs).

    Returns the extracted waveform x (N,), real, zero-phase.  The banded
    Cholesky solve is accurate to ~1e-11 for r <= 1000 (the paper's range); the
    error grows as r² ε (~1e-5 at r = 1e6).
    """
    y = np.asarray(y, dtype=np.float64)
    if y.ndim != 1 or y.shape[0] < 3:
        raise ValueError(f"y: expected shape (N,) with N >= 3, got {y.shape}")
    r = _check_r(r)
    w = _omega_per_sample(omega, y.shape[0], float(fs))
    return solveh_banded(_vkf1_bands(w, r), y, check_finite=False)


def _complex_probe(n: int, fs: float, freqs: np.ndarray) -> np.ndarray:
    """(n, 2F) real: cos and sin columns of e^{j2πfn/fs} for every f."""
    ph = 2.0 * np.pi * np.outer(np.arange(n), freqs / fs)
    return np.hstack([np.cos(ph), np.sin(ph)])


class _Vkf1Response:
    """|H(f)| of a stationary first-generation filter on an N-sample record,
    the banded Cholesky factor computed once for many probe frequencies."""

    def __init__(self, r: float, n: int, fs: float, f0: float):
        self.n, self.fs, self.f0, self.r = n, fs, f0, r
        w0 = 2.0 * np.pi * f0 / fs
        self.q: np.ndarray | None = None
        self.cb: np.ndarray | None = None
        if math.isinf(r):
            # r -> ∞: x is the projection of y on the null space of A, which
            # for a stationary ω₀ is span{cos ω₀n, sin ω₀n}.
            nn = np.arange(n)
            q, _ = np.linalg.qr(np.column_stack([np.cos(w0 * nn), np.sin(w0 * nn)]))
            self.q = q
        else:
            self.cb = cholesky_banded(_vkf1_bands(np.full(n, w0), r), check_finite=False)

    def __call__(self, freqs) -> np.ndarray:
        freqs = np.atleast_1d(np.asarray(freqs, dtype=np.float64))
        e = _complex_probe(self.n, self.fs, freqs)
        if self.cb is None:
            assert self.q is not None
            x = self.q @ (self.q.T @ e)
        else:
            x = cho_solve_banded((self.cb, False), e, check_finite=False)
        F = freqs.shape[0]
        num = np.sum(x[:, :F] ** 2 + x[:, F:] ** 2, axis=0)
        den = np.sum(e[:, :F] ** 2 + e[:, F:] ** 2, axis=0)     # = n
        return np.sqrt(num / den)


def vkf1_response(r: float, n_samples: int | None, fs: float, f0: float, freqs) -> np.ndarray:
    """|H(f)| of the first-generation filter tuned to a stationary f0 (Hz).

    n_samples = None: the infinite-record response (R1), analytic.
    n_samples = N:    the finite-record response, numerically: ‖x‖/‖y‖ over
                      the record for y(n) = e^{j2πfn/fs} (the RMS gain of a real
                      sinusoid averaged over its phase).
    r = math.inf gives the limit r -> ∞ (the one-sinusoid least-squares fit).
    """
    freqs = np.asarray(freqs, dtype=np.float64)
    if not (float(r) > 0.0):
        raise ValueError(f"r: expected > 0, got {r}")
    if n_samples is None:
        w0 = 2.0 * np.pi * f0 / fs
        w = 2.0 * np.pi * freqs / fs
        if math.isinf(r):
            return np.where(np.isclose(np.cos(w), np.cos(w0), rtol=0, atol=1e-15), 1.0, 0.0)
        return 1.0 / (1.0 + 4.0 * r * r * (np.cos(w) - np.cos(w0)) ** 2)      # (R1)
    n = int(n_samples)
    if n < 3:
        raise ValueError(f"n_samples: expected >= 3, got {n}")
    return _Vkf1Response(float(r), n, float(fs), float(f0))(freqs).reshape(freqs.shape)


def vkf1_bandwidth(r: float, fs: float, f0: float, n_samples: int | None = None) -> float:
    """Full -3 dB bandwidth in Hz of the first-generation filter at a stationary f0.

    n_samples = None: analytic from (R1), |H| = 1/√2 at
    cos ω = cos ω₀ ± sqrt(√2 - 1)/(2r).  Otherwise the two -3 dB crossings of the
    finite-record response :func:`vkf1_response` nearest to f0, found by
    stepping outwards from f0 and refining with Brent's method.  A side with no
    crossing before 0 or fs/2 ends there.  r = math.inf is allowed for a finite record.
    """
    nyq = fs / 2.0
    if n_samples is None:
        r = _check_r(r)
        if math.isinf(r):
            return 0.0
        w0 = 2.0 * np.pi * f0 / fs
        d = _G3 / (2.0 * r)
        hi = math.acos(max(-1.0, math.cos(w0) - d))
        lo = math.acos(min(1.0, math.cos(w0) + d))
        return (hi - lo) * fs / (2.0 * np.pi)
    resp = _Vkf1Response(float(r), int(n_samples), float(fs), float(f0))
    width = 0.886 * fs / int(n_samples)
    if not math.isinf(r):
        width = max(width, vkf1_bandwidth(r, fs, f0))
    step = width / 20.0
    edges = []
    for side in (+1.0, -1.0):
        edge = nyq if side > 0 else 0.0          # no crossing before the band edge
        prev, k = f0, 1
        while True:
            f = f0 + side * step * np.arange(k, k + 64)
            f = f[(f > 0.0) & (f < nyq)]
            if f.size == 0:
                break
            below = np.nonzero(resp(f) < _SQRT_HALF)[0]
            if below.size:
                j = below[0]
                a = prev if j == 0 else f[j - 1]
                edge = brentq(lambda v: resp(v)[0] - _SQRT_HALF, min(a, f[j]), max(a, f[j]),
                              xtol=1e-9 * width)
                break
            prev, k = f[-1], k + 64
        edges.append(edge)
    return edges[0] - edges[1]


# --------------------------------------------------------------------------
# second generation, eqs. (12)-(15)
# --------------------------------------------------------------------------

def vkf_bandwidth(r: float, fs: float, poles: int = 2) -> float:
    """Full -3 dB bandwidth in Hz of the second-generation filter, from (R2).

    The passband of an order at f_k is f_k ± B/2 with
    2 sin(π B / (2 fs)) = (sqrt(√2 - 1) / r)^{1/s},  s = poles.
    math.inf when r is so small that (R2) never falls to -3 dB.
    """
    r = _check_r(r)
    s = _check_poles(poles)
    q = (_G3 / r) ** (1.0 / s)
    if q >= 2.0:
        return math.inf
    return 2.0 * fs / np.pi * math.asin(q / 2.0)


def r_for_bandwidth(bw_hz: float, fs: float, poles: int = 2) -> float:
    """Inverse of :func:`vkf_bandwidth`: r = sqrt(√2 - 1) / (2 sin(π B / (2 fs)))^s."""
    s = _check_poles(poles)
    bw = float(bw_hz)
    if not (0.0 < bw < fs):
        raise ValueError(f"bw_hz: expected 0 < bw < fs = {fs}, got {bw}")
    return _G3 / (2.0 * math.sin(np.pi * bw / (2.0 * fs))) ** s


def _check_poles(poles) -> int:
    if poles not in (1, 2):
        raise ValueError(f"poles: expected 1 or 2, got {poles!r}")
    return int(poles)


@dataclass(frozen=True)
class VkfResult:
    """Output of :func:`vkf2`, one row per order (phase row) k.

    envelopes : (K, N) complex a_k = 2 A_k, x_k = Re{a_k e^{jθ_k}}.
    waveforms : (K, N) real x_k(n), the extracted component.
    amplitude : (K, N) |a_k|, the peak amplitude of the component.
    r, poles  : the weighting factors (K,) and the number of poles used.
    refinements : iterative-refinement steps the solve took (1 when the
                  Cholesky solution was already accurate).
    ridge     : μ of the ridge term the solve needed (0: the paper's system as it is).
    """

    envelopes: np.ndarray
    waveforms: np.ndarray
    amplitude: np.ndarray
    r: np.ndarray
    poles: int
    refinements: int
    ridge: float = 0.0


def vkf2(y: np.ndarray, phases: np.ndarray, r: float | Sequence[float], *,
         poles: int = 2) -> VkfResult:
    """Second-generation VKF: all K orders extracted at once (coupled), eqs. (12)-(15).

    y      : (N,) real samples.
    phases : (K, N) θ_k(n) in rad (:func:`phases_for`); rows must differ.
    r      : weighting factor, one for all orders or one per order
             (:func:`r_for_bandwidth` from a bandwidth in Hz).
    poles  : 1 or 2, the order s of the difference in the structural equation (14).

    Solves the normal equations of J = ηᵀη + Σ_k (r_k²/2) Σ_n |∇^s a_k(n)|²
    (= r_k² on A_k and on A_{-k}) as one banded SPD system of 2K N unknowns.
    """
    y, phases, rk, s = _vkf2_inputs(y, phases, r, poles)
    N = y.shape[0]
    P = 2 * phases.shape[0]    # real unknowns per sample: (u_k, v_k) for every k
    # data equation (15): y(n) ≈ g(n)ᵀ z(n), g = [cos θ_1, -sin θ_1, cos θ_2, ...]
    g = np.empty((P, N))
    g[0::2] = np.cos(phases)
    g[1::2] = -np.sin(phases)
    rhs = (g * y).T.reshape(N, P)           # gᵀ y, in the same unknown order
    try:
        mu, z, refinements = 0.0, *solve(g, rhs, rk, s, 0.0)
    except np.linalg.LinAlgError:
        # not positive definite, or too ill-conditioned to refine, in double precision:
        # stretches where the orders cannot be told apart (a speed near 0, orders closer
        # than the bandwidth); the smallest ridge μ|z|² that makes the factor exist
        mu, z, refinements = ridge_solve(g, rhs, rk, s)
    del g
    env = z[:, 0::2].T + 1j * z[:, 1::2].T
    wave = z[:, 0::2].T * np.cos(phases) - z[:, 1::2].T * np.sin(phases)
    return VkfResult(envelopes=env, waveforms=wave, amplitude=np.abs(env), r=rk,
                     poles=s, refinements=refinements, ridge=mu)


def _vkf2_inputs(y, phases, r, poles) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The arguments of :func:`vkf2` checked: y (N,), phases (K, N), r (K,) as float64, and s."""
    y = np.asarray(y, dtype=np.float64)
    phases = np.asarray(phases, dtype=np.float64)
    if y.ndim != 1:
        raise ValueError(f"y: expected shape (N,), got {y.shape}")
    N = y.shape[0]
    if phases.ndim == 1:
        phases = phases[None, :]
    if phases.ndim != 2 or phases.shape[1] != N:
        raise ValueError(f"phases: expected shape (K, {N}), got {phases.shape}")
    s = _check_poles(poles)
    if N <= s + 1:
        raise ValueError(f"y: expected more than {s + 1} samples, got {N}")
    if not (np.isfinite(y).all() and np.isfinite(phases).all()):
        raise ValueError("y and phases must be finite (no NaN or inf)")
    K = phases.shape[0]
    rk = np.asarray(r, dtype=np.float64)
    if rk.ndim == 0:
        rk = np.full(K, float(rk))
    if rk.shape != (K,):
        raise ValueError(f"r: expected a scalar or shape ({K},), got {rk.shape}")
    if not (np.all(rk > 0) and np.all(np.isfinite(rk))):
        raise ValueError(f"r: expected finite values > 0, got {rk.tolist()}")
    for i in range(K):
        for j in range(i + 1, K):
            d = phases[i] - phases[j]
            if float(np.ptp(d)) <= 1e-12 * max(1.0, float(np.abs(phases[i]).max())):
                raise np.linalg.LinAlgError(
                    f"vkf2: phase rows {i} and {j} are identical (up to a constant): one "
                    "component asked for twice cannot be split between its two envelopes")
    return y, phases, rk, s


@dataclass(frozen=True)
class Hz:
    """A fixed-frequency component for :func:`phases_for` (a plain number is an order)."""

    f: float


def phases_for(components: Sequence[float | Hz], turns=None, t=None) -> np.ndarray:
    """Phases θ_k(n) (K, N) in rad for :func:`vkf2`, eq. (13).

    A number o is an order: θ = 2π o turns (turns = shaft revolutions since the
    start, the integral of the shaft frequency).  ``Hz(f)`` is a fixed
    frequency: θ = 2π f t (t in s).  A constant phase offset does not matter:
    it ends up in the complex envelope.
    """
    rows = []
    for c in components:
        if isinstance(c, Hz):
            if t is None:
                raise ValueError(f"phases_for: {c} needs t")
            rows.append(2.0 * np.pi * float(c.f) * np.asarray(t, dtype=np.float64))
        else:
            if turns is None:
                raise ValueError(f"phases_for: order {c} needs turns")
            rows.append(2.0 * np.pi * float(c) * np.asarray(turns, dtype=np.float64))
    if not rows:
        raise ValueError("phases_for: expected at least one component")
    shapes = {row.shape for row in rows}
    if len(shapes) != 1 or len(next(iter(shapes))) != 1:
        raise ValueError(f"phases_for: turns and t must be 1-D of equal length, got {sorted(shapes)}")
    return np.vstack(rows)


# --------------------------------------------------------------------------
# Yeh, Pan & Le, eq. (26)
# --------------------------------------------------------------------------

def block_rms(x: np.ndarray, block: int) -> np.ndarray:
    """RMS of consecutive blocks of ``block`` samples along the last axis.

    sqrt(1/M Σ_{k=(n-1)M+1}^{nM} x²(k)), n = 1..⌊N/M⌋ (the blocks of Yeh, Pan & Le
    eq. 26); an incomplete last block is dropped.
    """
    x = np.asarray(x, dtype=np.float64)
    M = int(block)
    if M < 1:
        raise ValueError(f"block: expected >= 1, got {block}")
    n = x.shape[-1] // M
    xb = x[..., :n * M].reshape(*x.shape[:-1], n, M)
    return np.sqrt(np.mean(xb * xb, axis=-1))


def block_rms_error(extracted: np.ndarray, designated: np.ndarray, block: int) -> np.ndarray:
    """Yeh, Pan & Le eq. (26) in percent, per block: |RMS(y) - RMS(x)| / RMS(x) x 100,
    y the extracted and x the designated (true) waveform.  inf or nan where the
    designated block is zero."""
    ex = block_rms(extracted, block)
    de = block_rms(designated, block)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(ex - de) / de * 100.0
