"""Recursive angular-velocity Vold-Kalman order tracking (AV2KF_OT), streaming.

Implements seed 001 (Yeh, Pan, Le, "Online Real-Time Monitoring System through
Using Adaptive Angular-Velocity VKF Order Tracking"), section 2, eqs. (10)-(25),
for several channels of one machine at once, with decimation in front, an
optional fixed-lag smoother behind, and per-block RMS/amplitude outputs.

Model (one real oscillator per tracked component k = 1..K)::

    structural  x_k(n) - 2cos(ω_k(n)ΔT) x_k(n-1) + x_k(n-2) = ε_k(n)          (10)
                [x_k(n); x_k(n+1)] = M_k(n) [x_k(n-1); x_k(n)] + [0; ε_k(n)]  (11)-(12)
                M_k(n) = [[0, 1], [-1, c_k(n)]],  c_k(n) = 2cos(ω_k(n)ΔT)
    augmented   X(n+1) = F(n+1, n) X(n) + E(n),  F = blockdiag(M_1 .. M_K)     (13)-(14)
    data        y(n) = Σ_k x_k(n) + η(n) = I X(n) + η(n),  I_k = [0 1]          (16)-(18)
    noise       Q1 = q1 I_{2K},  Q2 = r² q1                                     (19)-(25)

ω_k(n) = 2π o_k rpm(n)/60 for an order o_k, 2π f_k for a fixed-frequency
component (the 47-Hz whip beside the orders).  The state is the 2K vector X(n);
its covariance is the FULL 2K x 2K matrix, so components close in frequency are
estimated jointly (the cross-covariances are what separates orders 4 and 4.2).

Kalman filtering based on one-step prediction (Haykin, the paper's ref. [14]),
with X̂(n) = X̂(n|n-1), P(n) = P(n|n-1), h = I (the data row)::

    innovation  e(n) = y(n) - h X̂(n),   S(n) = h P(n) hᵀ + Q2
    gain        k(n) = P(n) hᵀ / S(n)
    filtered    X̂(n|n) = X̂(n) + k(n) e(n),   P(n|n) = P(n) - k(n) S(n) k(n)ᵀ
    prediction  X̂(n+1) = F(n) X̂(n|n),      P(n+1) = F(n) P(n|n) F(n)ᵀ + Q1

The tracked waveform of component k at sample n is the second element of its
pair in X̂(n|n), i.e. x̂_k(n|n) (which is also the first element of the
prediction X̂_k(n+1)).  Its envelope (peak amplitude) at n follows from the
pair (x̂_k(n-1|n), x̂_k(n|n)) of a sinusoid advancing θ = ω_k ΔT per sample::

    A_k(n)² = (x̂_k(n-1)² - c_k x̂_k(n-1) x̂_k(n) + x̂_k(n)²) / sin²θ

Reading the converted seed text (equations partly garbled):

* Eq. (11) uses ω_k(n) in the matrix that maps [x(n-1), x(n)] to [x(n), x(n+1)]:
  the speed of the middle sample n.  For a linear chirp this makes (10) hold
  to second order (the residual is ½ ω̇ ΔT² per step); F(n) below is that matrix.
* Eq. (19) speaks of "Z(n)" and (20) of ψ_k; both are the process noise E(n)
  of (14).  Eq. (24) is missing from the text; (25) is read as Q2 = r² q1 with
  Q1 = q1 I_{2K} ("Q1 is generally an identity matrix multiplied by q1").
* Per-component weighting: the paper allows Q1 "set variously according to the
  nature of the components".  With a weighting factor r_k per component we use
  Q1 = q1 blockdiag((r̄/r_k)² I_2) and Q2 = r̄² q1 with r̄ = r_1, so that
  Q2/Q1_k = r_k² for every k, and with all r_k = r this is exactly (25).
  Only the ratios matter: the gains, hence the estimates, do not depend on q1.
* The paper does not say how X̂ and P start: here X̂(0) = 0, P(0) = Q2 I
  (a prior of the size of the measurement artefacts; Q2 at the speed min_rpm).
* P is symmetrised after every prediction, P <- (P + Pᵀ)/2: rounding makes it
  drift from symmetry, and the Riccati recursion does not damp that drift
  (measured: without it two correct implementations disagree by 1e-11 in the
  gains for good; with it the disagreement decays to 1e-15).

Choices of this implementation (documented, configurable):

* Speed gate and model speed.  Near 0 rpm all orders have the same frequency and
  cannot be told apart: the covariance of their differences would grow without
  bound.  The MODEL speed is therefore clamped from below at ``min_rpm`` (NaN
  counts as 0; the sign is ignored), and every output block whose speed drops
  below ``min_rpm`` anywhere is reported invalid (values NaN).
* Gains.  k(n), S(n), P(n) depend only on the speed history, never on the data,
  so they are computed once per sample for all channels.  ``gains="exact"``
  runs the Riccati recursion above per sample (carried in the state);
  ``gains="table"`` uses the steady-state solution of the Riccati equation at
  the current speed, tabulated on a speed grid and interpolated linearly.  The
  table is filled in segments of 64 speeds when the speed first visits them
  (a machine at constant speed computes one or two segments, a run-up spreads
  the cost over the run); every entry is the same whenever it is computed.
  ``scipy.linalg.solve_discrete_are`` fails on these undamped models; the table
  is computed by a doubling algorithm (:func:`_riccati_doubling`), which returns
  P after 2^j constant-speed steps, j = ceil(log2(horizon_s fs)): the steady
  state wherever the filter converges within the horizon (time constants here
  are tens of ms), and still finite where two components cross (0.47 x 6000 rpm
  = 47 Hz), where no steady state exists.
* Smoother.  The paper's filter is causal.  With ``smoother_lag_s`` set, each
  output block [b0, b1) is also smoothed over the window [b0, b1 + L): a
  Rauch-Tung-Striebel pass in its modified Bryson-Frazier form, which needs no
  matrix inverse::

        λ(n) = hᵀ e(n)/S(n) + A(n)ᵀ λ(n+1),  λ(b1 + L) = 0,  A(n) = F(n)(I - k(n) h)
        X̂(n | b1+L-1) = X̂(n) + P(n) λ(n)

  so every sample of a block is estimated with at least L samples of future.
  It matters near close orders: a causal filter whose envelope model is a random
  walk lags ramping amplitudes by about 1/Δf when it must separate orders Δf apart.
* Decimation.  The input (e.g. 25 kHz) is low-passed (second-order sections,
  state ``zi`` carried between calls; the compiled kernel filters and decimates
  in one pass, the numpy path uses ``scipy.signal.sosfilt``, imported only
  there) and every D-th sample is kept.  The tracker rate fs_in/D is
  at least ``oversample`` (5) times the highest tracked frequency f_hi at
  ``max_rpm``; D is the largest such integer that also divides
  fs_in/output_rate_hz when that is an integer (so output blocks hold a whole
  number of tracker samples).  The filter is a Chebyshev type II low-pass (flat,
  monotonic pass band; order from ``cheb2ord``, 7 for 25 kHz -> 1250 Hz): at
  most 0.001 dB (0.012 %) down at f_hi, and at least 80 dB down from
  fs_track - f_hi, the lowest frequency that folds onto a tracked one.  It is
  designed in numpy (:func:`_cheb2ord`, :func:`_cheby2_sos`: scipy.signal's
  cheb2ord / cheby2 / zpk2sos step by step, the same sections), so the daemon
  never imports scipy.signal (~70 MB resident, ~0.9 s).
  The speed (one value per input sample, from the tacho) is delayed by the
  filter's group delay at DC, rounded to whole input samples (``delay_in``), and
  decimated with the same phase as the signal, so that ω(n) belongs to the
  signal sample it models.  Tracker sample j is input sample jD filtered; it
  stands for the signal at input index jD - delay_in (``t_in``).
* Outputs.  Waveforms at the tracker rate; per output block of B tracker
  samples (B = fs_track/output_rate_hz, 10 Hz by default) the mean speed, the RMS
  (sqrt of the mean of x̂_k² over the block) and the mean envelope A_k (peak
  amplitude) per channel and component, and a valid flag (speed >= min_rpm
  throughout the block and every tracked frequency below fs_track/2), and per
  channel the number of the block's samples that had no measurement
  (``missing``, see below).  Blocks are aligned to absolute tracker-sample
  indices, so a stream can be split anywhere.
* Latency (``latency_s``): decimation-filter delay + smoother lag + one output
  block.  The causal waveform itself is late by the filter delay only.
* Bandwidth.  A component may be given by r, by a -3 dB bandwidth in Hz or in %
  of its frequency (:class:`TrackedComponent`).  The mapping is the -3 dB width
  of the isolated steady-state one-component filter (:func:`r_to_bandwidth`,
  inverted by :func:`bandwidth_to_r`); for B ≪ f it is B = fs/(√2 π r sin θ),
  θ = 2π f/fs, with the envelope time constant τ = 1/(π B) (:func:`time_constant`).
  r is per sample: at fs = 2 kHz the paper's r = 2000 is 0.37 Hz wide at 200 Hz
  (τ = 0.83 s), r = 50 is 15 Hz (τ = 21 ms).  Given a bandwidth, r follows the
  speed (per sample, smoothly).  :meth:`OrderTracker.describe` reports r, the
  bandwidth and τ per component at a speed.

Missing samples (NaN in ``y``: a lost RAW frame is one channel's, a gap in the
stream all channels'):

* Anti-alias filter.  It cannot take NaN: a missing input is given to it as 0.
  The zero spoils the filter's output from that input on, as long as the
  filter's impulse response h lasts, so every tracker sample whose filtered
  value (input jD) is within W inputs after a missing input i (i <= jD < i + W)
  is treated as missing too (``TrackerOutput.missing``, per channel; the state
  carries the last missing input across calls).  W (``missing_window``) is
  computed from the designed sections (:func:`_missing_window`): the shortest
  W with Σ_{m>=W} |h(m)| <= 1e-3 (:data:`MISSING_TAIL`), so that the zero fill
  changes an output used as a measurement by at most 1e-3 of the missing
  input's peak, whatever the signal (-60 dB).  Default raw chain (25 kHz,
  orders 1-4 to 3600 rpm, Chebyshev II of order 7, D = 20): W = 363 inputs =
  14.5 ms = 18-19 tracker samples after the last missing input (close orders
  to 3000 rpm: 414; 10 kHz, D = 8: 167).  An energy tail < 1e-4 would give 235
  inputs, with a worst case of 1.6 % of the missing peak left after it.
  Without decimation (D = 1) W = 1: only the missing samples themselves.
* Filter.  At a missing sample n there is no measurement: eqs. (19)-(24) with
  the measurement update left out, i.e. gain 0 and no innovation::

      k(n) = 0,  X̂(n|n) = X̂(n),  P(n|n) = P(n)
      X̂(n+1) = F(n) X̂(n),  P(n+1) = F(n) P(n) F(n)ᵀ + Q1

  (``e(n)`` is stored as 0).  ``gains="exact"`` runs exactly this Riccati time
  update; ``gains="table"`` zeroes the tabulated gain there (see below).
* Smoother.  The MBF recursion above with k(n) = 0, so A(n) = F(n)(I - 0·h) = F(n),
  and without its innovation term (hᵀ e(n)/S(n) is the measurement's
  contribution; there is none)::

      λ(n) = F(n)ᵀ λ(n+1),   X̂(n | b1+L-1) = X̂(n) + P(n) λ(n)

  which is the RTS step through a sample without measurement
  (J = P(n) F(n)ᵀ P(n+1)⁻¹ with P(n|n) = P(n)); :func:`reference_track` runs that.
* Channels.  The mask is per channel.  The table's gains are shared and
  zeroed per channel (C kernel: per sample and channel; numpy: the channels
  that miss the same samples as a group, :func:`_mask_groups`).  The exact
  gains come from one Riccati recursion for all channels, so with
  ``gains="exact"`` the channels must miss the same samples (ValueError
  otherwise: run one tracker per channel); :func:`reference_track` gives each
  channel its own P when they differ.
* Outputs.  The estimates at missing samples are the predictions and stay in
  the waveforms and in the block RMS and envelopes (a held amplitude, not a
  drop to zero); ``BlockStats.missing`` counts the missing samples of each
  block and channel, so a block that is partly (or wholly) a prediction says so.
* Approximation of ``gains="table"``: the table holds the steady state, so
  after a gap new data are weighted as in the steady state, where the exact
  gains (P grown during the gap) weight them more, and the smoother uses the
  steady-state P through and after the gap, which over-weights the
  innovations just after a gap for the samples before it.  Measured
  (close_orders at 2 kHz, r = 50, lag 0.1 s, eq. (26) above 800 rpm):

  - 10-ms holes every 0.5 s (tests/test_order_tracker.py): as NaN the holes
    change the block RMS near them by at most 0.15 % causal and 1.5 %
    smoothed (given as zeros, the old behaviour: 15 % and 9 %); table and
    exact gains within 0.4 points of each other there.
  - one 10-ms hole, anywhere between 1.2 s and 4 s (13-ms steps): worst
    smoothed block without missing samples 4.5 % (order 4) / 1.8 % (4.2) with
    table gains, 1.5 % / 0.7 % with exact ones (1.4 % / 0.8 % without holes):
    the block just before the hole.  In the daemon (25 kHz, D = 20, 20-Hz
    bandwidth, W adds 17 ms) one lost RAW frame 13-23 ms after a block raised
    that block from 0.2 % to 4.8 % (order 4) / 3.1 % (order 4.2) at 1100 rpm.
  - long holes at 900 rpm: the first block after a 0.2-s hole 4.0 % causal
    (exact 3.0 %), the smoothed blocks inside it (flagged) up to 67 % (exact
    11 %); after a 1-s hole (the daemon's MAX_FILL_S) 38 % causal / 18 %
    smoothed, exact 10 % / 0.8 % (zeros: 50 % / 33 %); the blocks after that
    about 3 % or less.
  So for short gaps at well separated orders the table is fine; near close
  orders (~800-1100 rpm here) and for gaps of a large part of a second the
  exact gains are clearly better.  Only the blocks holding missing samples
  are flagged, not the ones next to them.

Measured on section 4.1's signals (tests/test_order_tracker.py; eq. (26) per
0.1-s block above 800 rpm, close_orders with 5 % noise, r = 50): causal, the
worst blocks are 9.8 % (order 4) and 6.5 % (order 4.2) at 930 rpm, where the
orders are 3 Hz apart; below 5 % / 3 % from 1110 / 1410 rpm on.  With the
smoother (lag 0.1 s, latency 0.2 s): at most 1.4 % and 0.8 % in every block,
at 2 kHz and from 25 kHz alike.

Three implementations of the recursions, with identical semantics:

* :func:`reference_track` — one sample at a time with plain 2K x 2K matrices,
  the equations above one to one (and a textbook RTS, J = P(n|n) Fᵀ P(n+1|n)⁻¹,
  for the smoother; missing samples: no measurement update).  The reference
  the others are tested against (to 1e-9).
* numpy — no numpy call per sample: the gain table is interpolated for a whole
  block, and the linear time-varying recursions X̂(n+1) = A(n) X̂(n) + F(n) k(n) y(n)
  and λ(n) = A(n)ᵀ λ(n+1) + g(n) are run by :func:`_scan`, a two-level
  chunked scan (m steps vectorised over the T/m chunks, then T/m chunk joins).
  The forward chunks (m = 32) are aligned to absolute sample indices and the
  chunk cut by the end of a call is re-run from its start in the next one, so
  a stream split anywhere gives bit-identical results (with missing samples
  too: channels that miss different samples are run once per group, each time
  on all channels, so that every product has the same shape whatever the
  grouping).  ``gains="exact"`` in
  numpy loops over samples for the Riccati recursion (slow; for tests).
* ``cmsensord.dsp._trackerkernel`` — the per-sample loops (and the decimator's
  filter) in C (built by
  ``python setup.py build_ext --inplace`` / ``pip install``), optional.

State lives in arrays (:class:`TrackerState`) with a leading channel axis where
per channel, and is carried between calls.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields

import numpy as np

try:  # the compiled kernel is optional: numpy is the fallback
    from cmsensord.dsp import _trackerkernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _trackerkernel = None

__all__ = [
    "DEFAULT_R",
    "AlarmEvent",
    "BlockStats",
    "OrderAlarm",
    "OrderTracker",
    "TrackedComponent",
    "TrackerOutput",
    "TrackerState",
    "bandwidth_to_r",
    "component_r",
    "have_kernel",
    "r_to_bandwidth",
    "reference_track",
    "time_constant",
]

DEFAULT_R = 50.0
"""Default weighting factor.  At a 2-kHz tracker rate its -3 dB bandwidth is
15 Hz at 200 Hz, 29 Hz at 100 Hz (see :func:`r_to_bandwidth`; time constant
21 ms at 200 Hz).  The paper's r = 2000 is 0.37 Hz wide at 200 Hz here (time
constant 0.83 s): too slow for the close-orders run-up, whose ramps it then
lags by about 20 % (eq. 26)."""


def have_kernel() -> bool:
    """True when the compiled kernel is importable."""
    return _trackerkernel is not None


# --------------------------------------------------------------------------
# the decimator's anti-alias low-pass, designed in numpy (no scipy.signal)
# --------------------------------------------------------------------------
# The daemon does not import scipy.signal: it costs ~70 MB of resident memory
# and ~0.9 s for three small functions.  These follow scipy.signal's cheb2ord,
# cheby2(output="sos") and zpk2sos(pairing="nearest") step by step, in the
# same arithmetic, so the sections are scipy's to rounding (compared in
# tests/test_order_tracker.py); the cascade runs in the compiled kernel.

def _cheb2ord(f_pass: float, f_stop: float, gpass: float, gstop: float, fs: float) -> tuple[int, float]:
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


def _cheby2_sos(order: int, gstop: float, f_edge: float, fs: float) -> np.ndarray:
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


def _sos_response(sos: np.ndarray, f, fs: float) -> np.ndarray:
    """Complex frequency response of the sections at frequencies f [Hz]."""
    zi = np.exp(-2j * np.pi * np.asarray(f, dtype=np.float64) / fs)
    h = np.ones(zi.shape, dtype=complex)
    for b0, b1, b2, a0, a1, a2 in sos:
        h = h * (b0 + zi * (b1 + zi * b2)) / (a0 + zi * (a1 + zi * a2))
    return h


def _sos_dc_delay(sos: np.ndarray) -> float:
    """Group delay at DC [samples] of the sections: per polynomial Σ k c_k / Σ c_k
    (d arg / dω at ω = 0), numerator minus denominator, summed over the sections."""
    k = np.arange(3.0)
    return float(sum(np.dot(k, s[:3]) / s[:3].sum() - np.dot(k, s[3:]) / s[3:].sum() for s in sos))


MISSING_TAIL = 1e-3
"""L1 tail of the anti-alias filter's impulse response beyond which a missing input
no longer spoils its outputs (see :func:`_missing_window` and "Missing samples" in
the module docstring)."""


def _sos_impulse(sos: np.ndarray) -> np.ndarray:
    """Impulse response of the sections (direct form II transposed, the decimator's
    arithmetic), until it has decayed to about 1e-17 of its start: the largest pole
    radius ρ sets the length, log(1e-17)/log ρ + 64 samples (at most 2^20)."""
    rho = max(float(np.max(np.abs(np.roots(s[3:])))) if np.any(s[4:]) else 0.0 for s in sos)
    n = 64 if rho <= 0.0 else min(1 << 20, math.ceil(math.log(1e-17) / math.log(rho)) + 64)
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


def _missing_window(sos: np.ndarray | None, tail: float = MISSING_TAIL) -> int:
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


# --------------------------------------------------------------------------
# components and their weighting factors
# --------------------------------------------------------------------------

@dataclass(frozen=True)
class TrackedComponent:
    """One tracked component: an order of the shaft speed or a fixed frequency.

    Exactly one of ``order`` / ``freq_hz``.  At most one of ``r`` (the paper's
    weighting factor), ``bandwidth_hz`` (the -3 dB bandwidth of the isolated
    steady-state filter, see :func:`r_to_bandwidth`) or ``bandwidth_pct`` (the
    same in % of the component's frequency, so r varies with speed); none
    means r = :data:`DEFAULT_R`.
    """

    name: str
    order: float | None = None
    freq_hz: float | None = None
    r: float | None = None
    bandwidth_hz: float | None = None
    bandwidth_pct: float | None = None

    def __post_init__(self):
        if (self.order is None) == (self.freq_hz is None):
            raise ValueError(f"component {self.name!r}: give exactly one of order, freq_hz")
        if self.order is not None and not self.order > 0:
            raise ValueError(f"component {self.name!r}: order must be > 0, got {self.order}")
        if self.freq_hz is not None and not self.freq_hz > 0:
            raise ValueError(f"component {self.name!r}: freq_hz must be > 0, got {self.freq_hz}")
        given = [k for k in ("r", "bandwidth_hz", "bandwidth_pct") if getattr(self, k) is not None]
        if len(given) > 1:
            raise ValueError(f"component {self.name!r}: give at most one of r, bandwidth_hz, "
                             f"bandwidth_pct, got {given}")
        for k in given:
            if not getattr(self, k) > 0:
                raise ValueError(f"component {self.name!r}: {k} must be > 0, got {getattr(self, k)}")

    def freq(self, rpm) -> np.ndarray:
        """Frequency [Hz] at shaft speed ``rpm``."""
        rpm = np.asarray(rpm, dtype=np.float64)
        if self.order is not None:
            return self.order * rpm / 60.0
        return np.full(rpm.shape, float(self.freq_hz))


def _omega(components: Sequence[TrackedComponent], speed: np.ndarray) -> np.ndarray:
    """ω_k(n) [rad/s] for model speeds ``speed`` (T,): (T, K)."""
    return np.stack([2.0 * np.pi * c.freq(speed) for c in components], axis=-1)


def _model_speed(rpm: np.ndarray, min_rpm: float) -> np.ndarray:
    """The speed the model uses: |rpm| clamped from below at min_rpm (NaN -> min_rpm)."""
    s = np.abs(np.asarray(rpm, dtype=np.float64))
    s = np.where(np.isfinite(s), s, 0.0)
    return np.maximum(s, float(min_rpm))


# --------------------------------------------------------------------------
# steady-state Riccati (doubling) and the r <-> bandwidth mapping
# --------------------------------------------------------------------------

def _f_matrices(c: np.ndarray) -> np.ndarray:
    """F(n) of eq. (13) for coefficients c (..., K) = 2cos(ω ΔT): (..., 2K, 2K)."""
    K = c.shape[-1]
    F = np.zeros(c.shape[:-1] + (2 * K, 2 * K))
    i = np.arange(K)
    F[..., 2 * i, 2 * i + 1] = 1.0
    F[..., 2 * i + 1, 2 * i] = -1.0
    F[..., 2 * i + 1, 2 * i + 1] = c
    return F


def _q_diag(rk: np.ndarray, q1: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample process-noise diagonal (..., 2K) and Q2 (...) from r_k (..., K).

    Q1 = q1 blockdiag((r̄/r_k)² I_2), Q2 = r̄² q1, r̄ = r_1 (eq. 25 generalised).
    """
    rbar = rk[..., :1]
    q1k = q1 * (rbar / rk) ** 2
    return np.repeat(q1k, 2, axis=-1), q1 * rbar[..., 0] ** 2


def _riccati_doubling(c: np.ndarray, qdiag: np.ndarray, q2: np.ndarray, n_double: int) -> np.ndarray:
    """P(n|n-1) after 2^n_double constant-model steps from P = 0, batched: (G, 2K, 2K).

    Structure-preserving doubling for the filter Riccati equation
    P = F P Fᵀ - F P hᵀ (h P hᵀ + Q2)⁻¹ h P Fᵀ + Q1, written as the control form
    with A = Fᵀ, G = hᵀh/Q2, H = Q1::

        W = I + G_j H_j
        A_{j+1} = A_j W⁻¹ A_j
        G_{j+1} = G_j + A_j W⁻¹ G_j A_jᵀ
        H_{j+1} = H_j + A_jᵀ H_j W⁻¹ A_j

    H_j is P after 2^j prediction steps.  Each model of the batch stops on its
    own once converged (H changes by at most 1e-15 of its largest element), so
    its result does not depend on the others in the batch (a gain table or r
    grid filled piecewise equals one filled at once); the stopped ones leave
    the batch.  W⁻¹A and W⁻¹G come from one solve.
    """
    F = _f_matrices(c)
    G, d = F.shape[0], F.shape[-1]
    h = np.zeros(d)
    h[1::2] = 1.0
    A = np.swapaxes(F, -1, -2).copy()
    Gm = np.outer(h, h)[None, :, :] / q2[:, None, None]
    H = np.zeros((G, d, d))
    H[:, np.arange(d), np.arange(d)] = qdiag
    out = np.empty((G, d, d))
    act = np.arange(G)
    eye = np.eye(d)
    for j in range(n_double):
        W = eye + Gm @ H
        X = np.linalg.solve(W, np.concatenate([A, Gm], axis=-1))
        WA, WG = X[..., :d], X[..., d:]
        At = np.swapaxes(A, -1, -2)
        Hn = H + At @ H @ WA
        Gm = Gm + A @ WG @ At
        A = A @ WA
        Hn = 0.5 * (Hn + np.swapaxes(Hn, -1, -2))
        Gm = 0.5 * (Gm + np.swapaxes(Gm, -1, -2))
        done = (np.max(np.abs(Hn - H), axis=(1, 2))
                <= 1e-15 * np.max(np.abs(Hn), axis=(1, 2)))
        H = Hn
        if j == n_double - 1 or done.all():
            out[act] = H
            break
        if done.any():
            out[act[done]] = H[done]
            keep = ~done
            act, A, Gm, H = act[keep], A[keep], Gm[keep], H[keep]
    return out


def _single_filter(r: np.ndarray, theta: np.ndarray):
    """The isolated steady-state one-component filter for r, θ (G,): the pieces of
    X̂(n+1) = A X̂(n) + F k y(n),  x̂(n|n) = e₂ᵀ(I - k h) X̂(n) + k₂ y(n)."""
    c = 2.0 * np.cos(theta)[:, None]
    qd, q2 = _q_diag(np.asarray(r, dtype=np.float64)[:, None], 1.0)
    P = _riccati_doubling(c, qd, q2, 40)
    S = P[:, 1, 1] + q2
    k = P[:, :, 1] / S[:, None]                       # (G, 2)
    F = _f_matrices(c)                                # (G, 2, 2)
    IKh = np.eye(2) - k[:, :, None] * np.array([0.0, 1.0])[None, None, :]
    A = F @ IKh
    Fk = (F @ k[:, :, None])[:, :, 0]                 # (G, 2)
    return A, Fk, IKh[:, 1, :], k[:, 1]


def _single_response(filt, nu: np.ndarray) -> np.ndarray:
    """|T(e^{jν})|² of :func:`_single_filter`'s filters at ν (G, M) rad/sample:
    T(z) = e₂ᵀ(I - k h)(zI - A)⁻¹ F k + k₂."""
    A, Fk, row, k2 = filt
    z = np.exp(1j * nu)
    a, b, cc, dd = A[:, 0, 0, None], A[:, 0, 1, None], A[:, 1, 0, None], A[:, 1, 1, None]
    det = (z - a) * (z - dd) - b * cc
    u0 = ((z - dd) * Fk[:, 0, None] + b * Fk[:, 1, None]) / det
    u1 = (cc * Fk[:, 0, None] + (z - a) * Fk[:, 1, None]) / det
    T = row[:, 0, None] * u0 + row[:, 1, None] * u1 + k2[:, None]
    return np.abs(T) ** 2


def r_to_bandwidth(r, freq_hz, fs: float) -> np.ndarray:
    """-3 dB bandwidth [Hz] of the isolated steady-state tracker with weighting factor r.

    The response of the steady-state one-component filter from y to x̂(n|n) is a
    band-pass with |T| = 1 exactly at the tracked frequency f (the model's poles
    are on the unit circle); the bandwidth is f_hi - f_lo where |T|² = 1/2
    either side (an edge at 0 or fs/2 if |T| never drops that far).  It depends
    on r and on θ = 2π f/fs, not on q1.  When B ≪ f (to 0.1 % for B < f/10)::

        B ≈ fs / (√2 π r sin θ),   τ = 1/(π B) ≈ √2 r sin θ / fs

    a first-order low-pass on the complex envelope (:func:`time_constant`):
    the process noise q1 on both samples of the pair (x(n-1), x(n)) is noise
    of variance 2 q1/sin²θ on the envelope, hence the sin θ.  So r is per
    sample and per frequency: the same r is narrower at a higher tracker rate
    and wider at a low frequency.  Vectorised over r and f.
    """
    r, f = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(freq_hz, dtype=np.float64))
    shape = r.shape
    r, f = r.ravel(), f.ravel()
    theta = 2.0 * np.pi * f / fs
    # geometric grid of offsets (rad/sample) outwards from θ (ratio 1.2 between
    # neighbours), then bisection to double precision
    off = np.geomspace(1e-7, np.pi, 100)
    filt = _single_filter(r, theta)
    edges = []
    for sgn, limit in ((-1.0, 0.0), (1.0, np.pi)):
        nu = theta[:, None] + sgn * off[None, :]
        inside = (nu > 1e-9) & (nu < np.pi - 1e-9)
        g = _single_response(filt, np.clip(nu, 1e-9, np.pi - 1e-9))
        below = (g < 0.5) & inside
        has = below.any(axis=1)
        i = np.where(has, below.argmax(axis=1), 0)
        lo = np.where(i > 0, off[np.maximum(i - 1, 0)], 0.0)
        hi = off[i]
        for _ in range(48):
            mid = 0.5 * (lo + hi)
            gm = _single_response(filt, (theta + sgn * mid)[:, None])[:, 0]
            lo, hi = np.where(gm < 0.5, lo, mid), np.where(gm < 0.5, mid, hi)
        edge = theta + sgn * 0.5 * (lo + hi)
        edges.append(np.where(has, edge, limit))
    return ((edges[1] - edges[0]) * fs / (2.0 * np.pi)).reshape(shape)


