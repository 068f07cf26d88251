"""The streaming order tracker: gains, filter, per-block outputs (the input's decimation:
:mod:`.decimation`; the smoother: :mod:`.smoother`; the blocks' statistics: :mod:`.blocks`).

:class:`OrderTracker` runs the recursive angular-velocity Vold-Kalman order
tracker of Yeh, Pan & Le (eqs. (10)-(25)) for the channels of one machine,
streaming: any split of the input gives the same outputs.  The derivations,
the choices made where the paper is silent and the measured accuracy are in
docs/order_tracker.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cmsensord.dsp.order_tracker.antialias import cheb2ord, cheby2_sos, missing_window_of, sos_dc_delay
from cmsensord.dsp.order_tracker.bandwidth import component_r, describe
from cmsensord.dsp.order_tracker.blocks import block_stats, causal_blocks, fused_blocks, stats_numpy
from cmsensord.dsp.order_tracker.components import Omegas, TrackedComponent, model_speed, omega
from cmsensord.dsp.order_tracker.decimation import _NO_MISS, decimate, missing
from cmsensord.dsp.order_tracker.design import q_diag, riccati_doubling
from cmsensord.dsp.order_tracker.gain_table import GainTable, choose_grid, weakly
from cmsensord.dsp.order_tracker.live import LiveCall
from cmsensord.dsp.order_tracker.recursions import (
    CHUNK,
    envelope,
    forward_numpy,
    mask_groups,
    riccati_numpy,
)
from cmsensord.dsp.order_tracker.smoother import smooth
from cmsensord.dsp.order_tracker.sos_blocks import SosBlocks
from cmsensord.dsp.order_tracker.speed_line import SpeedAt, piece_of
from cmsensord.dsp.order_tracker.state import (
    BlockStats,
    TrackerOutput,
    TrackerState,
    cat_miss,
    join_outputs,
)

try:  # the compiled kernel is optional: numpy is the fallback
    from cmsensord.dsp import _trackerkernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _trackerkernel = None

PIECE_BYTES = 8 << 20   # a call is tracked in pieces whose per-sample arrays take about this


def have_kernel() -> bool:
    """True when the compiled kernel is importable."""
    return _trackerkernel is not None


class OrderTracker:
    """Streaming AV2KF order tracker for the channels of one machine (shared speed).

    Parameters
    ----------
    components : the tracked orders / fixed frequencies (K).
    fs_in : input sample rate [Hz] of ``y`` and ``rpm``.
    max_rpm : the highest speed expected; sets the decimation and the gain table.
    n_channels : C, channels of one machine (they share the speed, so the gains).
    q1 : process-noise level of eq. (25) (does not change the estimates).
    decimate : D, or None to choose it (docs/order_tracker.md §4 Decimation); 1 = none.
    oversample : minimum tracker rate over the highest tracked frequency (auto D).
    min_rpm : below this speed the output is invalid (and the model speed clamped).
    gains : "table" (steady-state, tabulated against speed) or "exact" (Riccati).
    smoother_lag_s : None (causal only) or the fixed lag L [s] of the smoother.
    output_rate_hz : rate of the per-block outputs (block = fs_track/rate samples).
    backend : "auto", "c" or "numpy".
    table_step_rpm : step of the gain table's speed grid at min_rpm (None: min_rpm/300); the
        grid is geometric (see gain_table.py), coarser if the table would exceed 16 MB.
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
        self._sos_blocks: SosBlocks | None = None       # the numpy path's anti-alias filter
        self.fs_in = float(fs_in)
        self.max_rpm = float(max_rpm)
        self.min_rpm = float(min_rpm)
        self.C = int(n_channels)
        self.K = len(self.components)
        self.top_order = max((c.order or 0.0) for c in self.components)      # the block statistics' top order
        self.omegas = Omegas(self.components)                               # omega() in one operation
        # in the kernel with the C backend (the same numbers): block statistics; filter + stats (process_blocks)
        self._stats_kernel = getattr(_trackerkernel, "block_stats", None) if backend == "c" else None
        self._fused_kernel = getattr(_trackerkernel, "forward_blocks", None) if backend == "c" else None
        self.q1 = float(q1)
        self.gains = gains
        self.f_hi = max(float(c.freq(self.max_rpm)) for c in self.components)

        self._setup_decimation(decimate, oversample, output_rate_hz)
        self._setup_blocks(output_rate_hz, smoother_lag_s)
        self._setup_table(horizon_s, table_step_rpm)
        self._live = LiveCall.of(self, _trackerkernel)      # process_blocks's live calls (live.py)
        self.state = self.initial_state()

    # ------------------------------------------------------------------ setup
    def _setup_decimation(self, decimate: int | None, oversample: float, output_rate_hz: float) -> None:
        """D, the tracker rate, the anti-alias sections, their delay and missing-sample window."""
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
            order, fc = cheb2ord(self.f_hi, self.fs_track - self.f_hi, 0.001, 80.0, self.fs_in)
            self.sos: np.ndarray | None = cheby2_sos(order, 80.0, fc, self.fs_in)
            gd = sos_dc_delay(self.sos)
            self.filter_delay_s = gd / self.fs_in
            self.delay_in = round(gd)
        else:
            self.sos = None
            self.filter_delay_s = 0.0
            self.delay_in = 0
        # a missing input spoils this many filter outputs (its own included): tracker
        # samples within them get no measurement update (docs/order_tracker.md §5)
        self.missing_window = missing_window_of(self.sos)

    def _setup_blocks(self, output_rate_hz: float, smoother_lag_s: float | None) -> None:
        """Output block length, smoother lag and latency."""
        self.block = max(1, round(self.fs_track / output_rate_hz))
        self.output_rate_hz = self.fs_track / self.block
        if smoother_lag_s is not None and smoother_lag_s < 0:
            raise ValueError(f"smoother_lag_s: expected None or >= 0, got {smoother_lag_s}")
        self.lag = None if smoother_lag_s is None else round(smoother_lag_s * self.fs_track)
        self.latency_s = (self.filter_delay_s + (self.lag or 0) / self.fs_track
                          + self.block / self.fs_track)
        # tracker samples per piece of a long call: P (2K x 2K) with the smoother, the
        # states (C x 2K, a few of them) always; 1024 (8 MB of P) at 16 orders
        d = 2 * len(self.components)
        per_sample = 8 * (d * d * (self.lag is not None) + 4 * self.C * d)
        self.piece = int(min(1 << 16, max(1024, PIECE_BYTES // per_sample)))

    def _setup_table(self, horizon_s: float, table_step_rpm: float | None) -> None:
        """The doubling horizon and the (empty) gain table over [min_rpm, 1.1 max_rpm]
        (P only with the smoother, which alone uses it)."""
        self.horizon_s = float(horizon_s)
        self._n_double = max(1, math.ceil(math.log2(max(2.0, horizon_s * self.fs_track))))
        self.table: GainTable | None = None
        self._fills = 0                 # fills of the table so far (_steady_state)
        if self.gains == "table":
            top = 1.1 * self.max_rpm
            want_p = self.lag is not None
            # r on the bandwidth grid is computed when the table's segments need it
            # (_steady_state): a machine at one speed pays for a few grid points only
            grid = choose_grid(self.min_rpm, top, table_step_rpm, self._crossing_cap(top),
                               GainTable.bytes_per_point(self.K, want_p))
            self.table = GainTable(grid, self.K, want_p, weakly(self._steady_state), kernel=self.backend == "c")

    def _crossing_cap(self, top: float) -> float | None:
        """1 rpm when a fixed-frequency component crosses an order's frequency between
        min_rpm and ``top`` (the gains change within a few rpm there), else None."""
        fixed = [c.freq_hz for c in self.components if c.freq_hz is not None]
        orders = [c.order for c in self.components if c.order]
        cross = [60.0 * f / o for f in fixed for o in orders]
        return 1.0 if any(self.min_rpm <= s <= top for s in cross) else None

    def _coeffs(self, speed: np.ndarray):
        """c_k(n) (T, K), Q1 diagonal (T, 2K) and Q2 (T,) at model speeds."""
        c = 2.0 * np.cos(omega(self.components, speed) / self.fs_track)
        rk = component_r(self.components, speed, self.fs_track)
        qd, q2 = q_diag(rk, self.q1)
        return c, qd, q2

    def _steady_state(self, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Steady-state [k | S] (G, 2K+1) and P(n|n-1) (G, 2K, 2K) at the grid speeds.

        The table's first fill computes r only around its speeds (a bandwidth solve is a
        few ms a batch, whatever its size); from the second on the speed moves, so r is
        computed over the table's whole range in one batch (each value the same)."""
        if self._fills == 1 and self.table is not None:       # every grid speed's r
            component_r(self.components, self.table.grid.speeds(np.arange(self.table.grid.n)), self.fs_track)
        self._fills += 1
        ks, Ps = [], []
        for i in range(0, len(grid), 1024):
            c, qd, q2 = self._coeffs(grid[i:i + 1024])
            P = riccati_doubling(c, qd, q2, self._n_double)
            ph = P[:, :, 1::2].sum(axis=2)
            S = ph[:, 1::2].sum(axis=1) + q2
            ks.append(np.concatenate([ph / S[:, None], S[:, None]], axis=1))
            Ps.append(P)
        return np.concatenate(ks), np.concatenate(Ps)

    def initial_state(self) -> TrackerState:
        """The state before the first input: P = Q2 I at min_rpm for the exact gains (the
        Riccati recursion starts from it); the table's gains never read P, so with them it is
        I and r needs no bandwidth solve before the first segment of the table does."""
        d = 2 * self.K
        q2 = self._coeffs(np.array([self.min_rpm]))[2] if self.gains == "exact" else np.ones(1)
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

    def next_block_input(self) -> int:
        """Input sample index (counted from the first input) whose arrival completes the
        next causal output block (tracker sample j is input sample j x decimate)."""
        st = self.state
        pending = len(st.pend["rpm"]) if st.pend else 0
        return (st.n_track - pending + self.block - 1) * self.decimate

    def describe(self, rpm: float) -> list[dict]:
        """Per component at speed ``rpm``: frequency, r, -3 dB bandwidth [Hz and %],
        time constant [s] (of the isolated steady-state filter at the tracker rate)."""
        return describe(self.components, model_speed(np.array([rpm]), self.min_rpm), self.fs_track)

    # ---------------------------------------------------------------- process
    def process(self, y, rpm: np.ndarray | SpeedAt) -> TrackerOutput:
        """Track a block: y (T, C) (or (T,) for one channel) at fs_in, rpm (T,) at fs_in.

        ``rpm`` may instead be a function giving the speed at input samples ``i`` (an int
        array, ascending, counted from this call's first sample, within 0..T-1): the
        tracker then asks only for the speeds it reads (one input sample in D, delayed
        by the anti-alias filter; :func:`~.speed_line.delayed_at`), each sample once, in the call it
        comes in, and gives the same outputs as with the array of them all.

        NaN in y is a missing sample of that channel (a lost frame, a gap): see
        docs/order_tracker.md §5.  With ``gains="exact"`` the
        channels must miss the same samples (ValueError otherwise, before any
        state changes): the exact Riccati recursion is shared by the channels."""
        y, rpm = self._checked(y, rpm)
        step = self.piece * self.decimate
        if self.gains == "table" and y.shape[0] > step:
            # pieces of at most ``piece`` tracker samples: the per-sample arrays (P of the
            # smoother: 8 kB a sample at 16 orders) stay bounded for any call; any split
            # gives the same outputs, so the joined pieces are those of one call
            return join_outputs([self._track(*self._prepare(y[a:a + step], piece_of(rpm, a, step)))
                                 for a in range(0, y.shape[0], step)])
        return self._track(*self._prepare(y, rpm))

    def process_blocks(self, y, rpm: np.ndarray | SpeedAt) -> tuple[BlockStats, BlockStats | None]:
        """The causal and the smoothed blocks (None without the smoother) of :meth:`process`:
        the same numbers and the same state after it.  A call without a missing sample,
        without the smoother (a live call), runs the filter, the envelope and the statistics in
        one kernel pass when the kernel has it (:func:`~.blocks.fused_blocks`), without the
        per-sample outputs; with a speed function, all its steps in a few (:class:`~.live.LiveCall`)."""
        y, rpm = self._checked(y, rpm)
        if self._fused_kernel is None or self.lag is not None or y.shape[0] > self.piece * self.decimate:
            out = self.process(y, rpm)
        else:
            if self._live is not None and callable(rpm):      # a live call: live.py, or the way below
                got, rpm = self._live(self, y, rpm)
                if got is not None:
                    return got, None
            n0, yd, rd, miss = self._prepare(y, rpm)
            if miss is None and "miss" not in self.state.pend and yd.shape[0]:
                c, k, _, _ = self._coeffs_gains(rd, None)
                return fused_blocks(self._fused_kernel, self.state, n0, yd, c, k, rd, self), None
            out = self._track(n0, yd, rd, miss)
        return out.blocks, out.smoothed_blocks

    def _checked(self, y, rpm: np.ndarray | SpeedAt) -> tuple[np.ndarray, np.ndarray | SpeedAt]:
        """y as (T, C) float64 and rpm as (T,) float64 (or the function), or ValueError."""
        y = np.asarray(y, dtype=np.float64)
        if y.ndim == 1 and self.C == 1:
            y = y[:, None]
        if y.ndim != 2 or y.shape[1] != self.C:
            raise ValueError(f"y: expected shape (T, {self.C}), got {y.shape}")
        if not callable(rpm):
            rpm = np.asarray(rpm, dtype=np.float64)
            if rpm.shape != (y.shape[0],):
                raise ValueError(f"rpm: expected shape ({y.shape[0]},), got {rpm.shape}")
        return y, rpm

    def _prepare(self, y: np.ndarray, rpm: np.ndarray | SpeedAt):
        """The first steps of :meth:`process`: the call's tracker samples (n0: the first one's
        index; yd (N, C); rd (N,) their speeds), which miss a measurement ((N, C) bool or None)."""
        st = self.state
        gone_in = None
        if y.size and np.isnan(y.min()):               # min() propagates NaN; cheaper than isnan
            gone_in = np.isnan(y)
        miss, last_miss = missing(self, gone_in, y.shape[0])
        if (miss is not None and self.gains == "exact" and self.C > 1
                and (miss != miss[:, :1]).any()):
            raise ValueError("gains='exact': the channels must miss the same samples (the exact "
                             "Riccati recursion is shared by the channels); got NaN in some "
                             "channels only: use gains='table' or one tracker per channel")
        if gone_in is not None:
            y = np.where(gone_in, 0.0, y)                # the anti-alias filter takes zeros
        yd, rd = decimate(self, _trackerkernel, y, rpm)
        st.last_miss = last_miss
        return st.n_track, yd, rd, miss

    def _track(self, n0: int, yd: np.ndarray, rd: np.ndarray, miss: np.ndarray | None) -> TrackerOutput:
        """The rest of :meth:`process`: filter, envelope, blocks, smoother."""
        st = self.state
        N = yd.shape[0]
        index = n0 + np.arange(N)
        t_in = index * self.decimate - self.delay_in
        xf, zp, e, c, k, S, P = self._filter(yd, rd, miss)
        wave = np.ascontiguousarray(xf[:, :, 1::2])
        env = self._envelope(xf, c)
        blocks = causal_blocks(self, n0, wave, env, rd, miss)
        out = TrackerOutput(index=index, t_in=t_in, rpm=rd, waveform=wave, blocks=blocks,
                            missing=miss if miss is not None else np.zeros((N, self.C), dtype=bool))
        if self.lag is not None:
            smooth(self, _trackerkernel, out, self.lag, n0, rd, c, k, S, P, zp, e, miss)
        st.n_track = n0 + N
        return out

    def _envelope(self, xs: np.ndarray, c: np.ndarray) -> np.ndarray:
        """:func:`envelope` (N, C, K) of the states xs (N, C, 2K) at c (N, K): in the compiled
        kernel with the C backend when it has it (the same operations, one pass)."""
        kernel = getattr(_trackerkernel, "envelope", None) if self.backend == "c" else None
        if kernel is None:
            return envelope(xs, c)
        env = np.empty((xs.shape[0], self.C, self.K))
        kernel(np.ascontiguousarray(xs), np.ascontiguousarray(c), env, self.K)
        return env

    def _gains(self, speed, c, gone=None):
        """k (N, 2K), S (N,), P (N, 2K, 2K) or None.  ``gone`` (N,) bool or None: samples
        without a measurement, for the exact gains (k = 0 and no update of P there);
        the table's steady-state gains do not depend on it (the forward and backward
        passes zero k per channel)."""
        want_p = self.lag is not None
        if self.table is not None:          # linear interpolation in the grid coordinate
            return self.table.lookup(speed)
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
        k, S, P, st.P = riccati_numpy(c, qd, q2, st.P, want_p, gone)
        return k, S, P

    def _coeffs_gains(self, rd: np.ndarray, miss: np.ndarray | None):
        """c (N, K) = 2 cos(omega / fs_track) at the model speeds of rd, and the gains there
        (:meth:`_gains`): c, k, S, P."""
        speed, c = self.omegas.scaled(rd, self.min_rpm, self.fs_track, self.backend == "c")
        np.cos(c, out=c)                    # 2 cos(omega / fs_track), in place
        c *= 2.0
        k, S, P = self._gains(speed, c, miss[:, 0] if miss is not None and self.gains == "exact" else None)
        return c, k, S, P

    def _filter(self, yd, rd, miss):
        """miss: (N, C) bool with a True somewhere, or None."""
        st = self.state
        N, d = yd.shape[0], 2 * self.K
        any_miss = miss is not None
        c, k, S, P = self._coeffs_gains(rd, miss)
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
        # numpy: chunks of CHUNK samples aligned to absolute tracker indices.  The
        # chunk cut by the end of the previous call is run again from its start
        # (its inputs are kept in the state), so that every sample is computed
        # exactly as in one pass, however the stream is split.
        # Channels that miss different samples run as separate groups (mask_groups),
        # each with k = 0 at its missing samples and no innovation there (e = 0).
        ch = st.chunk
        p = len(ch["y"]) if ch else 0
        Y = np.concatenate([ch["y"], yd]) if p else yd
        Cc = np.concatenate([ch["c"], c]) if p else c
        Kk = np.concatenate([ch["k"], k]) if p else k
        Mm = cat_miss(ch.get("m") if p else None, p, miss, N, self.C)
        T = len(Y)
        zp = np.empty((T + 1, self.C, d))
        e = np.empty((T, self.C))
        xf = np.empty((T, self.C, d))
        for chans, m in mask_groups(Mm):           # all channels each time, see there
            kg = Kk if m is None else np.where(m[:, None], 0.0, Kk)
            z0 = st.z0
            for i in range(0, T, 8192):  # bounded memory for long calls (8192 = 256 chunks)
                j = min(i + 8192, T)
                zp_i, e_i, xf_i = forward_numpy(Y[i:j], Cc[i:j], kg[i:j], z0)
                if m is not None:
                    e_i[m[i:j]] = 0.0                 # no innovation where missing
                zp[i:j + 1, chans] = zp_i[:, chans]
                e[i:j, chans] = e_i[:, chans]
                xf[i:j, chans] = xf_i[:, chans]
                z0 = zp_i[-1]
        nb = (T // CHUNK) * CHUNK                   # last chunk boundary
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
        E = wave.shape[0]
        kernel = self._stats_kernel
        if (kernel is not None and E and wave.flags.c_contiguous and env.flags.c_contiguous
                and rpm.flags.c_contiguous):        # the same operations in one pass
            rms, amp = np.empty((E, self.C, self.K)), np.empty((E, self.C, self.K))
            rmean, valid = np.empty(E), np.empty(E, dtype=bool)
            kernel(wave, env, rpm, self.K, self.min_rpm, self.top_order, 0.5 * self.fs_track, rms, amp,
                   rmean, valid.view(np.uint8))
        else:
            rms, amp, rmean, valid = self._block_stats_numpy(wave, env, rpm)
        return block_stats(starts, rms, amp, rmean, valid, miss, self.block, self.decimate, self.delay_in)

    def _block_stats_numpy(self, wave, env, rpm):
        """rms, amplitude (E, C, K), mean speed and validity (E,) of whole blocks."""
        return stats_numpy(wave, env, rpm, self.min_rpm, self.top_order, self.fs_track)
