"""The causal speed: from the edges at or before each sample only.

For the order tracker, which must not wait for the smoothed speed (see "Causal
speed" in docs/tacho.md): at every committed edge a one-sided weighted
quadratic over the last ``causal_window`` edges of the run gives the speed and
acceleration, extrapolated from there; capped when edges are overdue, 0 and
invalid after the run's timeout.  Any split of the frames gives the same values.
The fit of new edges and the order tracker's speed at its samples (:meth:`CausalSpeed.causal_rpm`)
also run in the compiled ``cmsensord.dsp._trackerkernel`` (bit for bit).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from cmsensord.dsp.tacho.edges import SUB, BoolArray, FloatArray, TachoState
from cmsensord.dsp.tacho.smoothing import bounded_lo, make_room, weighted_quadratic

try:  # the compiled fit and speed are optional: numpy is the fallback (same results)
    from cmsensord.dsp import _trackerkernel as _kernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _kernel = None

_CAUSAL_SLACK = 2.5  # causal speed: pulse periods without an edge before it is capped (a missed pulse is 2)


class CausalSpeed(TachoState):
    """The causal part of :class:`~cmsensord.dsp.tacho.TachoTracker`: one segment
    (speed, acceleration) per committed edge."""

    causal_kernel = True  # the fit of new edges and causal_rpm in the compiled kernel when it is built

    def _flush_segments(self, upto: int | None = None) -> None:
        """Fit the causal segments of the edges committed since the last call (see
        "Causal speed"), in time order with a segment for each stretch of lost frames
        (``_marks``) that the edges up to ``upto`` have passed (1/256 sample; default: the edge
        being handled or the coverage, whichever is later)."""
        todo = self._seg_todo
        marks = self._marks
        if marks:
            due = upto if upto is not None else max(self._known_q, SUB * (self._now or 0))
            while marks and marks[0][0] <= due:
                a, b = marks.popleft()
                i = next((i for i, t in enumerate(todo) if t[1] * SUB >= a), len(todo))
                if i:
                    self._seg_todo = []
                    self._fit_segments(todo[:i])
                    todo = todo[i:]
                self._over_hole(a / SUB, b / SUB)
        if not todo:
            return
        self._seg_todo = []
        self._fit_segments(todo)

    def _over_hole(self, a: float, b: float) -> None:
        """Lost frames from sample ``a`` to ``b``: no edge could be seen there, so the segment
        before goes on, extrapolated, with its cap counting the pulse periods without an edge
        from b on (a segment keyed at a whose reference time is b), while that one is valid
        (the run goes on)."""
        hi = self._shi
        if hi <= self._slo or not self._sbuf[4, hi - 1] > 0:
            return
        _, T, w, acc, _ = self._sbuf[:, hi - 1].tolist()
        self._append_segments(np.array([a]), np.array([b]), np.array([w + acc * (b - T)]), np.array([acc]),
                              np.ones(1))

    def _fit_segments(self, todo: list[tuple[int, float]]) -> None:
        """The causal segments of the committed edges ``todo`` (committed index, known at): a
        one-sided weighted quadratic over the last ``causal_window`` committed edges of the run
        at each, vectorised over them."""
        if _kernel is not None and self.causal_kernel:     # the same operations, in C, into the buffer
            buf = self._segment_room(len(todo))
            # the committed edges from the first window's on (not the run's whole list)
            lo = max(self._c0, todo[0][0] - self.causal_window + 1)
            _kernel.causal_fit(self._cT[lo - self._c0:], self._cn[lo - self._c0:], todo, self._ckernel, lo,
                               float(self.ppr), buf, self._shi)
            self._shi += len(todo)
            return
        Tc, nc = self._committed()
        c0 = self._c0
        k = np.fromiter((t[0] for t in todo), dtype=np.int64, count=len(todo))
        known = np.fromiter((t[1] for t in todo), dtype=np.float64, count=len(todo))
        m = self.causal_window
        kr = k - c0
        Tk = Tc[kr]
        if int(kr.min()) >= m - 1:
            # every window complete (the usual case): no masks, the same values
            idx = kr[:, None] - self._cback[None, :]
            dx = Tc[idx] - Tk[:, None]
            y = nc[idx] - nc[kr][:, None]
            wgt = self._ckernel                  # broadcast over the rows
            npts = np.full(k.size, m)
        else:
            idx = k[:, None] - self._cback[None, :]
            use = idx >= c0
            idx = np.where(use, idx, k[:, None]) - c0
            dx = np.where(use, Tc[idx] - Tk[:, None], 0.0)
            y = np.where(use, nc[idx] - nc[kr][:, None], 0.0)
            wgt = use * self._ckernel[None, :]
            npts = use.sum(axis=1)
        S = np.abs(dx).max(axis=1)
        S = np.where(S > 0, S, 1.0)
        x = dx / S[:, None]
        coef = weighted_quadratic(x, y, wgt, npts)
        speed = coef[:, 1] / (S * self.ppr)
        acc = 2.0 * coef[:, 2] / (S * S * self.ppr)
        self._append_segments(np.maximum(known, Tk), Tk, speed, acc,
                              (npts >= 2).astype(np.float64))

    def _append_segments(self, key: FloatArray, T: FloatArray, speed: FloatArray, acc: FloatArray,
                         valid: FloatArray) -> None:
        n = key.size
        buf = self._segment_room(n)
        for row, v in enumerate((key, T, speed, acc, valid)):
            buf[row, self._shi:self._shi + n] = v
        self._shi += n

    def _segment_room(self, n: int) -> FloatArray:
        """The segment buffer with room for n more segments after ``_shi``; beyond ``history_max``
        segments the oldest are dropped (queries behind them: NaN, as behind ``history_s``)."""
        lo = bounded_lo(self._slo, self._shi, n, self.history_max)
        if lo != self._slo:
            self._pruned = True
        self._sbuf, self._slo, self._shi = make_room(self._sbuf, lo, self._shi, n)
        return self._sbuf

    def evaluate_causal(self, samples: npt.ArrayLike) -> tuple[FloatArray, BoolArray]:
        """(speed in Hz, valid) at sample indices from the edges up to each sample only.

        See "Causal speed" in docs/tacho.md: the value at sample s depends only on
        edges at or before s, so it is the same whenever it is asked for, as long as
        s < :attr:`covered_until`.  Samples not yet covered get the extrapolation too.
        """
        self._flush_segments()
        s = np.asarray(samples, dtype=np.float64)
        flat = s.reshape(-1)
        keys = self._sbuf[0, self._slo:self._shi]
        if keys.size == 0:
            return np.zeros(s.shape), np.zeros(s.shape, dtype=bool)
        j = np.searchsorted(keys, flat, side="right") - 1
        before = j < 0
        jj = np.maximum(j, 0)
        jj += self._slo
        T, w, a, v = self._sbuf[1:5].take(jj, axis=1)       # one gather for the four rows
        sp, valid = self._causal_speed(flat - T, w, a, v, before if before.any() else None)
        return (sp * self.fs).reshape(s.shape), valid.reshape(s.shape)

    def causal_rpm(self, base: int, pos: npt.ArrayLike) -> FloatArray:
        """The order tracker's speed [rpm] at the samples ``base + pos``: 60 x the speed of
        :meth:`evaluate_causal` where it is valid and finite, else 0 (the same values, bit for
        bit; in the compiled kernel when it is built, one call for the search and the speed)."""
        pos = np.asarray(pos, dtype=np.int64)
        if _kernel is None or not self.causal_kernel:
            hz, valid = self.evaluate_causal(base + pos)
            return np.where(valid & np.isfinite(hz), 60.0 * hz, 0.0)
        self._flush_segments()
        out = np.empty(pos.shape[0])
        _kernel.causal_rpm(self._sbuf, self._slo, self._shi, base, pos, self.fs,
                           _CAUSAL_SLACK / self.ppr, out)
        return out

    def causal_range(self, start: int, stop: int) -> tuple[FloatArray, BoolArray]:
        """:meth:`evaluate_causal` at the samples start .. stop - 1 (the same values, bit
        for bit), segment by segment: no per-sample search or gather (the order chain
        asks for every sample, 25 000 a second)."""
        self._flush_segments()
        n = max(0, int(stop) - int(start))
        lo, hi = self._slo, self._shi
        keys = self._sbuf[0, lo:hi]
        if keys.size == 0 or n == 0:
            return np.zeros(n), np.zeros(n, dtype=bool)
        a = int(np.searchsorted(keys, start, side="right")) - 1       # segment of the first sample
        b = int(np.searchsorted(keys, stop - 1, side="right")) - 1    # ... and of the last
        first = max(a, 0)
        # sample s is in segment k when keys[k] <= s < keys[k + 1]: cut at ceil(keys); the few
        # cuts of a call on Python ints (np.clip(np.ceil(...)) gave the same ones)
        cuts = [min(max(math.ceil(v), start), stop) for v in keys[first + 1:b + 1].tolist()]
        # samples before the first segment
        head = int(min(max(np.ceil(keys[0]), start), stop)) - start if a < 0 else 0
        edges = [start + head, *cuts, stop]
        counts = [e1 - e0 for e0, e1 in zip(edges, edges[1:])]
        seg = slice(lo + first, lo + first + len(counts))              # consecutive segments
        x = np.arange(start + head, stop, dtype=np.float64)
        T, w, acc = np.repeat(self._sbuf[1:4, seg], counts, axis=1)    # one gather for the 3 rows
        x -= T
        if self._overdue(seg, edges):
            sp, valid = self._causal_speed(x, w, acc, np.repeat(self._sbuf[4, seg], counts), None)
        else:                                   # _causal_speed without a cap: the same values
            sp = acc * x
            sp += w
            valid = np.repeat(self._sbuf[4, seg] > 0, counts)
            valid &= sp > 0
            np.copyto(sp, 0.0, where=~valid)
        if head:
            sp = np.concatenate((np.full(head, np.nan if self._pruned else 0.0), sp))
            valid = np.concatenate((np.zeros(head, dtype=bool), valid))
        sp *= self.fs
        return sp, valid

    def _overdue(self, seg: slice, edges: list[int]) -> bool:
        """Whether any sample edges[i] .. edges[i + 1] - 1 of the i-th segment of ``seg`` is past
        the causal slack (:meth:`_causal_speed`'s ``late``).  ``tau w`` grows with tau within a
        segment (tau >= 0 from its key on, rounding is monotonic; NaN or w <= 0 is never
        late), so the segment's last sample decides, with the same arithmetic (on Python
        floats: a call has a few segments)."""
        slack = _CAUSAL_SLACK / self.ppr
        T, w = self._sbuf[1, seg].tolist(), self._sbuf[2, seg].tolist()
        return any(e1 > e0 and (float(e1 - 1) - t) * wi > slack
                   for e0, e1, t, wi in zip(edges, edges[1:], T, w))

    def _causal_speed(self, tau: FloatArray, w: FloatArray, a: FloatArray, v: FloatArray,
                      before: BoolArray | None) -> tuple[FloatArray, BoolArray]:
        """Speed (turns/sample) and validity tau samples after a segment's edge (docs/tacho.md,
        "Causal speed"); ``before`` (None: none) marks samples before the first segment."""
        sp = a * tau
        sp += w                                         # w + a tau
        slack = _CAUSAL_SLACK / self.ppr
        with np.errstate(invalid="ignore"):
            late = tau * w > slack                      # edges overdue
        if late.any():                                  # the shaft slows: capped
            with np.errstate(divide="ignore", invalid="ignore"):
                cap = np.where(late, slack / np.where(late, tau, 1.0), np.inf)
            np.minimum(sp, cap, out=sp)
        valid = v > 0
        valid &= sp > 0                                 # NaN -> False; so is a clip at 0
        if before is not None:
            valid &= ~before
        sp = np.where(valid, sp, 0.0)
        if before is not None and before.any() and self._pruned:
            sp[before] = np.nan
        return sp, valid