def bandwidth_to_r(bandwidth_hz, freq_hz, fs: float) -> np.ndarray:
    """The weighting factor r whose isolated filter has this -3 dB bandwidth (inverse of
    :func:`r_to_bandwidth`, by secant iteration in log-log; vectorised)."""
    b, f = np.broadcast_arrays(np.asarray(bandwidth_hz, dtype=np.float64),
                               np.asarray(freq_hz, dtype=np.float64))
    shape = b.shape
    b, f = b.ravel(), f.ravel()
    if np.any(b <= 0) or np.any(b >= fs / 2):
        raise ValueError(f"bandwidth_hz: expected in (0, fs/2 = {fs / 2}), got {b.min()}..{b.max()}")
    # first guess: the narrow-band relation B ≈ fs / (√2 π r sin θ) (see r_to_bandwidth)
    sin_t = np.maximum(np.sin(2.0 * np.pi * f / fs), 1e-3)
    x0 = np.log(fs / (np.sqrt(2.0) * np.pi * b * sin_t))
    x1 = x0 + 0.01
    g0 = np.log(r_to_bandwidth(np.exp(x0), f, fs)) - np.log(b)
    act = np.arange(b.size)          # elements still iterating (the others have converged,
    for _ in range(30):              # or sit where the bandwidth saturates near 0 or fs/2)
        g1 = np.log(r_to_bandwidth(np.exp(x1[act]), f[act], fs)) - np.log(b[act])
        done = np.abs(g1) < 1e-10    # bandwidth to 1e-10 relative
        x0[act[done]] = x1[act[done]]
        keep = ~done
        if not keep.any():
            break
        a, g1, gp = act[keep], g1[keep], g0[act[keep]]
        den = np.where(g1 != gp, g1 - gp, 1.0)
        x2 = np.where(g1 != gp, x1[a] - g1 * (x1[a] - x0[a]) / den, x1[a])
        x0[a], g0[a] = x1[a], g1
        x1[a] = np.clip(x2, x1[a] - 2.0, x1[a] + 2.0)
        act = a
    else:
        x0[act] = x1[act]
    return np.exp(x0).reshape(shape)


