"""Jitter smoothing of the committed edges and the speed and angle at every sample.

Steps 4-5 of docs/tacho.md: at every committed edge a local weighted
least-squares quadratic of pulse count vs edge time gives a knot (time, angle,
speed); between knots the speed is interpolated linearly and the angle by a
cubic Hermite; after a run's last edge the speed decays as one pulse over the
elapsed time.  Knots older than ``history_s``, or beyond the newest ``history_max``, are dropped.  The fit of the knots
and the loop between them also run in the compiled ``cmsensord.dsp._trackerkernel``
(bit for bit).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from cmsensord.dsp.tacho.edges import SUB, BoolArray, FloatArray, IntArray, Run, TachoState

try:  # the compiled loop of evaluate() is optional: numpy is the fallback (same results)
    from cmsensord.dsp import _trackerkernel as _kernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _kernel = None
_knot_fit = getattr(_kernel, "knot_fit", None)     # (an older build lacks it)

_SCALAR_ROWS = 8  # up to this many rows the 3x3 solves run on Python floats (the same arithmetic)


def weighted_quadratic(x: FloatArray, y: FloatArray, wgt: FloatArray, npts: IntArray) -> FloatArray:
    """Per row, the weighted least-squares quadratic y = c0 + c1 x + c2 x^2 over its
    points (weights ``wgt``, 0 for unused ones; a single row of weights serves every row):
    (rows, 3).  A straight line where a row has two points, zeros where it has fewer."""
    rows, width = x.shape
    # the weighted moments s0..s4 and right-hand sides b0..b2 (each a sum over its
    # window, the same products as written out term by term), in one reduction
    terms = np.empty((rows, 8, width))
    terms[:, 0] = wgt
    x2 = x * x
    wx, wx2 = np.multiply(wgt, x, out=terms[:, 1]), np.multiply(wgt, x2, out=terms[:, 2])
    np.multiply(wx2, x, out=terms[:, 3])
    np.multiply(wx2, x2, out=terms[:, 4])
    np.multiply(wgt, y, out=terms[:, 5])
    np.multiply(wx, y, out=terms[:, 6])
    np.multiply(wx2, y, out=terms[:, 7])
    mom = terms.sum(axis=2)
    if rows <= _SCALAR_ROWS:
        return np.array([_solve_normal(m, n) for m, n in zip(mom.tolist(), npts.tolist())],
                        dtype=np.float64).reshape(rows, 3)
    return solve_normal_rows(mom, npts)


def _solve_normal(mom: list[float], n: int) -> tuple[float, float, float]:
    """One row of :func:`solve_normal_rows` on Python floats (the same operations, so the same bits)."""
    if n < 2:
        return 0.0, 0.0, 0.0
    s0, s1, s2, s3, s4, b0, b1, b2 = mom
    a02, a12, a22 = (s2, s3, s4) if n >= 3 else (0.0, 0.0, 1.0)
    if n < 3:
        b2 = 0.0
    return _eliminate(s0, s1, s2, a02, a12, a22, b0, b1, b2)


def solve_normal_rows(mom: FloatArray, npts: IntArray) -> FloatArray:
    """Per row of moments ``mom`` (rows, 8) = s0..s4, b0..b2, the solution c of the normal
    equations [[s0 s1 s2] [s1 s2 s3] [s2 s3 s4]] c = b by symmetric Gaussian elimination
    (closed form, no pivoting: s0 >= |s1|, s2 when |x| <= 1): (rows, 3).  Rows with
    ``npts`` 2 solve for a straight line (c2 = 0), rows with fewer give zeros."""
    s0, s1, s2, s3, s4, b0, b1, b2 = mom.T
    lin = npts < 3
    one = npts < 2
    a02 = np.where(lin, 0.0, s2)
    a12 = np.where(lin, 0.0, s3)
    a22 = np.where(lin, 1.0, s4)
    b2 = np.where(lin, 0.0, b2)
    if one.any():
        s0, s1, s2, b0, b1 = (np.where(one, v, r) for v, r in
                              ((1.0, s0), (0.0, s1), (1.0, s2), (0.0, b0), (0.0, b1)))
    return np.stack(_eliminate(s0, s1, s2, a02, a12, a22, b0, b1, b2), axis=1)


def _eliminate(s0: Any, s1: Any, s2: Any, a02: Any, a12: Any, a22: Any, b0: Any, b1: Any,
               b2: Any) -> tuple[Any, Any, Any]:
    """c of [[s0 s1 a02] [s1 s2 a12] [a02 a12 a22]] c = [b0 b1 b2] by symmetric Gaussian
    elimination, on Python floats or on arrays of rows (the same operations: the same bits)."""
    m1 = s1 / s0
    d11 = s2 - m1 * s1
    d12 = a12 - m1 * a02
    e1 = b1 - m1 * b0
    m2 = a02 / s0
    d22 = a22 - m2 * a02
    e2 = b2 - m2 * b0
    m3 = d12 / d11
    c2 = (e2 - m3 * e1) / (d22 - m3 * d12)
    c1 = (e1 - d12 * c2) / d11
    c0 = (b0 - s1 * c1 - a02 * c2) / s0
    return c0, c1, c2


def bounded_lo(lo: int, hi: int, n: int, most: int | None) -> int:
    """The first live column of a buffer whose live columns are [lo, hi) once n more are
    added and at most ``most`` (None: no bound) are kept: the oldest go first."""
    if most is None or hi - lo + n <= most:
        return lo
    return min(hi, hi + n - most)


def make_room(buf: FloatArray, lo: int, hi: int, n: int) -> tuple[FloatArray, int, int]:
    """A column buffer whose live columns are [lo, hi) with room for n more after them:
    the same one, or a copy compacted to start at 0 and grown by doubling (amortised
    O(1) per column).  Returns (buffer, lo, hi)."""
    if hi + n <= buf.shape[1]:
        return buf, lo, hi
    live = hi - lo
    cap = buf.shape[1]
    while live + n > cap // 2:
        cap *= 2
    new = np.empty((buf.shape[0], cap))
    new[:, :live] = buf[:, lo:hi]
    return new, 0, live


class KnotSmoothing(TachoState):
    """The smoothing part of :class:`~cmsensord.dsp.tacho.TachoTracker`: knots of
    the committed edges and the speed and angle at any sample."""

    smooth_kernel = True  # the knots' fit in the compiled kernel when it is built

    def evaluate(self, samples: npt.ArrayLike) -> tuple[FloatArray, FloatArray, BoolArray]:
        """(speed in Hz, angle in turns, valid) at unwrapped sample indices (any shape, int or float).

        The angle counts revolutions since the first edge (turns 0 there).
        Before the first edge, after a loss and behind the kept history the
        speed is 0 and invalid (NaN behind the history); see docs/tacho.md.
        """
        self._settle()
        s = np.asarray(samples, dtype=np.float64)
        flat = s.reshape(-1)
        knots = self._knots(float(flat.min()), float(flat.max())) if flat.size else self._knots()
        if knots[0].size == 0:
            return (np.zeros(s.shape), np.full(s.shape, self._held), np.zeros(s.shape, dtype=bool))
        between = self._between_c if _kernel is not None and self.use_kernel else self._between
        speed, turns, valid, jj, before, tail = between(flat, *knots)
        if tail.any():
            self._after_runs(flat, jj, tail, knots, speed, turns, valid)
        if before.any() and self._pruned:  # behind the kept history: unknown
            turns[before] = np.nan
            speed[before] = np.nan
        return (speed.reshape(s.shape) * self.fs, turns.reshape(s.shape), valid.reshape(s.shape))

    @staticmethod
    def _between_c(flat: FloatArray, kT: FloatArray, kth: FloatArray, kw: FloatArray,
                   kr: IntArray) -> tuple[FloatArray, FloatArray, BoolArray, IntArray, BoolArray, BoolArray]:
        """:meth:`_between` in the compiled kernel (one pass, no temporaries)."""
        speed = np.empty(flat.size)
        turns = np.empty(flat.size)
        jj = np.empty(flat.size, dtype=np.int64)
        code = np.empty(flat.size, dtype=np.uint8)
        _kernel.tacho_eval(np.ascontiguousarray(flat), np.ascontiguousarray(kT),
                           np.ascontiguousarray(kth), np.ascontiguousarray(kw),
                           np.ascontiguousarray(kr, dtype=np.int64), speed, turns, jj, code)
        return speed, turns, code == 1, jj, code == 0, code == 2

    @staticmethod
    def _between(flat: FloatArray, kT: FloatArray, kth: FloatArray, kw: FloatArray,
                 kr: IntArray) -> tuple[FloatArray, FloatArray, BoolArray, IntArray, BoolArray, BoolArray]:
        """Speed and turns between two knots of one run (cubic Hermite angle, linear speed;
        0 elsewhere), valid there; each sample's knot at or before it, and the samples before
        the first knot and those after a run's last knot (``before``, ``tail``)."""
        speed = np.zeros(flat.size)
        turns = np.zeros(flat.size)
        valid = np.zeros(flat.size, dtype=bool)
        j = np.searchsorted(kT, flat, side="right") - 1
        before = j < 0
        jj = np.clip(j, 0, kT.size - 1)
        nxt = np.minimum(jj + 1, kT.size - 1)
        inner = (~before) & (jj + 1 < kT.size) & (kr[nxt] == kr[jj])
        every = bool(inner.all())         # the usual case: no masks needed
        a, b, x = (jj, nxt, flat) if every else (jj[inner], nxt[inner], flat[inner])
        if a.size:
            h = kT[b] - kT[a]
            u = (x - kT[a]) / h
            u2, u3 = u * u, u * u * u
            th = ((2 * u3 - 3 * u2 + 1) * kth[a] + (u3 - 2 * u2 + u) * h * kw[a]
                  + (-2 * u3 + 3 * u2) * kth[b] + (u3 - u2) * h * kw[b])
            sp = (1.0 - u) * kw[a] + u * kw[b]
            if every:
                turns, speed = th, sp
                valid[:] = True
            else:
                turns[inner] = th
                speed[inner] = sp
                valid[inner] = True
        return speed, turns, valid, jj, before, (~before) & (~inner)

    def _after_runs(self, flat: FloatArray, jj: IntArray, tail: BoolArray,
                    knots: tuple[FloatArray, FloatArray, FloatArray, IntArray], speed: FloatArray,
                    turns: FloatArray, valid: BoolArray) -> None:
        """Into ``speed``, ``turns`` and ``valid`` at ``tail``: the samples after their run's
        last knot (``jj``), extrapolated (:meth:`_tail`) until the run's timeout, 0 and invalid
        after it."""
        kT, kth, kw, kr = knots
        a = jj[tail]
        rids, inv = np.unique(kr[a], return_inverse=True)
        stops = np.array([self._stop_of(int(r)) for r in rids])[inv.reshape(-1)]
        tau = flat[tail] - kT[a]
        tau_stop = stops - kT[a]
        ok = tau < tau_stop
        sp, dturn = self._tail(kw[a], np.where(ok, tau, tau_stop), 1.0 / self.ppr)
        turns[tail] = kth[a] + dturn
        speed[tail] = np.where(ok, sp, 0.0)
        valid[tail] = ok

    def _stop_of(self, rid: int) -> float:
        """End of the valid extrapolation of run ``rid`` (samples): its timeout."""
        run = self._runs.get(rid)
        if run is None:
            return math.inf
        if run.ended:
            return run.stop
        return (run.last_raw_q + self._timeout_q(run)) / SUB

    @staticmethod
    def _tail(w0: FloatArray, tau: FloatArray, c: float) -> tuple[FloatArray, FloatArray]:
        """Speed min(w0, c / tau) after the last edge and its integral from 0 to tau."""
        with np.errstate(divide="ignore", invalid="ignore"):
            tc = np.where(w0 > 0, c / np.where(w0 > 0, w0, 1.0), np.inf)
            slow = tau > tc
            sp = np.where(slow, c / np.where(slow, tau, 1.0), w0)
            dturn = np.where(slow, c + c * np.log(np.where(slow, tau / tc, 1.0)), w0 * tau)
        return sp, dturn

    def _finalise(self, ended: bool) -> None:
        """Fit the knots of the current run whose windows are complete (all of them when
        the run has ended) and append them to the final knots."""
        self._flush_segments()
        run = self._run
        K = self._c0 + len(self._cT)  # committed edges of the run so far
        h = self.half_window
        last = K - 1 if ended else K - 1 - h  # last centre that can be finalised
        if run is None or K < 2 or last < self._final:
            if ended:
                self._final = max(self._final, K)
            return
        T, th, w = self._fit(run, np.arange(self._final, last + 1), K)
        self._append_knots(T, th, w, run.rid)
        self._final = last + 1
        # committed edges no longer needed by any future window (smoothing or causal)
        drop = min(self._final - h, K - self.causal_window) - self._c0
        if drop > 256:
            del self._cT[:drop]
            del self._cn[:drop]
            self._c0 += drop

    def _fit(self, run: Run, centres: IntArray, K: int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Local least-squares quadratic of pulse count vs edge time at each centre (docs/tacho.md, step 4).

        Windows [k - h, k + h] clipped to the committed edges [0, K) of ``run`` (the current one).
        Returns the knot times (samples), angles (turns) and speeds (turns/sample).  The centres
        are consecutive; in the compiled kernel when it is built (``smooth_kernel``: the same
        operations, from the committed edges as the Python lists they are).
        """
        if _knot_fit is not None and self.smooth_kernel and centres.size:
            out = np.empty((3, centres.size))
            first = int(centres[0])
            at = max(self._c0, first - self.half_window)     # the edges of the windows, not the whole list
            _knot_fit(self._cT[at - self._c0:], self._cn[at - self._c0:], at, first, K, self._kernel, run.base,
                      float(self.ppr), out)
            return out[0], out[1], out[2]
        h = self.half_window
        Tc, nc = self._committed()
        c0 = self._c0
        k = centres - c0
        if centres.size and int(centres[0]) >= h and int(centres[-1]) + h <= K - 1:
            # every window complete (the usual case): no masks, the same values
            idx = k[:, None] + self._offsets[None, :]
            Tk = Tc[k]
            dx = Tc[idx] - Tk[:, None]
            y = nc[idx] - nc[k][:, None]
            wgt = self._kernel                   # broadcast over the rows
            npts = np.full(k.size, 2 * h + 1)
        else:
            lo = np.maximum(centres - h, 0)
            hi = np.minimum(centres + h, K - 1)
            idx = centres[:, None] + self._offsets[None, :]
            use = (idx >= lo[:, None]) & (idx <= hi[:, None])
            idx = np.where(use, idx, centres[:, None]) - c0
            dx = np.where(use, Tc[idx] - Tc[k][:, None], 0.0)
            y = np.where(use, nc[idx] - nc[k][:, None], 0.0)
            wgt = use * self._kernel[None, :]
            npts = use.sum(axis=1)
        S = np.abs(dx).max(axis=1)
        x = dx / S[:, None]
        coef = weighted_quadratic(x, y, wgt, npts)
        T = Tc[k]
        th = run.base + (nc[k] + coef[:, 0]) / self.ppr
        w = coef[:, 1] / (S * self.ppr)
        return T, th, w

    def _provisional(self) -> tuple[FloatArray, FloatArray, FloatArray] | None:
        """Knots of the current run beyond the final ones (one-sided windows), fitted when queried."""
        run = self._run
        if run is None:
            return None
        K = self._c0 + len(self._cT)
        if K < 2 or self._final >= K:
            return None
        key = (run.rid, K, self._final)
        if key != self._prov_key:
            self._prov = self._fit(run, np.arange(self._final, K), K)
            self._prov_key = key
        return self._prov

    def _append_knots(self, T: FloatArray, th: FloatArray, w: FloatArray, rid: int) -> None:
        """Append final knots; beyond ``history_max`` knots the oldest are dropped (queries
        behind them: NaN, as behind ``history_s``)."""
        n = T.size
        lo = bounded_lo(self._klo, self._khi, n, self.history_max)
        if lo != self._klo:
            self._pruned = True
        buf, self._klo, self._khi = make_room(self._kbuf, lo, self._khi, n)
        self._kbuf = buf
        buf[0, self._khi:self._khi + n] = T
        buf[1, self._khi:self._khi + n] = th
        buf[2, self._khi:self._khi + n] = w
        buf[3, self._khi:self._khi + n] = rid
        self._khi += n

    def _knots(self, t_min: float = -math.inf, t_max: float = math.inf
               ) -> tuple[FloatArray, FloatArray, FloatArray, IntArray]:
        """Final knots (those around [t_min, t_max]) then the provisional ones: T, turns, speed, run id."""
        T = self._kbuf[0, self._klo:self._khi]
        a = max(int(np.searchsorted(T, t_min, side="right")) - 1, 0)
        b = min(int(np.searchsorted(T, t_max, side="right")) + 1, T.size)
        k = self._kbuf[:, self._klo + a:self._klo + b]
        kT, kth, kw, kr = k[0], k[1], k[2], k[3].astype(np.int64)
        if b < T.size:
            return kT, kth, kw, kr
        prov = self._provisional()
        run = self._run
        if prov is None or run is None:  # provisional knots imply a current run
            return kT, kth, kw, kr
        pT, pth, pw = prov
        rid = np.full(pT.size, run.rid, dtype=np.int64)
        return (np.concatenate([kT, pT]), np.concatenate([kth, pth]),
                np.concatenate([kw, pw]), np.concatenate([kr, rid]))

    def _prune(self) -> None:
        """Drop final knots more than history_s behind the newest (keeping the last two)."""
        T = self._kbuf[0, self._klo:self._khi]
        if T.size < 3:
            return
        cut = min(int(np.searchsorted(T, T[-1] - self.history_s * self.fs)), T.size - 2)
        if cut < max(64, T.size // 16):  # prune in batches
            return
        self._klo += cut
        self._pruned = True
        K = self._sbuf[0, self._slo:self._shi]
        scut = min(int(np.searchsorted(K, K[-1] - self.history_s * self.fs)), K.size - 2) if K.size > 2 else 0
        self._slo += max(scut, 0)
        first_live = int(self._kbuf[3, self._klo])  # run ids increase with time
        for rid in [r for r in self._runs if r < first_live]:
            del self._runs[rid]
