"""Banks of adaptive Kalman filters (AKF) on a scalar observation stream.

Implements Kim et al. 2023 (Kim, Song, Kim, Lee, "An Adaptive Kalman Filter-Based
Condition-Monitoring Technique for Induction Motors", IEEE Access 2023),
section III.A-B, equations (1)-(15), for many channels and many filters at once.

Model (random walk, eqs. 1-2)::

    x(k+1) = x(k) + w(k),   w ~ N(0, Q(k))
    y(k)   = x(k) + v(k),   v ~ N(0, R(k))

One step of the AKF (Fig. 2), for every filter of the bank:

    time update        x̂⁻(k) = x̂(k-1)                              (3)
                        P⁻(k) = P(k-1) + Q̂(k-1)                     (4)
    measurement update  ỹ(k) = y(k) - x̂⁻(k)                          (5)
                        Y(k)  = P⁻(k) + R                            (6)
                        K(k)  = P⁻(k) / Y(k)                         (7)
                        x̂(k)  = x̂⁻(k) + K(k) ỹ(k)                    (8)
                        P(k)  = (1 - K(k)) P⁻(k)                     (9)
    adaptation          Q̂(k)  = S(k) M(k)                            (10)
                        M(k)  = 1/N Σ_{j=k-N+1..k} (y(j) - x̂(j))²    (11)
                        S(k)  = max(1, Ĝ(k) / G̃(k))                  (12)
                        G̃(k)  = K(k)² Y(k)                           (13)
                        Ĝ(k)  = 1/N Σ_{j=k-N+1..k} Δx̂(j)²,  Δx̂ = x̂ - x̂⁻   (14)
    outlier test        z(k)  = Δx̂(k)/sqrt(G̃(k)) = ỹ(k)/sqrt(Y(k))  (15)
                        outlier if |z(k)| > z_c

The adaptive bounds reported beside the estimate are those of section III.B in
terms of the observation: x̂⁻(k) ± z_c sqrt(Y(k)); y(k) lies outside them
exactly when it is an outlier.

Choices the paper leaves open (documented here, configurable in MonitorConfig):

* Window before it is full: for k < N the sums of (11) and (14) run over the k
  samples that exist and are divided by k (not N), so the first estimates are
  not biased towards zero.
* Initial state: x̂(0) is the first observation, P(0) = p0, Q̂(0) = q0, empty
  windows.  The first decision period is a transient (Fig. 5 of the paper).
* A missing observation (lost frame) is a time update without a measurement:
  x̂(k) = x̂⁻(k), P(k) = P⁻(k); Q̂ and the windows are left as they are, no z,
  no outlier.  Never a zero observation.

Three implementations with identical semantics:

* :class:`ScalarAKF` — one filter, plain Python floats, the equations one to one.
  The reference the others are tested against (to 1e-12).
* :func:`_run_numpy` — the bank vectorised over (channels, filters), looping over
  time in Python; the fallback when the compiled kernel is unavailable.
* ``cmsensord.dsp._akfkernel`` — the same loop in C (built by ``pip install``);
  about 100x faster than the numpy loop, which matters at 1000x real time.  It runs a
  channel's filters two at a time in SSE2 registers where there are (the same IEEE
  operations in the same order per filter: the same bits), and its ``flags`` entry writes
  only the outlier flags (:meth:`AkfBank.outliers`, what a decision needs).

State lives in arrays with leading (channel, filter) axes (:class:`AkfState`)
and is carried between calls, so a stream can be split anywhere.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

try:  # the compiled kernel is optional: the numpy loop is the fallback
    from cmsensord.dsp import _akfkernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _akfkernel = None
#: the kernel's flags-only entry (None: no kernel, or one built before it had it: process() serves)
_flags = getattr(_akfkernel, "flags", None)

__all__ = [
    "ScalarAKF",
    "AkfBank",
    "AkfState",
    "AkfBlock",
    "bank_r",
    "have_kernel",
]


def bank_r(r_min: float, r_max: float, n: int) -> np.ndarray:
    """Measurement-noise variances of a bank of n AKFs, eq. (16).

    R_i = R_min + i (R_max - R_min) / n for i = 1..n, so R_n = R_max and the
    most sensitive filter, AKF_1, has R_1 = R_min + (R_max - R_min)/n.
    """
    i = np.arange(1, n + 1, dtype=np.float64)
    return r_min + i * (r_max - r_min) / n


def have_kernel() -> bool:
    """True when the compiled kernel is importable."""
    return _akfkernel is not None


class ScalarAKF:
    """One AKF, plain Python: the reference implementation of eqs. (3)-(15).

    ``step(y)`` processes one observation (``None`` for a missing one) and
    returns a dict with the intermediate quantities.
    """

    def __init__(self, R: float, *, window: int = 10, z_c: float = 2.8,
                 p0: float = 1.0, q0: float = 1e-3, scaling: bool = True):
        self.R = float(R)
        self.N = int(window)
        self.z_c = float(z_c)
        self.scaling = scaling
        self.x: float | None = None   # x̂(k-1); None until the first observation
        self.P = float(p0)            # P(k-1)
        self.Q = float(q0)            # Q̂(k-1)
        self.res2: deque[float] = deque(maxlen=self.N)  # (y - x̂)² window, eq. (11)
        self.dx2: deque[float] = deque(maxlen=self.N)   # Δx̂² window, eq. (14)

    def step(self, y: float | None) -> dict:
        if self.x is None:
            if y is None:
                return {"missing": True, "x_prior": math.nan, "x_hat": math.nan,
                        "Y": math.nan, "z": math.nan, "outlier": False, "Q": math.nan}
            self.x = float(y)                 # x̂(0): the first observation
        x_prior = self.x                      # (3)
        P_prior = self.P + self.Q             # (4)
        Y = P_prior + self.R                  # (6)
        if y is None:                         # time update only
            self.P = P_prior
            return {"missing": True, "x_prior": x_prior, "x_hat": x_prior,
                    "Y": Y, "z": math.nan, "outlier": False, "Q": self.Q}
        innov = y - x_prior                   # (5)
        K = P_prior / Y                       # (7)
        dx = K * innov
        x = x_prior + dx                      # (8)
        self.P = (1.0 - K) * P_prior          # (9)
        self.x = x
        self.res2.append((y - x) ** 2)
        self.dx2.append(dx * dx)
        M = sum(self.res2) / len(self.res2)   # (11)
        G_hat = sum(self.dx2) / len(self.dx2)  # (14)
        G_tilde = K * K * Y                   # (13)
        S = max(1.0, G_hat / G_tilde) if self.scaling else 1.0   # (12)
        self.Q = S * M                        # (10)
        z = innov / math.sqrt(Y)              # (15)
        return {"missing": False, "x_prior": x_prior, "x_hat": x, "Y": Y,
                "z": z, "outlier": abs(z) > self.z_c, "S": S, "M": M, "Q": self.Q}


@dataclass
class AkfState:
    """State of a bank over C channels x n filters (arrays carried between calls)."""

    x: np.ndarray      # (C, n) x̂(k-1)
    P: np.ndarray      # (C, n) P(k-1)
    Q: np.ndarray      # (C, n) Q̂(k-1)
    res2: np.ndarray   # (C, n, Nmax) ring buffer of (y - x̂)²
    dx2: np.ndarray    # (C, n, Nmax) ring buffer of Δx̂²
    pos: np.ndarray    # (C,) int64 next ring slot
    fill: np.ndarray   # (C,) int64 samples in the window (<= N)
    started: np.ndarray  # (C,) uint8: x̂(0) set from a first observation

    def copy(self) -> AkfState:
        return AkfState(**{k: v.copy() for k, v in self.__dict__.items()})


@dataclass
class AkfBlock:
    """Per-observation outputs of a block of T observations, shape (T, C, n)."""

    x_prior: np.ndarray
    x_hat: np.ndarray
    Y: np.ndarray
    Q: np.ndarray         # Q̂(k) after the step (eq. 10), used by the next time update
    outlier: np.ndarray   # uint8
    valid: np.ndarray     # (T, C) bool, False for a missing observation

    def z(self, y: np.ndarray) -> np.ndarray:
        """Normalised innovation of eq. (15); NaN where the observation is missing."""
        with np.errstate(invalid="ignore"):
            z = (np.asarray(y, np.float64)[:, :, None] - self.x_prior) / np.sqrt(self.Y)
        z[~self.valid] = np.nan
        return z


class AkfBank:
    """A bank of AKFs per channel, vectorised over (channel, filter).

    Parameters are per channel (arrays of length C) so channels may be
    configured differently; ``R`` has shape (C, n).
    """

    def __init__(self, R: np.ndarray, *, window, z_c, p0=1.0, q0=1e-3,
                 scaling: bool = True, backend: str = "auto"):
        R = np.atleast_2d(np.asarray(R, dtype=np.float64))
        if R.ndim != 2:
            raise ValueError(f"R: expected shape (channels, filters), got {R.shape}")
        C, n = R.shape
        self.R = np.ascontiguousarray(R)
        self.C, self.n = C, n
        self.N = np.broadcast_to(np.asarray(window, dtype=np.int64), (C,)).copy()
        if np.any(self.N < 1):
            raise ValueError(f"window: expected >= 1, got {self.N.tolist()}")
        self.z_c = np.broadcast_to(np.asarray(z_c, dtype=np.float64), (C,)).copy()
        self.p0 = np.broadcast_to(np.asarray(p0, dtype=np.float64), (C,)).copy()
        self.q0 = np.broadcast_to(np.asarray(q0, dtype=np.float64), (C,)).copy()
        self.scaling = bool(scaling)
        if backend == "auto":
            backend = "c" if _akfkernel is not None else "numpy"
        if backend == "c" and _akfkernel is None:
            raise RuntimeError("the compiled AKF kernel is not built; use backend='numpy'")
        if backend not in ("c", "numpy"):
            raise ValueError(f"backend: expected 'auto', 'c' or 'numpy', got {backend!r}")
        self.backend = backend
        self.state = self.initial_state()

    def initial_state(self) -> AkfState:
        C, n, Nmax = self.C, self.n, int(self.N.max())
        return AkfState(
            x=np.zeros((C, n)),
            P=np.repeat(self.p0[:, None], n, axis=1),
            Q=np.repeat(self.q0[:, None], n, axis=1),
            res2=np.zeros((C, n, Nmax)),
            dx2=np.zeros((C, n, Nmax)),
            pos=np.zeros(C, dtype=np.int64),
            fill=np.zeros(C, dtype=np.int64),
            started=np.zeros(C, dtype=np.uint8),
        )

    def _inputs(self, y: np.ndarray, valid: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Observations (T, C) with 0.0 where missing, C-contiguous, and the valid mask (T, C)
        (``valid`` and finite); ValueError for a shape that is not the bank's."""
        y = np.asarray(y, dtype=np.float64)
        if y.ndim == 1 and self.C == 1:
            y = y[:, None]
        if y.ndim != 2 or y.shape[1] != self.C:
            raise ValueError(f"y: expected shape (T, {self.C}), got {y.shape}")
        finite = np.isfinite(y)
        if valid is None:
            valid = finite
        else:
            valid = np.asarray(valid, dtype=bool)
            if valid.shape != y.shape:
                raise ValueError(f"valid: expected shape {y.shape}, got {valid.shape}")
            valid = valid & finite
        return np.ascontiguousarray(np.where(valid, y, 0.0)), valid

    def process(self, y: np.ndarray, valid: np.ndarray | None = None) -> AkfBlock:
        """Run T observations of every channel through the bank.

        y: (T, C) observations; valid: (T, C) bool, False marks a missing
        observation (its y value is ignored).  NaN in y is treated as missing.
        """
        y, valid = self._inputs(y, valid)
        T = y.shape[0]
        out = AkfBlock(
            x_prior=np.empty((T, self.C, self.n)),
            x_hat=np.empty((T, self.C, self.n)),
            Y=np.empty((T, self.C, self.n)),
            Q=np.empty((T, self.C, self.n)),
            outlier=np.zeros((T, self.C, self.n), dtype=np.uint8),
            valid=valid,
        )
        if T == 0:
            return out
        if self.backend == "c":
            s = self.state
            _akfkernel.run(
                y, np.ascontiguousarray(valid, dtype=np.uint8), self.R, self.z_c, self.N,
                int(self.scaling), s.x, s.P, s.Q, s.res2, s.dx2, s.pos, s.fill, s.started,
                out.x_prior, out.x_hat, out.Y, out.Q, out.outlier,
            )
        else:
            _run_numpy(self, y, valid, out)
        return out

    def outliers(self, y: np.ndarray, valid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The outlier flags (T, C, n) uint8 and the valid mask (T, C) that :meth:`process`
        gives for the same input, with the same change of state, without its other outputs
        (the compiled kernel then writes only the flags: what a decision needs)."""
        if self.backend != "c" or _flags is None:
            out = self.process(y, valid)
            return out.outlier, out.valid
        y, valid = self._inputs(y, valid)
        T = y.shape[0]
        outlier = np.zeros((T, self.C, self.n), dtype=np.uint8)
        if T:
            s = self.state
            _flags(
                y, np.ascontiguousarray(valid, dtype=np.uint8), self.R, self.z_c, self.N,
                int(self.scaling), s.x, s.P, s.Q, s.res2, s.dx2, s.pos, s.fill, s.started, outlier,
            )
        return outlier, valid


def _run_numpy(bank: AkfBank, y: np.ndarray, valid: np.ndarray, out: AkfBlock) -> None:
    """Eqs. (3)-(15) looping over time, vectorised over (channel, filter).

    A run of steps where every channel has started and has its observation goes to
    :func:`_run_steady` when every channel has the same window; the other steps run one by
    one in :func:`_step`, with the masks.  The same arithmetic either way, bit for bit."""
    s = bank.state
    uniform = bool((bank.N == bank.N[0]).all())
    all_valid = np.asarray(valid.all(axis=1))
    any_valid = np.asarray(valid.any(axis=1)).tolist()
    T = y.shape[0]
    gaps = np.flatnonzero(~all_valid)           # run_end[k]: the first step >= k without every observation
    run_end = np.append(gaps, T)[np.searchsorted(gaps, np.arange(T))].tolist()
    rings = _Rings(bank)
    k = 0
    while k < T:
        if uniform and run_end[k] > k and bool(s.started.all()):
            _run_steady(bank, y, out, k, run_end[k])
            k = run_end[k]
        else:
            _step(bank, rings, y, valid, out, k, any_valid[k], run_end[k] > k)
            k += 1


class _Rings:
    """Index arrays of a bank's ring buffers (per call of :func:`_run_numpy`)."""

    def __init__(self, bank: AkfBank):
        Nmax = bank.state.res2.shape[2]
        self.chan = np.arange(bank.C)
        self.slots = np.arange(Nmax)[None, :]
        self.slot_mask = self.slots < bank.N[:, None]           # (C, Nmax) slots in use
        self.full = bool((bank.N == Nmax).all())   # every ring as long as the longest: once filled, all in use
        self.ci, self.ni = self.chan[:, None, None], np.arange(bank.n)[None, :, None]   # ring[ci, ni, order]


def _step(bank: AkfBank, g: _Rings, y: np.ndarray, valid: np.ndarray, out: AkfBlock, k: int,
          any_v: bool, every: bool) -> None:
    """Step k of every (channel, filter), masked for the channels not started or without their
    observation (the masks are skipped once every channel has started, and at a step where
    every channel has its observation)."""
    s = bank.state
    R, zc, N = bank.R, bank.z_c[:, None], bank.N
    v = valid[k]
    yk = y[k][:, None]
    first = v & (s.started == 0)
    if first.any():                       # x̂(0) = first observation
        s.x[first] = yk[first]
        s.started[first] = 1
    all_on = bool(s.started.all())
    on = (s.started == 1)[:, None]        # nothing happens before the first observation
    x_prior = s.x                                          # (3) (s.x is replaced, never changed in place, below)
    P_prior = s.P + s.Q if all_on else np.where(on, s.P + s.Q, s.P)   # (4)
    Y = P_prior + R                                        # (6)
    out.x_prior[k] = x_prior if all_on else np.where(on, x_prior, np.nan)
    out.Y[k] = Y if all_on else np.where(on, Y, np.nan)
    if not any_v:
        s.P = P_prior
        out.x_hat[k] = out.x_prior[k]
        out.Q[k] = s.Q if all_on else np.where(on, s.Q, np.nan)
        return
    innov = yk - x_prior                                   # (5)
    K = P_prior / Y                                        # (7)
    dx = K * innov
    x = x_prior + dx                                       # (8)
    P = (1.0 - K) * P_prior                                # (9)
    vv = v[:, None]
    s.x = x if every else np.where(vv, x, x_prior)
    s.P = P if every else np.where(vv, P, P_prior)
    out.x_hat[k] = s.x if all_on else np.where(on, s.x, np.nan)
    # windows of eqs. (11) and (14): ring buffers, per-channel slot
    if every:
        s.res2[g.chan, :, s.pos] = (yk - x) ** 2
        s.dx2[g.chan, :, s.pos] = dx * dx
        s.pos = (s.pos + 1) % N
        s.fill = np.minimum(s.fill + 1, N)
    else:
        slot = s.pos
        vc = g.chan[v]
        s.res2[vc, :, slot[v]] = ((yk - x) ** 2)[v]
        s.dx2[vc, :, slot[v]] = (dx * dx)[v]
        s.pos = np.where(v, (s.pos + 1) % N, s.pos)
        s.fill = np.where(v, np.minimum(s.fill + 1, N), s.fill)
    cnt = np.maximum(s.fill[:, None].astype(np.float64), 1)
    # sum in chronological order, like the reference and the C kernel
    order = (((s.pos - s.fill)[:, None] + g.slots) % N[:, None])[:, None, :]   # each ring's slots, oldest first
    take = (None if g.full and (s.fill == N).all()
            else ((g.slots < s.fill[:, None]) & g.slot_mask)[:, None, :])
    M = _window_sum(s.res2[g.ci, g.ni, order], take) / cnt         # (11)
    G_hat = _window_sum(s.dx2[g.ci, g.ni, order], take) / cnt      # (14)
    G_tilde = K * K * Y                                    # (13)
    S = np.maximum(1.0, G_hat / G_tilde) if bank.scaling else 1.0   # (12)
    s.Q = S * M if every else np.where(vv, S * M, s.Q)     # (10)
    out.Q[k] = s.Q if all_on else np.where(on, s.Q, np.nan)
    z = innov / np.sqrt(Y)                                 # (15)
    out.outlier[k] = (np.abs(z) > zc) & vv


def _run_steady(bank: AkfBank, y: np.ndarray, out: AkfBlock, k0: int, k1: int) -> None:
    """Steps k0..k1-1, where every channel has started and has its observation, of a bank
    whose channels all have the same window N.

    The windows of eqs. (11) and (14) are laid out in time rather than in rings, both in one
    array ``h`` (steps, 2, C, n): the N-1 entries before the run (zeros where a window is not
    yet full; 0 + v is v, so a zero prefix leaves the bits of the chronological sum as they
    are), then one row per step, so that each step sums one contiguous slice, oldest first.
    Only x̂, P, Q̂ and the windows feed back; x̂⁻ (the previous x̂), z and the outlier test
    are formed for the whole run afterwards, and the rings are updated at the end.  Every
    value is the operation :func:`_step` does on the same operands: the same bits."""
    s = bank.state
    N, L = int(bank.N[0]), k1 - k0
    R = bank.R
    h = _window_history(s, N, L)
    cnts = np.minimum(s.fill[None, :, None] + np.arange(1, L + 1)[:, None, None], N).astype(np.float64)
    x, P, Q = s.x, s.P, s.Q
    x_hat, Yo, Qo = out.x_hat, out.Y, out.Q
    ys = y[k0:k1, :, None]                                             # (L, C, 1)
    scaling = bank.scaling
    acc = np.add.accumulate
    for j in range(L):
        k = k0 + j
        yk, row = ys[j], h[N - 1 + j]
        P_prior = P + Q                                                # (4)
        Y = np.add(P_prior, R, out=Yo[k])                              # (6)
        K = P_prior / Y                                                # (7)
        dx = np.multiply(K, yk - x, out=row[1])                        # (5), K ỹ
        x = np.add(x, dx, out=x_hat[k])                                # (8)
        P = (1.0 - K) * P_prior                                        # (9)
        np.subtract(yk, x, out=row[0])
        np.multiply(row, row, out=row)                                 # (y - x̂)², Δx̂²
        MG = acc(h[j:j + N], axis=0)[-1] / cnts[j]                     # (11), (14)
        S = np.maximum(1.0, MG[1] / (K * K * Y)) if scaling else 1.0   # (12), (13)
        Q = np.multiply(S, MG[0], out=Qo[k])                           # (10)
    out.x_prior[k0] = s.x                                              # (3): x̂⁻(k) = x̂(k-1)
    out.x_prior[k0 + 1:k1] = x_hat[k0:k1 - 1]
    s.x, s.P, s.Q = x_hat[k1 - 1].copy(), P, Q.copy()
    z = (ys - out.x_prior[k0:k1]) / np.sqrt(Yo[k0:k1])                # (15)
    out.outlier[k0:k1] = np.abs(z) > bank.z_c[:, None]
    _store_history(s, h, N, L)


def _window_history(s: AkfState, N: int, L: int) -> np.ndarray:
    """(N-1+L, 2, C, n) array whose first N-1 rows are the rings' last N-1 entries of
    (y - x̂)² and Δx̂², oldest first (zeros beyond a ring's fill)."""
    C, n = s.x.shape
    h = np.empty((N - 1 + L, 2, C, n))
    if N > 1:
        age = np.arange(N - 1, 0, -1)[:, None]                       # N-1 .. 1 steps before the run
        slot = (s.pos[None, :] - age) % N                            # (N-1, C)
        chan = np.arange(C)[None, :]
        keep = (age <= s.fill[None, :])[:, :, None]
        h[:N - 1, 0] = np.where(keep, s.res2[chan, :, slot], 0.0)   # (N-1, C, n)
        h[:N - 1, 1] = np.where(keep, s.dx2[chan, :, slot], 0.0)
    return h


def _store_history(s: AkfState, h: np.ndarray, N: int, L: int) -> None:
    """Write a run's last min(L, N) window entries back to the rings; advance pos and fill."""
    m = min(L, N)
    age = np.arange(m, 0, -1)[:, None]                               # m .. 1
    pos = (s.pos + L) % N
    slot = (pos[None, :] - age) % N                                  # (m, C)
    chan = np.arange(s.x.shape[0])[None, :]
    rows = h[N - 1 + L - m:]                                         # (m, 2, C, n), oldest first
    s.res2[chan, :, slot] = rows[:, 0]
    s.dx2[chan, :, slot] = rows[:, 1]
    s.pos = pos
    s.fill = np.minimum(s.fill + L, N)


def _window_sum(ordered, take):
    """Sum of the last `fill` entries of each ring (``ordered``: its slots oldest first,
    ``take``: those that hold an entry, None: all), oldest first (chronological)."""
    vals = ordered if take is None else np.where(take, ordered, 0.0)
    # cumulative left-to-right addition = chronological order (np.add.accumulate is
    # sequential: its last entry is the loop 0 + v0 + v1 + ..., bit for bit)
    return np.add.accumulate(vals, axis=2)[:, :, -1]