def time_constant(r, freq_hz, fs: float) -> np.ndarray:
    """Envelope time constant [s] of the isolated steady-state tracker: -ΔT/ln ρ,
    ρ the spectral radius of A = F(I - k h) (the decay of an estimation error);
    ≈ √2 r sin θ / fs = 1/(π B) when B ≪ f (see :func:`r_to_bandwidth`)."""
    r, f = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(freq_hz, dtype=np.float64))
    shape = r.shape
    r, f = r.ravel(), f.ravel()
    c = 2.0 * np.cos(2.0 * np.pi * f / fs)[:, None]
    qd, q2 = _q_diag(r[:, None], 1.0)
    P = _riccati_doubling(c, qd, q2, 40)
    S = P[:, 1, 1] + q2
    k = P[:, :, 1] / S[:, None]
    A = _f_matrices(c) @ (np.eye(2) - k[:, :, None] * np.array([0.0, 1.0])[None, None, :])
    rho = np.max(np.abs(np.linalg.eigvals(A)), axis=-1)
    return (-1.0 / (fs * np.log(rho))).reshape(shape)


def component_r(components: Sequence[TrackedComponent], speed, fs: float) -> np.ndarray:
    """Weighting factor r_k at model speeds ``speed`` (T,): (T, K).

    Constant for a component given by r (or none: DEFAULT_R); from
    :func:`bandwidth_to_r` for one given by bandwidth_hz (evaluated at its
    frequency at each speed: a mild dependence) or bandwidth_pct (bandwidth
    = pct/100 x its frequency).  Bandwidth-given orders are computed on a fixed
    grid of 256 speeds (geometric, 10 to 100 000 rpm) and interpolated in
    log-log (to about 1e-4 of the bandwidth), so the result is a smooth,
    deterministic function of the speed.  r is per tracker sample: the same r
    is a different bandwidth in Hz at a different tracker rate.

    The grid values are computed when first needed (the grid points around
    the speeds asked for, all components in one batch) and cached; each is
    the same whenever and with whichever others it is computed.
    """
    speed = np.asarray(speed, dtype=np.float64)
    out = np.empty(speed.shape + (len(components),))
    grid_comps = [c for c in components if (c.bandwidth_hz is not None or c.bandwidth_pct is not None)
                  and c.freq_hz is None]
    span = None
    finite = speed[np.isfinite(speed)] if grid_comps else speed[:0]
    if finite.size:
        s = np.clip(finite, _R_SPEEDS[0], _R_SPEEDS[-1])
        lo, hi = float(np.min(s)), float(np.max(s))
        j0 = min(max(int(np.searchsorted(_R_SPEEDS, lo, side="right")) - 1, 0), _R_N - 2)
        j1 = min(max(int(np.searchsorted(_R_SPEEDS, hi, side="right")) - 1, 0), _R_N - 2) + 1
        span = (j0, j1 + 1)                          # grid points [j0, j1] bracket every speed
        _fill_r_grid(grid_comps, fs, *span)
    for i, c in enumerate(components):
        if c.bandwidth_hz is None and c.bandwidth_pct is None:
            out[..., i] = DEFAULT_R if c.r is None else c.r
        elif c.freq_hz is not None:
            key = (c, fs)
            if key not in _R_CACHE:
                _R_CACHE[key] = float(bandwidth_to_r(c.bandwidth_hz, c.freq_hz, fs))
            out[..., i] = _R_CACHE[key]
        elif span is None:                           # no finite speed
            out[..., i] = np.nan
        else:
            j0, j1 = span
            lr = _R_CACHE[(c, fs)][j0:j1]
            s = np.clip(speed, _R_SPEEDS[0], _R_SPEEDS[-1])
            out[..., i] = np.exp(np.interp(np.log(s), _R_LOG[j0:j1], lr))
    return out


