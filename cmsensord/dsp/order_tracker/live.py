"""A live call of the order tracker in few steps: the common path of :meth:`OrderTracker.process_blocks`.

A live call (a tenth of a second of samples, the speed from a function, no sample missing,
without the smoother) takes the same steps every time: the anti-alias filter and decimation,
the delayed speed (:func:`~.speed_line.delayed_at`), the model speed and omega, the gains
from the table, the filter with its block statistics (:func:`~.blocks.fused_blocks`).
:class:`LiveCall` runs them as two passes of the compiled kernel with numpy's transcendental
functions between them: ``live_in`` (the decimation, the delay line, the model speed, omega /
fs and the speed over the grid's lowest), ``np.cos`` and ``np.log`` (the same ufuncs as the
general path), ``live_out`` (the table's rows at the grid coordinate, as ``lerp_at``, and
``forward_blocks`` with the block starts and input samples of
:func:`~.blocks.block_stats`).  The same operations as the general path, so the same
numbers and the same state after the call (tests/test_tracker_live_call.py holds them bit
for bit).  ``live_in`` declines, changing nothing, where the general path has more to do: a
NaN in the input, a missing input near, a call shorter than the delay line; so does
:meth:`LiveCall.__call__` before it for the first call and a partial block carried with
missing samples.  ``live_out`` declines where the table lacks the rows (the table's lookup
then fills them and ``forward_blocks`` runs as in the general path).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from cmsensord.dsp.order_tracker.blocks import fused_blocks
from cmsensord.dsp.order_tracker.gain_table import SEGMENT
from cmsensord.dsp.order_tracker.speed_line import SpeedAt
from cmsensord.dsp.order_tracker.state import BlockStats

if TYPE_CHECKING:
    from cmsensord.dsp.order_tracker.tracker import OrderTracker

TWO_PI = 2.0 * np.pi        # components.Omegas's factor
SCRATCH = 4096              # a call of up to this many tracker samples works in kept arrays


class LiveCall:
    """The live path of tracker ``tr`` (built by :meth:`of` where it applies; called with the
    tracker, which holds it: no reference cycle)."""

    def __init__(self, tr: OrderTracker, kernel):
        self.C, self.K = tr.C, tr.K
        self._live_in, self._live_out, self._forward_blocks = kernel.live_in, kernel.live_out, kernel.forward_blocks
        om = tr.omegas
        assert tr.table is not None
        grid = tr.table.grid
        self._omega = (tr.min_rpm, om.orders, om.fixed, om.by_order_u8, TWO_PI, tr.fs_track, grid.lo)
        # the grid coordinate log(max(speed, lo) / lo) / lq of GainTable.lookup is log(speed / lo) / lq
        # where the grid starts at min_rpm (the model speed is never below it) and is geometric
        self._direct = not grid.linear and grid.lo == tr.min_rpm and tr.table.P is None
        self._stats = (tr.min_rpm, tr.top_order, 0.5 * tr.fs_track)
        self._kept: tuple[np.ndarray, ...] | None = None     # _scratch's arrays

    @classmethod
    def of(cls, tr: OrderTracker, kernel) -> LiveCall | None:
        """The live path of ``tr``, or None where it has none: no compiled kernel (or one without
        ``live_in``), no decimation, exact gains, the smoother."""
        if (not all(hasattr(kernel, f) for f in ("live_in", "live_out", "forward_blocks")) or tr.backend != "c"
                or tr.sos is None or tr.table is None or tr.lag is not None):
            return None
        return cls(tr, kernel)

    def __call__(self, tr: OrderTracker, y: np.ndarray, speed_at: SpeedAt) -> tuple[BlockStats | None, SpeedAt]:
        """The causal blocks of tracker ``tr``'s call of y (T, C) whose speed comes from
        ``speed_at``, and ``speed_at``; or (None, a function giving the speeds already asked)
        where the general path must run: it asks for the same samples (each is asked for once)."""
        st = tr.state
        T, n, D, skip = y.shape[0], tr.delay_in, tr.decimate, st.skip
        if not st.n_in or T < n or skip >= T or "miss" in st.pend:
            return None, speed_at
        p0 = -(st.n_in + n) % D
        asked = np.arange(p0, T, D)
        vals = np.ascontiguousarray(speed_at(asked), dtype=np.float64)
        N = (T - skip + D - 1) // D
        yd, rd, speed, u, c = self._scratch(N)
        if not y.flags.c_contiguous:
            y = np.ascontiguousarray(y)
        if not self._live_in(tr.sos, y, st.zi, skip, D, st.last_miss, st.n_in + skip, tr.missing_window,
                             st.rpm_line, vals, p0, *self._omega, yd, rd, speed, u, c):
            return None, _Asked(asked, vals)
        st.skip = (skip - T) % D
        st.n_in += T
        np.cos(c, out=c)                    # cos(omega / fs_track), as _coeffs_gains
        if self._direct:
            np.log(u, out=u)                # the grid coordinate times log1p(q) (GainTable.lookup)
            got = self._blocks(tr, yd, rd, u, c)
            if got is not None:
                return got, speed_at
        c *= 2.0
        assert tr.table is not None         # of(): the table's gains
        k = tr.table.lookup(speed)[0]
        return fused_blocks(self._forward_blocks, st, st.n_track, yd, c, k, rd, tr), speed_at

    def _scratch(self, N: int) -> tuple[np.ndarray, ...]:
        """yd (N, C), rd, speed, u (N) and c (N, K) of a call: views of arrays kept for the calls
        of up to SCRATCH samples (what a call leaves in them is read by no one after it)."""
        if N > SCRATCH:
            return np.empty((N, self.C)), np.empty(N), np.empty(N), np.empty(N), np.empty((N, self.K))
        if self._kept is None:
            self._kept = (np.empty((SCRATCH, self.C)), np.empty(SCRATCH), np.empty(SCRATCH), np.empty(SCRATCH),
                          np.empty((SCRATCH, self.K)))
        yd, rd, speed, u, c = self._kept
        return yd[:N], rd[:N], speed[:N], u[:N], c[:N]

    def _blocks(self, tr: OrderTracker, yd: np.ndarray, rd: np.ndarray, logu: np.ndarray,
                cosw: np.ndarray) -> BlockStats | None:
        """:func:`~.blocks.fused_blocks` of the call with the gains at grid coordinates logu /
        log1p(q) and c = 2 cosw, in ``live_out``; None (nothing done) where the table lacks rows."""
        st, table = tr.state, tr.table
        assert table is not None
        pend = st.pend
        C, K, B, N = tr.C, tr.K, tr.block, yd.shape[0]
        p = len(pend["rpm"]) if pend else 0
        E = (p + N) // B
        tail = p + N - E * B
        ra, tt, si = np.empty((2, E, C, K)), np.empty((2, tail, C, K)), np.empty((2, E), dtype=np.int64)
        rms, amp, tw, te, starts, t_in = ra[0], ra[1], tt[0], tt[1], si[0], si[1]      # each contiguous
        rmean, valid, rt = np.empty(E), np.empty(E, dtype=bool), np.empty(tail)
        cw, ce, pr = (pend["wave"], pend["env"], pend["rpm"]) if p else (tw[:0], te[:0], rt[:0])
        n0 = st.n_track
        if not self._live_out(logu, table.grid.lq, table.kS, table.dkS, table.have, SEGMENT, table.kS.shape[1],
                              yd, cosw, st.z, pr, rd, K, B, cw, ce, *self._stats, n0, tr.decimate, tr.delay_in,
                              rms, amp, rmean, valid, tw, te, rt, starts, t_in):
            return None
        st.pend = {"wave": tw, "env": te, "rpm": rt} if p or tail else {}
        st.n_track = n0 + N
        return BlockStats(start=starts, t_in=t_in, rpm=rmean, rms=rms, amplitude=amp, valid=valid,
                          missing=np.zeros((E, C), dtype=np.int64))


class _Asked:
    """The speeds asked at input samples ``asked`` of a call, given again for those samples."""

    def __init__(self, asked: np.ndarray, vals: np.ndarray):
        self.asked, self.vals = asked, vals

    def __call__(self, i: np.ndarray) -> np.ndarray:
        if not np.array_equal(i, self.asked):
            raise AssertionError("the general path asked for other samples than the live path")
        return self.vals