def _fill_r_grid(components: Sequence[TrackedComponent], fs: float, j0: int, j1: int) -> None:
    """Compute the log r of grid points [j0, j1) not yet cached, for all these
    (bandwidth-given order) components in one batch."""
    idx, bws, fs_, dest = [], [], [], []
    for c in components:
        key = (c, fs)
        lr = _R_CACHE.get(key)
        if lr is None:
            lr = _R_CACHE[key] = np.full(_R_N, np.nan)
        miss = j0 + np.flatnonzero(np.isnan(lr[j0:j1]))
        if not miss.size:
            continue
        grid = _R_SPEEDS[miss]
        f = c.freq(grid)
        bw = c.bandwidth_hz if c.bandwidth_hz is not None else c.bandwidth_pct / 100.0 * f
        bws.append(np.minimum(np.broadcast_to(bw, f.shape), 0.45 * fs))
        fs_.append(np.minimum(f, 0.49 * fs))
        idx.append(miss)
        dest.append(lr)
    if not idx:
        return
    lr_all = np.log(bandwidth_to_r(np.concatenate(bws), np.concatenate(fs_), fs))
    n = 0
    for miss, lr in zip(idx, dest):
        lr[miss] = lr_all[n:n + miss.size]
        n += miss.size


_R_GRID = (10.0, 100_000.0)   # rpm range of the bandwidth -> r grid
_R_N = 256                    # its points (geometric)
_R_SPEEDS = np.geomspace(_R_GRID[0], _R_GRID[1], _R_N)
_R_LOG = np.log(_R_SPEEDS)
_R_CACHE: dict = {}           # (component, fs) -> log r on the grid (NaN: not computed yet)


# --------------------------------------------------------------------------
# the reference: eqs. (10)-(25) one sample at a time, textbook matrices
# --------------------------------------------------------------------------

def reference_track(y, rpm, components: Sequence[TrackedComponent], fs: float, *,
                    q1: float = 0.1, min_rpm: float = 300.0,
                    smoother_lag: int | None = None, block: int = 0):
    """Plain per-sample Kalman one-step prediction of eqs. (10)-(25), exact gains.

    y: (T,) or (T, C) at ``fs`` (no decimation); rpm: (T,).  Returns the filtered
    waveforms x̂_k(n|n), (T, C, K) (or (T, K) for 1-D y).  With ``smoother_lag``
    = L and ``block`` = B it also returns the fixed-lag smoothed waveforms: for
    each block [jB, (j+1)B) a textbook Rauch-Tung-Striebel pass (with
    J = P(n|n) Fᵀ P(n+1|n)⁻¹) over [jB, (j+1)B + L); samples whose window is
    incomplete at the end are NaN.

    NaN in y is a missing sample of that channel: no measurement update, X̂(n|n) =
    X̂(n|n-1), P(n|n) = P(n|n-1) (and the RTS pass uses those).  Each channel is its
    own Kalman filter with its own P; when the channels miss different samples they
    are run one at a time.
    """
    y = np.asarray(y, dtype=np.float64)
    one = y.ndim == 1
    Y = y[:, None] if one else y
    T, C = Y.shape
    gone = np.isnan(Y)
    if C > 1 and (gone != gone[:, :1]).any():             # per-channel P: one channel at a time
        runs = [reference_track(Y[:, c], rpm, components, fs, q1=q1, min_rpm=min_rpm,
                                smoother_lag=smoother_lag, block=block) for c in range(C)]
        if smoother_lag is None:
            return np.stack(runs, axis=1)
        return np.stack([r[0] for r in runs], axis=1), np.stack([r[1] for r in runs], axis=1)
    gone = gone[:, 0]
    K = len(components)
    d = 2 * K
    speed = _model_speed(rpm, min_rpm)
    w = _omega(components, speed)
    rk = component_r(components, speed, fs)
    h = np.zeros((1, d))
    h[0, 1::2] = 1.0
    qd, q2 = _q_diag(rk, q1)
    X = np.zeros((d, C))
    _, q20 = _q_diag(component_r(components, np.array([min_rpm]), fs), q1)
    P = q20[0] * np.eye(d)                                  # P(0) = Q2 I, Q2 at min_rpm
    xf_all = np.empty((T, d, C))
    keep = smoother_lag is not None
    if keep:
        xp_all, Pp_all, Pf_all, F_all = (np.empty((T, d, C)), np.empty((T, d, d)),
                                          np.empty((T, d, d)), np.empty((T, d, d)))
    for n in range(T):
        F = np.zeros((d, d))                                # eqs. (11)-(13)
        for k in range(K):
            F[2 * k, 2 * k + 1] = 1.0
            F[2 * k + 1, 2 * k] = -1.0
            F[2 * k + 1, 2 * k + 1] = 2.0 * math.cos(w[n, k] / fs)
        Q1 = np.diag(qd[n])                                 # eq. (25)
        Q2 = q2[n]
        if gone[n]:                                         # no measurement: time update only
            Xf, Pf = X, P
        else:
            S = (h @ P @ h.T)[0, 0] + Q2
            G = P @ h.T / S                                 # gain (2K, 1)
            e = Y[n][None, :] - h @ X                       # innovation (1, C), eq. (18)
            Xf = X + G @ e
            Pf = P - G @ h @ P
        if keep:
            xp_all[n], Pp_all[n], Pf_all[n], F_all[n] = X, P, Pf, F
        xf_all[n] = Xf
        X = F @ Xf                                          # eq. (14)
        P = F @ Pf @ F.T + Q1
        P = 0.5 * (P + P.T)                                 # keep P symmetric (see module doc)
    wave = np.transpose(xf_all[:, 1::2, :], (0, 2, 1))      # (T, C, K)
    if not keep:
        return wave[:, 0, :] if one else wave
    L, B = int(smoother_lag), int(block)
    sm = np.full((T, d, C), np.nan)
    for b0 in range(0, T, B):
        b1 = b0 + B
        end = b1 + L
        if end > T:
            break
        xs = xf_all[end - 1]
        for n in range(end - 2, b0 - 1, -1):
            Ppred = F_all[n] @ Pf_all[n] @ F_all[n].T + np.diag(qd[n])   # = Pp_all[n+1]
            J = np.linalg.solve(Ppred, F_all[n] @ Pf_all[n]).T             # Pf Fᵀ Ppred⁻¹
            xs = xf_all[n] + J @ (xs - F_all[n] @ xf_all[n])
            if n < b1:
                sm[n] = xs
        if b1 - 1 == end - 1:
            sm[end - 1] = xf_all[end - 1]
    swave = np.transpose(sm[:, 1::2, :], (0, 2, 1))
    return (wave[:, 0, :], swave[:, 0, :]) if one else (wave, swave)


# --------------------------------------------------------------------------
# the numpy recursions
# --------------------------------------------------------------------------

def _scan(A: np.ndarray, b: np.ndarray, u0: np.ndarray, m: int | None = None) -> np.ndarray:
    """u(t+1) = A[t] u(t) + b[t] for t = 0..T-1, without a numpy call per step.

    A: (..., T, d, d), b: (..., T, d, C), u0: (..., d, C) -> u(0..T): (..., T+1, d, C).
    Two levels: the T steps are cut into J chunks of m ≈ sqrt(T); all chunks run
    their m steps at once from a zero state, also accumulating their transition
    matrix Φ (M = [Φ | z]); then the J chunk starts s_j are joined in sequence,
    and every state is u = Φ(j, i) s_j + z(j, i) in one batched product.
    (A pairwise composition of the chunk maps, or re-running the chunks from
    their starts, measured slower here.)  ``m`` fixes the chunk length (the
    forward filter uses chunks aligned to absolute sample indices, see
    :meth:`OrderTracker._filter`); by default m = ceil(sqrt(T)).
    """
    T, d = A.shape[-3], A.shape[-1]
    C = b.shape[-1]
    batch = A.shape[:-3]
    if m is None:
        m = max(1, math.ceil(math.sqrt(T)))
    J = -(-T // m)
    pad = J * m - T
    if pad:
        eye = np.broadcast_to(np.eye(d), batch + (pad, d, d))
        A = np.concatenate([A, eye], axis=-3)
        b = np.concatenate([b, np.zeros(batch + (pad, d, C))], axis=-3)
    A = A.reshape(batch + (J, m, d, d))
    b = b.reshape(batch + (J, m, d, C))
    M = np.zeros(batch + (J, d, d + C))
    M[..., :, :d] = np.eye(d)
    store = np.empty(batch + (J, m, d, d + C))
    for i in range(m):
        store[..., i, :, :] = M
        M = A[..., i, :, :] @ M
        M[..., d:] += b[..., i, :, :]
    s = np.empty(batch + (J + 1, d, C))
    s[..., 0, :, :] = u0
    for j in range(J):
        s[..., j + 1, :, :] = M[..., j, :, :d] @ s[..., j, :, :] + M[..., j, :, d:]
    u = store[..., :d] @ s[..., :J, None, :, :] + store[..., d:]
    u = u.reshape(batch + (J * m, d, C))[..., :T, :, :]
    return np.concatenate([u, s[..., J:, :, :]], axis=-3)


def _fk(c: np.ndarray, k: np.ndarray) -> np.ndarray:
    """F(n) k(n) for c (T, K), k (T, 2K), using the block structure of F."""
    out = np.empty_like(k)
    out[:, 0::2] = k[:, 1::2]
    out[:, 1::2] = -k[:, 0::2] + c * k[:, 1::2]
    return out


def _a_matrices(c: np.ndarray, k: np.ndarray) -> np.ndarray:
    """A(n) = F(n)(I - k(n) h) = F(n) - (F(n) k(n)) h: (T, 2K, 2K)."""
    F = _f_matrices(c)
    F[:, :, 1::2] -= _fk(c, k)[:, :, None]
    return F


_CHUNK = 32       # chunk length of the forward scan (numpy path)
_NO_MISS = -(1 << 62)   # last_miss of a channel that has not missed an input yet
_TABLE_SEG = 64   # the gain table is computed in segments of this many speeds


def _forward_numpy(y, c, k, z0):
    """Filter a block that starts at a chunk boundary: y (T, C), c (T, K), k (T, 2K),
    z0 (C, 2K) the predicted state at its start.

    Returns predicted states (T+1, C, 2K) (the last one after the block),
    innovations (T, C), filtered states (T, C, 2K).
    """
    A = _a_matrices(c, k)
    b = _fk(c, k)[:, :, None] * y[:, None, :]                       # F k y: (T, 2K, C)
    u = _scan(A, b, z0.T, _CHUNK)                                   # (T+1, 2K, C)
    zp = np.ascontiguousarray(np.swapaxes(u, 1, 2))                 # (T+1, C, 2K)
    e = y - zp[:-1, :, 1::2].sum(axis=2)
    xf = zp[:-1] + k[:, None, :] * e[:, :, None]
    return zp, e, xf


def _backward_numpy(c, k, S, P, zp, e, starts, W, nout):
    """MBF fixed-lag smoothing of E windows [s, s+W) (all inside the given arrays).

    Returns smoothed states of the first ``nout`` samples of each window: (E, nout, C, 2K).
    """
    E = len(starts)
    idx = np.asarray(starts)[:, None] + np.arange(W)[None, :]           # (E, W)
    ridx = idx[:, ::-1]                                                 # backwards in time
    A = _a_matrices(c, k)                                               # (T, 2K, 2K)
    At = np.swapaxes(A, 1, 2)[ridx]                                     # (E, W, 2K, 2K)
    d = A.shape[1]
    C = e.shape[1]
    g = np.zeros((e.shape[0], d, C))
    g[:, 1::2, :] = (e / S[:, None])[:, None, :]
    # λ(n) = Aᵀ(n) λ(n+1) + g(n): step t maps λ(end-t) to λ(end-t-1); the first
    # step multiplies λ(end) = 0, so its matrix is irrelevant
    u = _scan(At, g[ridx], np.zeros((E, d, C)))                         # (E, W+1, d, C)
    lam = u[:, ::-1][:, :nout]                                          # λ(s..s+nout-1)
    oidx = idx[:, :nout]
    xs = zp[oidx] + np.swapaxes(P[oidx] @ lam, -1, -2)                  # (E, nout, C, d)
    return xs


def _mask_groups(miss: np.ndarray | None) -> list:
    """Channels that miss the same samples, with that mask: [(channels, mask (T,) or
    None)], channels a slice (all of them, one group) or an index array.

    The numpy recursions share A(n) = F(n)(I - k(n)h) across channels; channels
    that miss different samples need different A (k zeroed where each misses).
    The caller runs the recursion once per group, on ALL channels (keeping the
    group's): the products then have the same shape whatever the grouping, so a
    channel's result depends only on its own mask, bit for bit (a stream split
    elsewhere groups differently; BLAS rounds a product differently when its
    column count changes)."""
    if miss is None or not miss.any():
        return [(slice(None), None)]
    cols: dict[bytes, list[int]] = {}
    for ch in range(miss.shape[1]):
        cols.setdefault(np.ascontiguousarray(miss[:, ch]).tobytes(), []).append(ch)
    if len(cols) == 1:
        return [(slice(None), miss[:, 0])]
    out = []
    for chans in cols.values():
        m = miss[:, chans[0]]
        out.append((np.array(chans), m if m.any() else None))
    return out


def _riccati_numpy(c, qdiag, q2, P, want_p, miss=None):
    """Exact gains per sample (a loop: one set of numpy calls per sample).  At samples
    ``miss`` (T,) (None: none) there is no measurement: k = 0, P(n|n) = P(n|n-1)."""
    T, K = c.shape
    d = 2 * K
    k = np.empty((T, d))
    S = np.empty(T)
    Pout = np.empty((T, d, d)) if want_p else None
    F = _f_matrices(c)
    hi = np.arange(1, d, 2)
    for n in range(T):
        ph = P[:, hi].sum(axis=1)
        s = ph[hi].sum() + q2[n]
        if want_p:
            Pout[n] = P
        S[n] = s
        if miss is not None and miss[n]:
            k[n] = 0.0
            Pf = P
        else:
            kn = ph / s
            k[n] = kn
            Pf = P - np.outer(kn, ph)
        P = F[n] @ Pf @ F[n].T
        P[np.arange(d), np.arange(d)] += qdiag[n]
        P = 0.5 * (P + P.T)
    return k, S, Pout, P


# --------------------------------------------------------------------------
# outputs and state
# --------------------------------------------------------------------------

@dataclass
class BlockStats:
    """Per output block (E blocks): aligned to tracker-sample indices [start, start + B)."""

    start: np.ndarray       # (E,) tracker-sample index of the block's first sample
    t_in: np.ndarray        # (E,) input-sample index the block's LAST sample stands for
    rpm: np.ndarray         # (E,) mean speed over the block (as measured, not clamped)
    rms: np.ndarray         # (E, C, K) RMS of x̂_k over the block; NaN where invalid
    amplitude: np.ndarray   # (E, C, K) mean envelope (peak amplitude); NaN where invalid
    valid: np.ndarray       # (E,) bool: speed >= min_rpm throughout the block
    missing: np.ndarray | None = None   # (E, C) int: the block's samples without a
    #                         measurement (missing input); their estimates are predictions


@dataclass
class TrackerOutput:
    """What one call of :meth:`OrderTracker.process` produced.

    Causal: ``waveform`` (N, C, K) for tracker samples ``index`` (N,) (absolute,
    from the start of the stream), standing for input samples ``t_in``, at
    speed ``rpm``; ``blocks`` the output blocks completed by this call.
    Smoothed (when ``smoother_lag_s`` is set): ``smoothed_index`` /
    ``smoothed_waveform`` / ``smoothed_blocks``, lagging by the smoother's lag.
    ``missing`` (N, C) bool: tracker samples without a measurement (a missing input
    within the anti-alias filter's window, see the module docstring).
    """

    index: np.ndarray
    t_in: np.ndarray
    rpm: np.ndarray
    waveform: np.ndarray
    blocks: BlockStats
    smoothed_index: np.ndarray | None = None
    smoothed_waveform: np.ndarray | None = None
    smoothed_blocks: BlockStats | None = None
    missing: np.ndarray | None = None


@dataclass
class TrackerState:
    """Everything carried between calls (arrays; a leading channel axis where per channel)."""

    n_in: int                  # input samples consumed
    n_track: int               # tracker samples produced
    skip: int                  # input samples until the next one kept by the decimator
    zi: np.ndarray | None      # (sections, 2, C) sosfilt state
    rpm_line: np.ndarray       # (delay_in,) delayed speed samples (oldest first)
    z: np.ndarray              # (C, 2K) predicted state X̂(n|n-1)
    P: np.ndarray              # (2K, 2K) predicted covariance (exact gains)
    z0: np.ndarray | None = None   # numpy path: X̂ at the start of the current chunk
    last_miss: np.ndarray | None = None   # (C,) input index of the last missing input
    chunk: dict = field(default_factory=dict)   # numpy path: inputs of the current chunk so far
    pend: dict = field(default_factory=dict)    # partial causal block, per-sample arrays
    hist: dict = field(default_factory=dict)    # smoother history from the next block to smooth
    next_smooth: int = 0       # index of the next block to smooth

    def copy(self) -> TrackerState:
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                v = v.copy()
            elif isinstance(v, dict):
                v = {k: a.copy() for k, a in v.items()}
            out[f.name] = v
        return TrackerState(**out)


# --------------------------------------------------------------------------
# the tracker
# --------------------------------------------------------------------------

class OrderTracker:
    """Streaming AV2KF order tracker for the channels of one machine (shared speed).

    Parameters
    ----------
    components : the tracked orders / fixed frequencies (K).
    fs_in : input sample rate [Hz] of ``y`` and ``rpm``.
    max_rpm : the highest speed expected; sets the decimation and the gain table.
    n_channels : C, channels of one machine (they share the speed, so the gains).
    q1 : process-noise level of eq. (25) (does not change the estimates).
    decimate : D, or None to choose it (see the module docstring); 1 = none.
    oversample : minimum tracker rate over the highest tracked frequency (auto D).
    min_rpm : below this speed the output is invalid (and the model speed clamped).
    gains : "table" (steady-state, tabulated against speed) or "exact" (Riccati).
    smoother_lag_s : None (causal only) or the fixed lag L [s] of the smoother.
    output_rate_hz : rate of the per-block outputs (block = fs_track/rate samples).
    backend : "auto", "c" or "numpy".
    table_step_rpm : grid step of the gain table (None: about 1 rpm, <= 8192 points).
    horizon_s : horizon of the doubling solver for the table.
    """

    def __init__(self, components: Sequence[TrackedComponent], *, fs_in: float, max_rpm: float,
                 n_channels: int = 1, q1: float = 0.1, decimate: int | None = None,
                 oversample: float = 5.0, min_rpm: float = 300.0, gains: str = "table",
                 smoother_lag_s: float | None = None, output_rate_hz: float = 10.0,
                 backend: str = "auto", table_step_rpm: float | None = None,
                 horizon_s: float = 4.0):
        self.components = tuple(components)
        if not self.components:
            raise ValueError("components: expected at least one")
        names = [c.name for c in self.components]
        if len(set(names)) != len(names):
            raise ValueError(f"components: duplicate names in {names}")
        if not fs_in > 0:
            raise ValueError(f"fs_in: expected > 0, got {fs_in}")
        if not max_rpm > 0:
            raise ValueError(f"max_rpm: expected > 0, got {max_rpm}")
        if not 0 < min_rpm < max_rpm:
            raise ValueError(f"min_rpm: expected in (0, max_rpm = {max_rpm}), got {min_rpm}")
        if int(n_channels) < 1:
            raise ValueError(f"n_channels: expected >= 1, got {n_channels}")
        if gains not in ("table", "exact"):
            raise ValueError(f"gains: expected 'table' or 'exact', got {gains!r}")
        if backend == "auto":
            backend = "c" if _trackerkernel is not None else "numpy"
        if backend not in ("c", "numpy"):
            raise ValueError(f"backend: expected 'auto', 'c' or 'numpy', got {backend!r}")
        if backend == "c" and _trackerkernel is None:
            raise RuntimeError("the compiled tracker kernel is not built; use backend='numpy'")
        self.backend = backend
        self.fs_in = float(fs_in)
        self.max_rpm = float(max_rpm)
        self.min_rpm = float(min_rpm)
        self.C = int(n_channels)
        self.K = len(self.components)
        self.q1 = float(q1)
        self.gains = gains
        self.f_hi = max(float(c.freq(self.max_rpm)) for c in self.components)

        # -- decimation
        if decimate is None:
            dmax = max(1, math.floor(self.fs_in / (oversample * self.f_hi)))
            per_block = self.fs_in / output_rate_hz
            if abs(per_block - round(per_block)) < 1e-9:
                pb = round(per_block)
                decimate = max(q for q in range(1, dmax + 1) if pb % q == 0)
            else:
                decimate = dmax
        self.decimate = int(decimate)
        if self.decimate < 1:
            raise ValueError(f"decimate: expected >= 1, got {decimate}")
        self.fs_track = self.fs_in / self.decimate
        if self.f_hi >= 0.5 * self.fs_track:
            raise ValueError(f"decimate: tracker rate {self.fs_track:g} Hz is not above twice the "
                             f"highest tracked frequency {self.f_hi:g} Hz")
        if self.decimate > 1:
            order, fc = _cheb2ord(self.f_hi, self.fs_track - self.f_hi, 0.001, 80.0, self.fs_in)
            self.sos = _cheby2_sos(order, 80.0, fc, self.fs_in)
            gd = _sos_dc_delay(self.sos)
            self.filter_delay_s = gd / self.fs_in
            self.delay_in = round(gd)
            self.cutoff_hz = float(fc)             # the stop-band edge of cheby2
        else:
            self.sos = None
            self.filter_delay_s = 0.0
            self.delay_in = 0
            self.cutoff_hz = None
        # a missing input spoils this many filter outputs (its own included): tracker
        # samples within them get no measurement update (module docstring)
        self.missing_window = _missing_window(self.sos)

        # -- output blocks and smoother
        self.block = max(1, round(self.fs_track / output_rate_hz))
        self.output_rate_hz = self.fs_track / self.block
        if smoother_lag_s is not None and smoother_lag_s < 0:
            raise ValueError(f"smoother_lag_s: expected None or >= 0, got {smoother_lag_s}")
        self.lag = None if smoother_lag_s is None else round(smoother_lag_s * self.fs_track)
        self.latency_s = (self.filter_delay_s + (self.lag or 0) / self.fs_track
                          + self.block / self.fs_track)

        # -- gain table
        self.horizon_s = float(horizon_s)
        self._n_double = max(1, math.ceil(math.log2(max(2.0, horizon_s * self.fs_track))))
        if gains == "table":
            top = 1.1 * self.max_rpm
            if table_step_rpm is None:
                table_step_rpm = max(1.0, (top - self.min_rpm) / 8191)
            n = math.ceil((top - self.min_rpm) / table_step_rpm) + 1
            self._grid0 = self.min_rpm
            self._grid_step = (top - self.min_rpm) / (n - 1)
            # filled in segments of _TABLE_SEG speeds when first needed (see _fill_table);
            # np.zeros: pages never touched cost no memory
            # r on the bandwidth grid over the table's speeds, in one batch (the table
            # segments, filled as the speed goes, then find it there)
            component_r(self.components, np.array([self.min_rpm, top]), self.fs_track)
            d = 2 * self.K
            self._tab_n = n
            self._tab_have = np.zeros(-(-n // _TABLE_SEG), dtype=bool)
            self._kS = np.zeros((n, d + 1))
            self._dkS = np.zeros((n - 1, d + 1))
            self._P = np.zeros((n, d, d))
            self._dP = np.zeros((n - 1, d, d))
        self.state = self.initial_state()

    # ------------------------------------------------------------------ setup
    def _coeffs(self, speed: np.ndarray):
        """c_k(n) (T, K), Q1 diagonal (T, 2K) and Q2 (T,) at model speeds."""
        c = 2.0 * np.cos(_omega(self.components, speed) / self.fs_track)
        rk = component_r(self.components, speed, self.fs_track)
        qd, q2 = _q_diag(rk, self.q1)
        return c, qd, q2

    def _steady_state(self, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Steady-state [k | S] (G, 2K+1) and P(n|n-1) (G, 2K, 2K) at the grid speeds."""
        ks, Ps = [], []
        for i in range(0, len(grid), 1024):
            c, qd, q2 = self._coeffs(grid[i:i + 1024])
            P = _riccati_doubling(c, qd, q2, self._n_double)
            ph = P[:, :, 1::2].sum(axis=2)
            S = ph[:, 1::2].sum(axis=1) + q2
            ks.append(np.concatenate([ph / S[:, None], S[:, None]], axis=1))
            Ps.append(P)
        return np.concatenate(ks), np.concatenate(Ps)

    def _fill_table(self, i: np.ndarray) -> None:
        """Compute the gain-table segments that hold grid points i or i + 1 and are
        not there yet (each point is the same whenever it is computed)."""
        seg = _TABLE_SEG
        need = np.zeros_like(self._tab_have)
        need[i // seg] = True
        need[(i + 1) // seg] = True
        miss = np.flatnonzero(need & ~self._tab_have)
        if not miss.size:
            return
        n = self._tab_n
        pts = np.concatenate([np.arange(m * seg, min((m + 1) * seg, n)) for m in miss])
        grid = self._grid0 + self._grid_step * pts
        self._kS[pts], self._P[pts] = self._steady_state(grid)
        self._tab_have[miss] = True
        # differences to the next point, where both ends are there now
        j = np.unique(np.concatenate([pts - 1, pts]))
        j = j[(j >= 0) & (j < n - 1)]
        j = j[self._tab_have[j // seg] & self._tab_have[(j + 1) // seg]]
        self._dkS[j] = self._kS[j + 1] - self._kS[j]
        self._dP[j] = self._P[j + 1] - self._P[j]

    def initial_state(self) -> TrackerState:
        d = 2 * self.K
        _, _, q2 = self._coeffs(np.array([self.min_rpm]))
        zi = None
        if self.sos is not None:
            zi = np.zeros((self.sos.shape[0], 2, self.C))
        return TrackerState(n_in=0, n_track=0, skip=0, zi=zi,
                            rpm_line=np.full(self.delay_in, np.nan),
                            z=np.zeros((self.C, d)), P=q2[0] * np.eye(d),
                            z0=np.zeros((self.C, d)),
                            last_miss=np.full(self.C, _NO_MISS, dtype=np.int64))

    def reset(self) -> None:
        self.state = self.initial_state()

    def describe(self, rpm: float) -> list[dict]:
        """Per component at speed ``rpm``: frequency, r, -3 dB bandwidth [Hz and %],
        time constant [s] (of the isolated steady-state filter at the tracker rate)."""
        speed = _model_speed(np.array([rpm]), self.min_rpm)
        rk = component_r(self.components, speed, self.fs_track)[0]
        out = []
        for c, r in zip(self.components, rk):
            f = float(c.freq(speed)[0])
            bw = float(r_to_bandwidth(r, f, self.fs_track))
            out.append({"name": c.name, "freq_hz": f, "r": float(r), "bandwidth_hz": bw,
                        "bandwidth_pct": 100.0 * bw / f,
                        "time_constant_s": float(time_constant(r, f, self.fs_track))})
        return out

    # ---------------------------------------------------------------- process
    def process(self, y, rpm) -> TrackerOutput:
        """Track a block: y (T, C) (or (T,) for one channel) at fs_in, rpm (T,) at fs_in.

        NaN in y is a missing sample of that channel (a lost frame, a gap): see
        "Missing samples" in the module docstring.  With ``gains="exact"`` the
        channels must miss the same samples (ValueError otherwise, before any
        state changes): the exact Riccati recursion is shared by the channels."""
        y = np.asarray(y, dtype=np.float64)
        if y.ndim == 1 and self.C == 1:
            y = y[:, None]
        if y.ndim != 2 or y.shape[1] != self.C:
            raise ValueError(f"y: expected shape (T, {self.C}), got {y.shape}")
        rpm = np.asarray(rpm, dtype=np.float64)
        if rpm.shape != (y.shape[0],):
            raise ValueError(f"rpm: expected shape ({y.shape[0]},), got {rpm.shape}")
        st = self.state
        gone_in = None
        if y.size and np.isnan(y.min()):               # min() propagates NaN; cheaper than isnan
            gone_in = np.isnan(y)
        miss, last_miss = self._missing(gone_in, y.shape[0])
        if (miss is not None and self.gains == "exact" and self.C > 1
                and (miss != miss[:, :1]).any()):
            raise ValueError("gains='exact': the channels must miss the same samples (the exact "
                             "Riccati recursion is shared by the channels); got NaN in some "
                             "channels only: use gains='table' or one tracker per channel")
        if gone_in is not None:
            y = np.where(gone_in, 0.0, y)                # the anti-alias filter takes zeros
        yd, rd = self._decimate(y, rpm)
        st.last_miss = last_miss
        n0 = st.n_track
        N = yd.shape[0]
        index = n0 + np.arange(N)
        t_in = index * self.decimate - self.delay_in
        xf, zp, e, c, k, S, P = self._filter(yd, rd, miss)
        wave = np.ascontiguousarray(xf[:, :, 1::2])
        env = _envelope(xf, c)
        blocks = self._causal_blocks(n0, wave, env, rd, miss)
        out = TrackerOutput(index=index, t_in=t_in, rpm=rd, waveform=wave, blocks=blocks,
                            missing=miss if miss is not None else np.zeros((N, self.C), dtype=bool))
        if self.lag is not None:
            self._smooth(out, n0, rd, c, k, S, P, zp, e, miss)
        st.n_track = n0 + N
        return out

    def _missing(self, gone_in, T):
        """Tracker samples of this call without a measurement, (N, C) bool or None (none),
        and the new ``last_miss``: tracker sample j (input jD, filtered) is missing when
        an input in (jD - W, jD] is, W = ``missing_window`` (the state carries the last
        missing input per channel across calls).  Changes no state.  (None, not an
        array of False, is what the rest passes on when nothing is missing: no
        per-call cost on the common path.)"""
        st = self.state
        W = self.missing_window
        n0 = st.n_in
        last = st.last_miss
        first = st.skip if self.sos is not None else 0
        if gone_in is None and n0 + first - int(last.max()) >= W:
            return None, last                       # the common case: nothing missing near
        take = np.arange(first, T, self.decimate)
        pos = n0 + take
        if gone_in is None:
            m = (pos[:, None] - last[None, :]) < W
            return (m if m.any() else None), last
        idx = np.where(gone_in, (n0 + np.arange(T))[:, None], _NO_MISS)
        lm = np.maximum(np.maximum.accumulate(idx, axis=0), last[None, :])
        m = (pos[:, None] - lm[take]) < W
        return (m if m.any() else None), lm[-1].copy()

    def _decimate(self, y, rpm):
        st = self.state
        if self.sos is None:
            st.n_in += y.shape[0]
            return y, rpm
        if y.shape[0] == 0:
            return y, rpm
        take = np.arange(st.skip, y.shape[0], self.decimate)
        if self.backend == "c":           # filter and keep every D-th sample in one pass
            yd = np.empty((len(take), self.C))
            _trackerkernel.sosfilt(self.sos, np.ascontiguousarray(y), st.zi, yd, st.skip,
                                   self.decimate)
        else:                             # the numpy path: scipy, imported only here
            from scipy.signal import sosfilt
            yf, st.zi = sosfilt(self.sos, y, axis=0, zi=st.zi)
            yd = np.ascontiguousarray(yf[take])
        if self.delay_in:
            if st.n_in == 0 and rpm.size:        # the line starts filled with the first speed
                st.rpm_line[:] = rpm[0]
            line = np.concatenate([st.rpm_line, rpm])
            st.rpm_line = line[len(line) - self.delay_in:].copy()
            rdel = line[:len(rpm)]
        else:
            rdel = rpm
        st.skip = int((st.skip - y.shape[0]) % self.decimate)
        st.n_in += y.shape[0]
        return yd, rdel[take]

    def _gains(self, speed, c, gone=None):
        """k (N, 2K), S (N,), P (N, 2K, 2K) or None.  ``gone`` (N,) bool or None: samples
        without a measurement, for the exact gains (k = 0 and no update of P there);
        the table's steady-state gains do not depend on it (the forward and backward
        passes zero k per channel)."""
        want_p = self.lag is not None
        if self.gains == "table":           # linear interpolation in the speed
            x = (np.clip(speed, self._grid0, None) - self._grid0) / self._grid_step
            n = self._tab_n
            i = np.minimum(x.astype(np.int64), n - 2)
            f = np.clip(x - i, 0.0, 1.0)
            if i.size:
                self._fill_table(i)
            kS = self._kS[i] + self._dkS[i] * f[:, None]
            P = None
            if want_p:
                P = self._P[i] + self._dP[i] * f[:, None, None]
            return np.ascontiguousarray(kS[:, :-1]), kS[:, -1].copy(), P
        _, qd, q2 = self._coeffs(speed)
        st = self.state
        if self.backend == "c":
            N, d = c.shape[0], 2 * self.K
            k, S = np.empty((N, d)), np.empty(N)
            P = np.empty((N, d, d)) if want_p else np.empty((0,))
            args = (np.ascontiguousarray(c), np.ascontiguousarray(qd), np.ascontiguousarray(q2),
                    st.P, k, S, P, int(want_p))
            if gone is not None:
                args += (np.ascontiguousarray(gone).view(np.uint8),)
            _trackerkernel.riccati(*args)
            return k, S, (P if want_p else None)
        k, S, P, st.P = _riccati_numpy(c, qd, q2, st.P, want_p, gone)
        return k, S, P

    def _filter(self, yd, rd, miss):
        """miss: (N, C) bool with a True somewhere, or None."""
        st = self.state
        N, d = yd.shape[0], 2 * self.K
        speed = _model_speed(rd, self.min_rpm)
        c = 2.0 * np.cos(_omega(self.components, speed) / self.fs_track)
        any_miss = miss is not None
        k, S, P = self._gains(speed, c, miss[:, 0] if any_miss and self.gains == "exact" else None)
        if N == 0:
            return (np.zeros((0, self.C, d)), np.zeros((0, self.C, d)), np.zeros((0, self.C)),
                    c, k, S, P)
        if self.backend == "c":
            zp, e, xf = np.empty((N, self.C, d)), np.empty((N, self.C)), np.empty((N, self.C, d))
            args = (np.ascontiguousarray(yd), np.ascontiguousarray(c), np.ascontiguousarray(k),
                    st.z, zp, e, xf, self.K)
            if any_miss:
                args += (np.ascontiguousarray(miss).view(np.uint8),)
            _trackerkernel.forward(*args)
            return xf, zp, e, c, k, S, P
        # numpy: chunks of _CHUNK samples aligned to absolute tracker indices.  The
        # chunk cut by the end of the previous call is run again from its start
        # (its inputs are kept in the state), so that every sample is computed
        # exactly as in one pass, however the stream is split.
        # Channels that miss different samples run as separate groups (_mask_groups),
        # each with k = 0 at its missing samples and no innovation there (e = 0).
        ch = st.chunk
        p = len(ch["y"]) if ch else 0
        Y = np.concatenate([ch["y"], yd]) if p else yd
        Cc = np.concatenate([ch["c"], c]) if p else c
        Kk = np.concatenate([ch["k"], k]) if p else k
        Mm = _cat_miss(ch.get("m") if p else None, p, miss, N, self.C)
        T = len(Y)
        zp = np.empty((T + 1, self.C, d))
        e = np.empty((T, self.C))
        xf = np.empty((T, self.C, d))
        for chans, m in _mask_groups(Mm):           # all channels each time, see there
            kg = Kk if m is None else np.where(m[:, None], 0.0, Kk)
            z0 = st.z0
            for i in range(0, T, 8192):  # bounded memory for long calls (8192 = 256 chunks)
                j = min(i + 8192, T)
                zp_i, e_i, xf_i = _forward_numpy(Y[i:j], Cc[i:j], kg[i:j], z0)
                if m is not None:
                    e_i[m[i:j]] = 0.0                 # no innovation where missing
                zp[i:j + 1, chans] = zp_i[:, chans]
                e[i:j, chans] = e_i[:, chans]
                xf[i:j, chans] = xf_i[:, chans]
                z0 = zp_i[-1]
        nb = (T // _CHUNK) * _CHUNK                   # last chunk boundary
        tail = T - nb
        st.z0 = np.ascontiguousarray(zp[T - tail])
        st.z = np.ascontiguousarray(zp[T])
        st.chunk = {"y": Y[nb:].copy(), "c": Cc[nb:].copy(), "k": Kk[nb:].copy()} if tail else {}
        if tail and Mm is not None and Mm[nb:].any():
            st.chunk["m"] = Mm[nb:].copy()
        return xf[p:], zp[p:T], e[p:], c, k, S, P

    # ----------------------------------------------------------------- blocks
    def _block_stats(self, starts, wave, env, rpm, miss) -> BlockStats:
        """Statistics of whole blocks: wave/env (E, B, C, K), rpm (E, B), miss (E, B, C)
        or None (none missing)."""
        rms = np.sqrt(np.mean(wave * wave, axis=1))
        amp = np.mean(env, axis=1)
        rmean = np.mean(rpm, axis=1)
        speed_ok = np.all(np.abs(rpm) >= self.min_rpm, axis=1)          # NaN -> False
        f_hi = np.max(np.abs(rpm), axis=1) / 60.0 * max((c.order or 0.0) for c in self.components)
        valid = speed_ok & (f_hi < 0.5 * self.fs_track)
        rms[~valid] = np.nan
        amp[~valid] = np.nan
        starts = np.asarray(starts, dtype=np.int64)
        t_in = (starts + self.block - 1) * self.decimate - self.delay_in
        if miss is None:
            missing = np.zeros((len(starts), self.C), dtype=np.int64)
        else:
            missing = np.count_nonzero(miss, axis=1).astype(np.int64)
        return BlockStats(start=starts, t_in=t_in, rpm=rmean, rms=rms, amplitude=amp, valid=valid,
                          missing=missing)

    def _causal_blocks(self, n0, wave, env, rd, miss) -> BlockStats:
        st = self.state
        B = self.block
        cur = _with_carry(st.pend, {"wave": wave, "env": env, "rpm": rd}, miss, self.C)
        first = n0 - (len(cur["rpm"]) - len(rd))          # index of cur[0], a block start
        nb = len(cur["rpm"]) // B
        used = nb * B
        st.pend = {k: v[used:].copy() for k, v in cur.items()}
        if "miss" in st.pend and not st.pend["miss"].any():
            del st.pend["miss"]
        C, K = self.C, self.K
        return self._block_stats(first + B * np.arange(nb),
                                 cur["wave"][:used].reshape(nb, B, C, K),
                                 cur["env"][:used].reshape(nb, B, C, K),
                                 cur["rpm"][:used].reshape(nb, B),
                                 _miss_blocks(cur.get("miss"), used, nb, B))

    # --------------------------------------------------------------- smoother
    def _smooth(self, out: TrackerOutput, n0, rd, c, k, S, P, zp, e, miss) -> None:
        st = self.state
        B, L = self.block, self.lag
        cur = _with_carry(st.hist, {"rpm": rd, "c": c, "k": k, "S": S, "P": P, "zp": zp, "e": e},
                          miss, self.C)
        h0 = st.next_smooth * B                              # index of cur[0]
        n_end = n0 + len(rd)
        jb = st.next_smooth
        n_emit = max(0, (n_end - L) // B - jb)
        W = B + L
        d = 2 * self.K
        if n_emit:
            starts = (np.arange(n_emit) * B).tolist()        # positions in cur
            if self.backend == "c":
                xs = np.empty((n_emit, B, self.C, d))
                some = "miss" in cur
                for i, s0 in enumerate(starts):
                    sl = slice(s0, s0 + W)
                    args = (np.ascontiguousarray(cur["c"][sl]), np.ascontiguousarray(cur["k"][sl]),
                            np.ascontiguousarray(cur["S"][sl]), np.ascontiguousarray(cur["P"][sl]),
                            np.ascontiguousarray(cur["zp"][sl]), np.ascontiguousarray(cur["e"][sl]),
                            xs[i], self.K)
                    if some and cur["miss"][sl].any():
                        args += (np.ascontiguousarray(cur["miss"][sl]).view(np.uint8),)
                    _trackerkernel.backward(*args)
            else:                     # per mask pattern, as in _filter: k = 0 where missing
                xs = None
                for chans, m in _mask_groups(cur.get("miss")):
                    kg = cur["k"] if m is None else np.where(m[:, None], 0.0, cur["k"])
                    res = _backward_numpy(cur["c"], kg, cur["S"], cur["P"], cur["zp"], cur["e"],
                                          starts, W, B)
                    if xs is None:
                        xs = res
                    else:
                        xs[:, :, chans] = res[:, :, chans]
            used = n_emit * B
            cb = cur["c"][:used].reshape(n_emit, B, self.K)
            wave = xs[..., 1::2]
            env = _envelope(xs.reshape(used, self.C, d), cb.reshape(used, self.K)).reshape(
                n_emit, B, self.C, self.K)
            out.smoothed_index = h0 + np.arange(used)
            out.smoothed_waveform = np.ascontiguousarray(wave.reshape(used, self.C, self.K))
            out.smoothed_blocks = self._block_stats(h0 + B * np.arange(n_emit), wave, env,
                                                    cur["rpm"][:used].reshape(n_emit, B),
                                                    _miss_blocks(cur.get("miss"), used, n_emit, B))
        else:
            used = 0
            out.smoothed_index = np.zeros(0, dtype=np.int64)
            out.smoothed_waveform = np.zeros((0, self.C, self.K))
            out.smoothed_blocks = self._block_stats(np.zeros(0, np.int64),
                                                    np.zeros((0, B, self.C, self.K)),
                                                    np.zeros((0, B, self.C, self.K)),
                                                    np.zeros((0, B)), None)
        st.next_smooth = jb + n_emit
        st.hist = {key: v[used:].copy() for key, v in cur.items()}
        if "miss" in st.hist and not st.hist["miss"].any():
            del st.hist["miss"]


def _cat_miss(before, n_before, now, n_now, C):
    """Missing-sample masks of kept samples (``before``, n_before rows) and new ones
    (``now``), either None for none missing: the concatenation, or None."""
    if before is None and now is None:
        return None
    return np.concatenate([before if before is not None else np.zeros((n_before, C), dtype=bool),
                           now if now is not None else np.zeros((n_now, C), dtype=bool)])


def _with_carry(carry, cur, miss, C):
    """The arrays kept from the last call (``carry``: a dict with "rpm", maybe "miss", or
    empty) followed by this call's (``cur``); "miss" only when a sample is missing."""
    p = len(carry["rpm"]) if carry else 0
    if p:
        cur = {k: np.concatenate([carry[k], v]) for k, v in cur.items()}
    m = _cat_miss(carry.get("miss") if p else None, p, miss, len(cur["rpm"]) - p, C)
    if m is not None:
        cur["miss"] = m
    return cur


def _miss_blocks(miss, used, nb, B):
    """The first ``used`` rows of a mask (or None) as (nb, B, C) blocks (or None)."""
    return None if miss is None else miss[:used].reshape(nb, B, miss.shape[1])


def _envelope(xs: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Peak amplitude from the state pairs: xs (N, C, 2K), c (N, K) -> (N, C, K)."""
    x1, x2 = xs[..., 0::2], xs[..., 1::2]
    cc = c[:, None, :]
    s2 = np.maximum(1.0 - 0.25 * cc * cc, 1e-300)
    a2 = (x1 * x1 - cc * x1 * x2 + x2 * x2) / s2
    return np.sqrt(np.maximum(a2, 0.0))


# --------------------------------------------------------------------------
# alarms on the per-block RMS
# --------------------------------------------------------------------------

@dataclass(frozen=True)
class AlarmEvent:
    kind: str          # "onset" or "clear"
    component: str
    channel: int
    block_start: int   # tracker-sample index of the block that changed the state
    rpm: float
    rms: float
    level: float


class OrderAlarm:
    """RMS level alarm per (channel, component) with hysteresis.

    ``levels``: {component name: RMS level}.  An alarm sets when a valid block's
    RMS reaches the level and clears when it falls below level x (1 - hysteresis).
    Invalid blocks (speed gate) change nothing.  :meth:`update` returns the
    transitions, with the block's speed.
    """

    def __init__(self, components: Sequence[TrackedComponent], levels: dict[str, float], *,
                 n_channels: int = 1, hysteresis: float = 0.2):
        names = [c.name for c in components]
        unknown = sorted(set(levels) - set(names))
        if unknown:
            raise ValueError(f"levels: unknown components {unknown}; tracked: {names}")
        if not 0 <= hysteresis < 1:
            raise ValueError(f"hysteresis: expected in [0, 1), got {hysteresis}")
        self.names = names
        self.levels = {n: float(v) for n, v in levels.items()}
        self.hysteresis = float(hysteresis)
        self.active = np.zeros((int(n_channels), len(names)), dtype=bool)

    def update(self, blocks: BlockStats) -> list[AlarmEvent]:
        events = []
        for e in range(len(blocks.start)):
            if not blocks.valid[e]:
                continue
            for k, name in enumerate(self.names):
                if name not in self.levels:
                    continue
                lev = self.levels[name]
                for ch in range(self.active.shape[0]):
                    v = float(blocks.rms[e, ch, k])
                    if not self.active[ch, k] and v >= lev:
                        self.active[ch, k] = True
                        events.append(AlarmEvent("onset", name, ch, int(blocks.start[e]),
                                                 float(blocks.rpm[e]), v, lev))
                    elif self.active[ch, k] and v < lev * (1.0 - self.hysteresis):
                        self.active[ch, k] = False
                        events.append(AlarmEvent("clear", name, ch, int(blocks.start[e]),
                                                 float(blocks.rpm[e]), v, lev))
        return events
