"""Tacho edges -> instantaneous shaft speed and angle at every sample.

Owns the shaft reference of the order tracker (seed 001 needs the "reference
shaft speed ... to be measured", section 2): the TACHO frames of PROTOCOL.md
carry the rising edges of a shaft encoder with ``ppr`` pulses per revolution,
as u32 offsets from the frame's t0 in 1/256 sample. :class:`TachoTracker`
turns them, streaming, into the speed (Hz, rpm) and the shaft angle (turns)
at any sample index, with a validity flag.

Pipeline, per edge, in time order
---------------------------------
1. **Absolute time.** ``q = 256 * t0_unwrapped + offset`` (int64, 1/256 sample),
   so no rounding ever depends on how frames are grouped.
2. **Runs and loss.** Edges form a *run* while each follows the previous one
   within the timeout ``max(timeout_s, timeout_periods x the longer of the last
   two raw intervals)`` (``max_timeout_s`` after a single edge, whose period is
   unknown). When the timeout passes with no edge the run ends: a valid run
   (>= 2 pulses) emits ``tacho_lost`` at ``last edge + timeout``. A new run
   that becomes valid after a loss emits ``tacho_restored`` at its second
   pulse. The angle across a loss is unknown: the new run starts at the next
   whole pulse after the held angle.
3. **Missed and extra pulses** (repair before smoothing). The next interval
   P is predicted from the last <= 4 committed intervals by a straight-line
   fit of the pulse rate against time, integrated forward (exact for a
   constant acceleration). For an interval d, r = d / P:

   * r within ``tol`` of an integer m >= 2: m - 1 pulses were missed; the
     pulse count advances by m (event ``tacho_missed_pulse``, counter
     ``missed``). Nothing is invented for the fit: only the count changes;
   * r < 1 - ``tol``: if the following edge lies within ``tol`` of P from the
     last committed edge, this edge is spurious and is removed (event
     ``tacho_extra_pulse``, counter ``extra``); deciding needs the next edge
     (one edge of look-ahead);
   * any other r outside 1 +- tol is kept as is and counted ``irregular``.

   The check starts once a run has two committed intervals (a straight-line
   rate needs two points); the first pulses of a run are taken as they come.
4. **Jitter smoothing** (the B&K idea of least-squares fits to edge time vs
   pulse count, done locally, like a Savitzky-Golay filter): for every
   committed edge k, the pulse counts n_j of the edges j = k - h .. k + h of
   its run (``half_window`` h, default 4 ppr: four revolutions each side) are
   fitted by weighted least squares with a quadratic in the edge time,
   n(T) = c0 + c1 x + c2 x^2, x = (T - T_k) / S, tricube weights
   (1 - (|j - k| / (h + 1))^3)^3. The knot of edge k is
   (T_k, turns_k = (n_k + c0) / ppr, speed_k = c1 / (S ppr)): the fitted
   angle and its derivative. A quadratic in time is exact for a constant
   acceleration (n = a t^2 / 2), so a linear run-up is tracked without bias;
   the tapered weights make neighbouring fits agree (less ripple between knots
   than uniform weights, which gave twice the peak error with jitter). Near a
   run's ends the window is one-sided (fewer points; a straight line with two).
5. **Every sample.** Between consecutive knots of a run the speed is the
   linear interpolation of the knot speeds (continuous), and the angle the
   cubic Hermite interpolant of (turns, speed) at both knots (C1, through the
   fitted angles). At the knots the angle's derivative is the speed; between
   them they differ by the disagreement of neighbouring fits (within the
   jitter noise; differentiating the Hermite angle instead would amplify that
   disagreement by 1.5 / period). After the last edge of a run the speed is
   ``min(speed_last, (1 / ppr) / elapsed)`` -- the shaft cannot have turned
   faster than one pulse over the time without an edge -- so it decays to 0
   when the edges stop; the angle is its integral. After the timeout the speed
   is 0 and invalid, the angle held.

Accuracy (board edges, 1/256-sample capture; tests/test_tacho.py): constant
28.66 Hz, ppr 1 and 4: speed error < 3e-6, angle < 1e-5 rev. Close-orders
run-up (0 -> 3000 rpm in 5 s) with 2 samples (std) of edge jitter: above
300 rpm the speed error is at most 0.23 % (ppr 1) / 0.29 % (ppr 4), RMS about
0.05 %, the peak at the kink where the run-up stops (t = 5 s; 0.27 % there
without jitter: a quadratic cannot follow a kink). Whirl (0 -> 7000 rpm in
180 s, jitter 2 samples, periods down to 214 samples): at most 0.43 %.

Delay and chunk invariance
--------------------------
The knot of edge k is final once edge k + h has been committed (or its run has
ended); committing may wait for one more edge (step 3). So the speed and angle
at sample s, between edges k and k + 1, are final once edges up to
k + 1 + h (+ 1) have arrived: a delay of h + 1 to h + 2 pulse periods (with
the default h = 4 ppr: 4 revolutions and one or two pulses; 80 ms at 3000 rpm,
0.8 s at 300 rpm). ``TachoUpdate.final_until``
and :attr:`TachoTracker.final_until` give the sample index up to which values
are final; later samples (up to the coverage) hold provisional values
computed with the one-sided windows. Every decision depends only on the edge
sequence and the covered time, never on how frames are grouped into calls,
so final values are identical for any split of the input (tested).

Causal speed
------------
For the order tracker, which must not wait for the smoothed speed
(:meth:`evaluate_causal`, ``orders.speed: causal``): at every committed edge k
a one-sided weighted least-squares quadratic of pulse count vs edge time over
the last ``causal_window`` committed edges of the run (default 16 revolutions,
at most 64 pulses; tricube weights 1 - (j/M)^3)^3 on the edge j places back)
gives the speed w_k and the acceleration a_k at T_k, and from there the speed
is extrapolated, w_k + a_k (s - T_k) -- exact for a constant acceleration,
like the symmetric fit. When no edge has come for 2.5 pulse periods (a
missed pulse is 2) the speed is capped at 2.5 pulses over the time since
T_k, and after the run's timeout it is 0 and invalid. The segment of edge k
applies from max(T_k, the time of the edge whose arrival committed k) on, so
the value at sample s depends only on the edges at or before s: it is the
same whenever it is asked for, and any split of the frames gives the same
values (tested). Accuracy on the close-orders run-up with 2 samples of edge
jitter, ppr 1, above 800 rpm: at most 0.3 %; it overshoots for about
``causal_window`` pulses after an abrupt change of the acceleration.

Memory is bounded: knots older than ``history_s`` behind the newest are dropped
(queries there return NaN and invalid).

Cost: :meth:`TachoTracker.update` touches only the frames that carry edges
(the others just advance the coverage: one timeout check before the next edge
is the same as one per frame); :meth:`TachoTracker.evaluate` runs its
between-knots loop in the compiled ``cmsensord.dsp._trackerkernel`` when it is
built (the same arithmetic as the numpy path, bit for bit; tested).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, replace
from typing import NamedTuple

import numpy as np

try:  # the compiled loop of evaluate() is optional: numpy is the fallback (same results)
    from cmsensord.dsp import _trackerkernel as _kernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _kernel = None

__all__ = ["TachoEvent", "TachoCounters", "TachoUpdate", "TachoTracker", "tacho_frames_to_arrays",
           "LOST", "RESTORED", "MISSED", "EXTRA"]

SUB = 256  # edge resolution: 1/256 sample (PROTOCOL.md, TACHO)

LOST = "tacho_lost"
RESTORED = "tacho_restored"
MISSED = "tacho_missed_pulse"
EXTRA = "tacho_extra_pulse"

_MAX_MISSED_RUN = 8  # at most this many consecutive pulses repaired as missed
_PREDICT_INTERVALS = 4  # committed intervals behind the predicted next interval
_CAUSAL_SLACK = 2.5  # causal speed: pulse periods without an edge before it is capped (a missed pulse is 2)
_HANKEL = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4]])  # moments s0..s4 -> normal equations


@dataclass(frozen=True)
class TachoEvent:
    """One tacho event: ``kind`` (LOST, RESTORED, MISSED, EXTRA), where (unwrapped
    sample index, float), how many pulses it concerns, and a one-line message."""

    kind: str
    sample: float
    count: int
    message: str


@dataclass
class TachoCounters:
    """Cumulative counters of a tracker."""

    edges: int = 0  # edges received
    pulses: int = 0  # pulses committed (edges kept + pulses inserted for missed ones)
    missed: int = 0  # pulses inserted (missed by the encoder)
    extra: int = 0  # edges removed as spurious
    irregular: int = 0  # intervals outside 1 +- tol of the prediction, not repaired
    out_of_order: int = 0  # edges earlier than one already received (ignored)
    lost: int = 0  # tacho_lost transitions
    restored: int = 0  # tacho_restored transitions

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class TachoUpdate(NamedTuple):
    """What one :meth:`TachoTracker.update` produced."""

    events: list[TachoEvent]
    final_until: float  # values at samples < final_until are final
    valid: bool  # a run with a measured speed is active (at the coverage end)
    counters: TachoCounters


@dataclass
class _Run:
    """One run of edges without a timeout."""

    rid: int
    base: float  # turns at pulse count 0 of the run
    first_q: int  # first edge, 1/256 sample
    last_raw_q: int  # last edge received (also spurious ones), 1/256 sample
    prev_raw_q: int | None = None
    prev_prev_raw_q: int | None = None
    ended: bool = False
    stop: float = math.inf  # samples: last_raw + timeout (set when it ends)
    committed: int = 0  # committed edges
    valid: bool = False  # >= 2 committed edges
    end_turns: float = math.nan  # turns at stop (set when it ends)


class TachoTracker:
    """Streaming tacho processing: edges in, speed and angle at any sample out.

    Parameters
    ----------
    fs : samples per second (25000).
    ppr : tacho pulses per revolution (STATUS ``tacho_ppr``).
    block_len : samples a TACHO frame covers (STATUS ``block_len``).
    half_window : h, edges on each side of the local least-squares fit
        (default 4 ppr: four revolutions each side).
    tol : tolerance on the interval ratio for missed/extra detection (0.25).
    timeout_s, timeout_periods, max_timeout_s : the run timeout
        max(timeout_s, timeout_periods x last interval), capped at max_timeout_s
        (and max_timeout_s after a single edge).
    history_s : seconds of knots kept for queries behind the newest one.

    Use::

        tr = TachoTracker(25000, ppr=1)
        u = tr.update(t0_unwrapped, edges)        # a batch of TACHO frames, in time order
        for ev in u.events: ...                   # tacho_lost / tacho_restored / missed / extra
        s = np.arange(done, int(np.ceil(u.final_until)))   # samples whose values are final
        hz, turns, valid = tr.evaluate(s)
    """

    use_kernel = True  # evaluate() between knots in the compiled kernel when it is built

    def __init__(self, fs: float, ppr: int, *, block_len: int = 250, half_window: int | None = None,
                 tol: float = 0.25, timeout_s: float = 0.5, timeout_periods: float = 3.0,
                 max_timeout_s: float = 10.0, history_s: float = 60.0,
                 causal_window: int | None = None):
        if not (fs > 0 and math.isfinite(fs)):
            raise ValueError(f"fs must be > 0, got {fs!r}")
        if not isinstance(ppr, (int, np.integer)) or not 1 <= ppr <= 255:
            raise ValueError(f"ppr must be an integer 1..255, got {ppr!r}")
        if not isinstance(block_len, (int, np.integer)) or block_len < 1:
            raise ValueError(f"block_len must be a positive integer, got {block_len!r}")
        h = 4 * int(ppr) if half_window is None else half_window
        if not isinstance(h, (int, np.integer)) or h < 1:
            raise ValueError(f"half_window must be an integer >= 1, got {half_window!r}")
        if not 0 < tol < 0.5:
            raise ValueError(f"tol must be in (0, 0.5), got {tol!r}")
        if not (timeout_s > 0 and timeout_periods > 2 and max_timeout_s >= timeout_s):
            raise ValueError("need timeout_s > 0, timeout_periods > 2 (a missed pulse is 2 periods) "
                             f"and max_timeout_s >= timeout_s; got {timeout_s}, {timeout_periods}, "
                             f"{max_timeout_s}")
        if not history_s > 0:
            raise ValueError(f"history_s must be > 0, got {history_s!r}")
        m = min(64, max(3, 16 * int(ppr))) if causal_window is None else causal_window
        if not isinstance(m, (int, np.integer)) or m < 2:
            raise ValueError(f"causal_window must be an integer >= 2, got {causal_window!r}")
        self.fs = float(fs)
        self.ppr = int(ppr)
        self.block_len = int(block_len)
        self.half_window = int(h)
        self.tol = float(tol)
        self.timeout_s = float(timeout_s)
        self.timeout_periods = float(timeout_periods)
        self.max_timeout_s = float(max_timeout_s)
        self.history_s = float(history_s)
        self.causal_window = int(m)
        self._timeout_hi = int(round(self.max_timeout_s * self.fs * SUB))  # 1/256 sample
        self._timeout_lo = int(round(self.timeout_s * self.fs * SUB))
        # tricube weights over the pulse positions k - h .. k + h (module notes, step 4)
        u = np.arange(-self.half_window, self.half_window + 1) / (self.half_window + 1)
        self._kernel = (1.0 - np.abs(u) ** 3) ** 3
        self._offsets = np.arange(-self.half_window, self.half_window + 1)
        self._committed_key: tuple | None = None
        self._committed_arrays: tuple[np.ndarray, np.ndarray] | None = None
        self.counters = TachoCounters()
        self._now: int | None = None  # coverage end, samples (exclusive)
        self._last_q: int | None = None  # last edge received
        self._run: _Run | None = None  # the current (not ended) run
        self._runs: dict[int, _Run] = {}
        self._next_rid = 0
        self._held = 0.0  # turns held after the last ended valid run
        self._had_loss = False
        # the current run's committed edges (times in samples, pulse counts), from index _c0
        self._cT: list[float] = []
        self._cn: list[int] = []
        self._c0 = 0
        self._cq_last: int | None = None  # last committed edge, 1/256 sample
        self._n_last = 0
        self._pending: deque[int] = deque()  # edges of the current run not yet classified
        self._hist: deque[tuple[float, float]] = deque(maxlen=_PREDICT_INTERVALS)  # (mid q, pulses/q)
        self._final = 0  # knots finalised in the current run (centres 0 .. _final-1)
        # final knots of all runs: times (samples), turns, speed (turns/sample), run id
        self._kbuf = np.empty((4, 1024))  # rows: time, turns, speed, run id; live columns [_klo, _khi)
        self._klo = 0
        self._khi = 0
        self._prov: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # provisional knots
        self._events: list[TachoEvent] = []
        self._last_t0: int | None = None
        self._prov_key: tuple | None = None
        self._pruned = False
        # causal segments (see "Causal speed"): rows key, T, speed, acceleration, valid
        u = np.arange(self.causal_window) / self.causal_window
        self._ckernel = (1.0 - u ** 3) ** 3          # weight of the edge j places back
        self._sbuf = np.empty((5, 1024))
        self._slo = 0
        self._shi = 0
        self._seg_todo: list[tuple[int, float]] = []  # (committed index, known at) to fit
        self._known_q = 0                             # the edge (or time) being handled

    # ------------------------------------------------------------------ input
    def update(self, t0_unwrapped: Sequence[int] | np.ndarray,
               edges: Sequence[Sequence[int] | np.ndarray]) -> TachoUpdate:
        """Feed TACHO frames: their unwrapped t0 (F,) and their edge offsets (F arrays, 1/256 sample).

        Frames must come in time order; each covers [t0, t0 + block_len). Returns
        the events of this call, the finality horizon, the validity and the counters.
        """
        t0 = np.asarray(t0_unwrapped, dtype=np.int64).reshape(-1)
        if len(edges) != t0.size:
            raise ValueError(f"expected one edge array per frame: {t0.size} t0 values, {len(edges)} edge arrays")
        self._events = []
        F = t0.size
        if F == 0:
            self._finalise(ended=False)
            self._prune()
            return TachoUpdate([], self.final_until, self.valid, replace(self.counters))
        # Frames without edges only advance the coverage, and a timeout check at the
        # end of each of them is the same as one check at the end of the last one
        # before the next edge (the run's timeout changes only with an edge, and the
        # checks see a non-decreasing time).  So: one running maximum of the frame
        # ends, and the frames with edges one by one.
        prev = np.empty(F, dtype=np.int64)
        prev[0] = t0[0] if self._last_t0 is None else self._last_t0
        prev[1:] = t0[:-1]
        back = np.flatnonzero(t0 < prev)
        n_ok = int(back[0]) if back.size else F      # frames before the first error
        err, bad_offsets = None, False
        if back.size:
            err = ValueError(f"TACHO frames must come in time order: t0 {int(t0[n_ok])} after "
                             f"t0 {int(prev[n_ok])}")
        sizes = np.fromiter((len(e) for e in edges[:n_ok]), dtype=np.int64, count=n_ok)
        full = np.flatnonzero(sizes)
        if full.size:                                # all edges at once: q in 1/256 sample
            off = np.concatenate([edges[i] for i in full.tolist()], axis=None).astype(np.int64)
            frame = np.repeat(full, sizes[full])
            out = (off < 0) | (off > 0xFFFFFFFF)     # u32 offsets, else an error at that frame
            if out.any():
                f_bad = int(frame[int(np.argmax(out))])
                o = off[frame == f_bad]
                err = ValueError(f"edge offsets must be u32, got {o.min()}..{o.max()}")
                bad_offsets = True
                n_ok = f_bad
                off, frame = off[frame < f_bad], frame[frame < f_bad]
                full = full[full < f_bad]
            q = off + t0[frame] * SUB
            order = np.lexsort((q, frame))           # time order within each frame
            qs = q[order].tolist()
            stop = np.cumsum(sizes[full]).tolist()
        ends = np.maximum.accumulate(t0[:n_ok] + self.block_len) if n_ok else t0[:0]
        k = 0
        for i, e in zip(full.tolist(), stop if full.size else ()):
            if i > 0:
                self._advance(int(ends[i - 1]))
            for j in range(k, e):
                self._edge(qs[j])
            k = e
        if n_ok:
            self._advance(int(ends[n_ok - 1]))
            self._last_t0 = int(t0[n_ok - 1])
        if err is not None:
            if bad_offsets:                          # the frame's t0 was taken, as before
                self._last_t0 = int(t0[n_ok])
            raise err
        self._finalise(ended=False)
        self._prune()
        ev = self._events
        self._events = []
        return TachoUpdate(ev, self.final_until, self.valid, replace(self.counters))

    def _advance(self, end: int) -> None:
        """The frames so far cover up to ``end`` (exclusive): coverage and timeout check."""
        self._now = end if self._now is None else max(self._now, end)
        self._check_timeout(self._now * SUB)

    def update_frames(self, frames: Iterable, chan: int = 0) -> TachoUpdate:
        """Feed decoded :class:`cmsensord.protocol.Frame` objects (TACHO frames of input ``chan``; others ignored)."""
        t0, edges = tacho_frames_to_arrays(frames, chan)
        return self.update(t0, edges)

    # ------------------------------------------------------------------ output
    @property
    def valid(self) -> bool:
        return self._run is not None and self._run.valid

    @property
    def final_until(self) -> float:
        """Sample index (float) below which speed, angle and validity are final."""
        run = self._run
        if run is None:
            return float(self._now) if self._now is not None else 0.0
        if self._final >= 1:
            return self._cT[self._final - 1 - self._c0]
        return run.first_q / SUB

    def evaluate(self, samples) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(speed in Hz, angle in turns, valid) at unwrapped sample indices (any shape, int or float).

        The angle counts revolutions since the first edge (turns 0 there).
        Before the first edge, after a loss and behind the kept history the
        speed is 0 and invalid (NaN behind the history); see the module notes.
        """
        s = np.asarray(samples, dtype=np.float64)
        flat = s.reshape(-1)
        if flat.size:
            kT, kth, kw, kr = self._knots(float(flat.min()), float(flat.max()))
        else:
            kT, kth, kw, kr = self._knots()
        if kT.size == 0:
            return (np.zeros(s.shape), np.full(s.shape, self._held), np.zeros(s.shape, dtype=bool))
        if _kernel is not None and self.use_kernel:
            # between knots in C (one pass, no temporaries; 0 elsewhere), the rest below
            speed = np.empty(flat.size)
            turns = np.empty(flat.size)
            jj = np.empty(flat.size, dtype=np.int64)
            code = np.empty(flat.size, dtype=np.uint8)
            _kernel.tacho_eval(np.ascontiguousarray(flat), np.ascontiguousarray(kT),
                               np.ascontiguousarray(kth), np.ascontiguousarray(kw),
                               np.ascontiguousarray(kr, dtype=np.int64), speed, turns, jj, code)
            valid = code == 1
            before = code == 0
            tail = code == 2
        else:
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
            tail = (~before) & (~inner)
        if tail.any():
            a = jj[tail]
            rids, inv = np.unique(kr[a], return_inverse=True)
            stops = np.array([self._stop_of(int(r)) for r in rids])[inv.reshape(-1)]
            tau = flat[tail] - kT[a]
            w0 = kw[a]
            c = 1.0 / self.ppr
            tau_stop = stops - kT[a]
            ok = tau < tau_stop
            tq = np.where(ok, tau, tau_stop)
            sp, dturn = self._tail(w0, tq, c)
            turns[tail] = kth[a] + dturn
            speed[tail] = np.where(ok, sp, 0.0)
            valid[tail] = ok
        if before.any() and self._pruned:  # behind the kept history: unknown
            turns[before] = np.nan
            speed[before] = np.nan
        return (speed.reshape(s.shape) * self.fs, turns.reshape(s.shape), valid.reshape(s.shape))

    def speed_at(self, samples) -> np.ndarray:
        """Shaft speed in Hz (revolutions per second) at the sample indices."""
        return self.evaluate(samples)[0]

    def rpm_at(self, samples) -> np.ndarray:
        """Shaft speed in rpm at the sample indices."""
        return 60.0 * self.evaluate(samples)[0]

    def turns_at(self, samples) -> np.ndarray:
        """Shaft angle in revolutions since the first edge at the sample indices."""
        return self.evaluate(samples)[1]

    def valid_at(self, samples) -> np.ndarray:
        """True where the speed is measured (inside a run or before its timeout)."""
        return self.evaluate(samples)[2]

    # ------------------------------------------------------------------ machinery
    def _stop_of(self, rid: int) -> float:
        """End of the valid extrapolation of run ``rid`` (samples): its timeout."""
        run = self._runs.get(rid)
        if run is None:
            return math.inf
        if run.ended:
            return run.stop
        return (run.last_raw_q + self._timeout_q(run)) / SUB

    @staticmethod
    def _tail(w0: np.ndarray, tau: np.ndarray, c: float) -> tuple[np.ndarray, np.ndarray]:
        """Speed min(w0, c / tau) after the last edge and its integral from 0 to tau."""
        with np.errstate(divide="ignore", invalid="ignore"):
            tc = np.where(w0 > 0, c / np.where(w0 > 0, w0, 1.0), np.inf)
            slow = tau > tc
            sp = np.where(slow, c / np.where(slow, tau, 1.0), w0)
            dturn = np.where(slow, c + c * np.log(np.where(slow, tau / tc, 1.0)), w0 * tau)
        return sp, dturn

    def _timeout_q(self, run: _Run) -> int:
        """The current run's timeout in 1/256 sample (integer arithmetic: deterministic)."""
        hi = self._timeout_hi
        if run.prev_raw_q is None:
            return hi
        d = run.last_raw_q - run.prev_raw_q
        if run.prev_prev_raw_q is not None:
            d = max(d, run.prev_raw_q - run.prev_prev_raw_q)
        return min(hi, max(self._timeout_lo, int(math.ceil(self.timeout_periods * d))))

    def _check_timeout(self, q_now: int) -> None:
        """End the current run if no edge came within its timeout before q_now (exclusive)."""
        run = self._run
        if run is None:
            return
        stop_q = run.last_raw_q + self._timeout_q(run)
        if q_now > stop_q:
            self._end_run(stop_q)

    def _edge(self, q: int) -> None:
        c = self.counters
        c.edges += 1
        if self._last_q is not None and q <= self._last_q:
            c.out_of_order += 1     # earlier than, or a duplicate of, an edge already received
            return
        self._last_q = q
        self._known_q = q
        self._check_timeout(q)
        run = self._run
        if run is None:
            self._start_run(q)
            return
        run.prev_prev_raw_q, run.prev_raw_q, run.last_raw_q = run.prev_raw_q, run.last_raw_q, q
        self._pending.append(q)
        self._classify(final=False)

    def _start_run(self, q: int) -> None:
        base = 0.0
        if self._runs or self._khi:
            base = (math.floor(self._held * self.ppr + 1e-9) + 1) / self.ppr
        run = _Run(rid=self._next_rid, base=base, first_q=q, last_raw_q=q)
        self._next_rid += 1
        self._run = run
        self._runs[run.rid] = run
        self._cT, self._cn, self._c0 = [], [], 0
        self._pending.clear()
        self._hist.clear()
        self._final = 0
        self._n_last = 0
        self._cq_last = None
        self._commit(q, 0)

    def _commit(self, q: int, npulses: int) -> None:
        """Commit edge q as ``npulses`` pulses after the previous committed edge."""
        run = self._run
        if self._cq_last is not None:
            d = q - self._cq_last
            self._hist.append((self._cq_last + 0.5 * d, npulses / d))
        self._n_last += npulses
        self._cT.append(q / SUB)
        self._cn.append(self._n_last)
        self._cq_last = q
        run.committed += 1
        self._seg_todo.append((self._c0 + len(self._cT) - 1, self._known_q / SUB))
        self.counters.pulses += 1 if run.committed == 1 else npulses
        if run.committed == 2 and not run.valid:
            run.valid = True
            if self._had_loss:
                self._had_loss = False
                self.counters.restored += 1
                self._events.append(TachoEvent(RESTORED, q / SUB, 1,
                                               f"tacho restored at sample {q / SUB:.0f}: edges again"))

    def _predict(self) -> float | None:
        """Predicted next interval (1/256 sample) after the last committed edge, or None."""
        hist = self._hist
        n = len(hist)
        if n < 2:
            return None
        t_ref = hist[-1][0]
        xs = [h[0] - t_ref for h in hist]
        rt = [h[1] for h in hist]
        xm, ym = sum(xs) / n, sum(rt) / n
        sxx = sum((x - xm) ** 2 for x in xs)
        slope = sum((x - xm) * (r - ym) for x, r in zip(xs, rt)) / sxx if sxx > 0 else 0.0
        r0 = ym + slope * (self._cq_last - t_ref - xm)  # pulse rate at the last committed edge
        d_last = 1.0 / rt[-1]
        disc = r0 * r0 + 2.0 * slope
        if r0 <= 0 or disc <= 0:
            return d_last
        d = 2.0 / (r0 + math.sqrt(disc))  # solves slope/2 d^2 + r0 d = 1 pulse
        return min(max(d, 0.5 * d_last), 2.0 * d_last)

    def _classify(self, final: bool) -> None:
        """Commit (or drop) pending edges; waits for one look-ahead edge unless ``final``."""
        tol = self.tol
        c = self.counters
        while self._pending:
            q = self._pending[0]
            P = self._predict()
            if P is None:
                self._pending.popleft()
                self._commit(q, 1)
                continue
            d = q - self._cq_last
            r = d / P
            if r < 1.0 - tol:
                if len(self._pending) < 2:
                    if not final:
                        return  # wait for the next edge
                    self._pending.popleft()
                    c.irregular += 1
                    self._commit(q, 1)
                    continue
                r2 = (self._pending[1] - self._cq_last) / P
                self._pending.popleft()
                if abs(r2 - 1.0) < tol:
                    c.extra += 1
                    self._events.append(TachoEvent(EXTRA, q / SUB, 1,
                                                   f"spurious tacho pulse removed at sample {q / SUB:.1f}"))
                    continue
                c.irregular += 1
                self._commit(q, 1)
                continue
            self._pending.popleft()
            m = int(round(r))
            if r > 1.0 + tol and 2 <= m <= _MAX_MISSED_RUN and abs(r - m) < tol:
                c.missed += m - 1
                self._events.append(TachoEvent(
                    MISSED, (self._cq_last + d / m) / SUB, m - 1,
                    f"{m - 1} missed tacho pulse(s) inserted after sample {self._cq_last / SUB:.1f}"))
                self._commit(q, m)
                continue
            if r > 1.0 + tol:
                c.irregular += 1
            self._commit(q, 1)

    def _end_run(self, stop_q: int) -> None:
        run = self._run
        self._known_q = stop_q
        self._classify(final=True)
        run.ended = True
        run.stop = stop_q / SUB
        self._flush_segments()
        self._append_segments(np.array([run.stop]), np.array([run.stop]), np.zeros(1), np.zeros(1),
                              np.zeros(1))
        self._finalise(ended=True)
        self._prov = None
        if run.valid:
            # the angle at the stop, from the tail of the last knot
            T_last, th_last, w_last, _ = self._kbuf[:, self._khi - 1]  # the run's last knot
            _, dturn = self._tail(np.array([w_last]), np.array([run.stop - T_last]), 1.0 / self.ppr)
            run.end_turns = float(th_last + dturn[0])
            self._held = run.end_turns
            self._had_loss = True
            self.counters.lost += 1
            self._events.append(TachoEvent(LOST, run.stop, 1,
                                           f"tacho lost at sample {run.stop:.0f}: no edge for "
                                           f"{(stop_q - run.last_raw_q) / SUB / self.fs:.3g} s"))
        else:
            # a single edge: no speed; the angle stays where it was
            self._runs.pop(run.rid, None)
        self._run = None
        self._pending.clear()

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
        T, th, w = self._fit(np.arange(self._final, last + 1), K)
        self._append_knots(T, th, w, run.rid)
        self._final = last + 1
        # committed edges no longer needed by any future window (smoothing or causal)
        drop = min(self._final - h, K - self.causal_window) - self._c0
        if drop > 256:
            del self._cT[:drop]
            del self._cn[:drop]
            self._c0 += drop

    def _fit(self, centres: np.ndarray, K: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Local least-squares quadratic of pulse count vs edge time at each centre (see module notes).

        Windows [k - h, k + h] clipped to the committed edges [0, K) of the run.
        Returns the knot times (samples), angles (turns) and speeds (turns/sample).
        """
        h = self.half_window
        Tc, nc = self._committed()
        c0 = self._c0
        lo = np.maximum(centres - h, 0)
        hi = np.minimum(centres + h, K - 1)
        idx = centres[:, None] + self._offsets[None, :]
        use = (idx >= lo[:, None]) & (idx <= hi[:, None])
        idx = np.where(use, idx, centres[:, None]) - c0
        k = centres - c0
        dx = np.where(use, Tc[idx] - Tc[k][:, None], 0.0)
        S = np.abs(dx).max(axis=1)
        x = dx / S[:, None]
        y = np.where(use, nc[idx] - nc[k][:, None], 0.0)
        wgt = use * self._kernel[None, :]
        npts = use.sum(axis=1)
        x2 = x * x
        wx, wx2 = wgt * x, wgt * x2
        # the weighted moments s0..s4 and right-hand sides b0..b2 (each a sum over its
        # window, the same products as written out term by term), in one reduction
        mom = np.stack([wgt, wx, wx2, wx2 * x, wx2 * x2, wgt * y, wx * y, wx2 * y], axis=1).sum(axis=2)
        A = mom[:, _HANKEL]                  # [[s0 s1 s2] [s1 s2 s3] [s2 s3 s4]]
        b = mom[:, 5:]
        lin = npts < 3  # two points: a straight line
        if lin.any():
            A[lin, 2, :] = 0.0
            A[lin, :, 2] = 0.0
            A[lin, 2, 2] = 1.0
            b[lin, 2] = 0.0
        coef = np.linalg.solve(A, b[..., None])[..., 0]
        run = self._run
        T = Tc[k]
        th = run.base + (nc[k] + coef[:, 0]) / self.ppr
        w = coef[:, 1] / (S * self.ppr)
        return T, th, w

    def _flush_segments(self) -> None:
        """Fit the causal segments of the edges committed since the last call (see
        "Causal speed"): a one-sided weighted quadratic over the last ``causal_window``
        committed edges of the run at each, vectorised over the new edges."""
        todo = self._seg_todo
        if not todo:
            return
        self._seg_todo = []
        Tc, nc = self._committed()
        c0 = self._c0
        k = np.fromiter((t[0] for t in todo), dtype=np.int64, count=len(todo))
        known = np.fromiter((t[1] for t in todo), dtype=np.float64, count=len(todo))
        idx = k[:, None] - np.arange(self.causal_window)[None, :]
        use = idx >= c0
        idx = np.where(use, idx, k[:, None]) - c0
        kr = k - c0
        dx = np.where(use, Tc[idx] - Tc[kr][:, None], 0.0)
        S = np.abs(dx).max(axis=1)
        S = np.where(S > 0, S, 1.0)
        x = dx / S[:, None]
        y = np.where(use, nc[idx] - nc[kr][:, None], 0.0)
        wgt = use * self._ckernel[None, :]
        npts = use.sum(axis=1)
        x2 = x * x
        wx, wx2 = wgt * x, wgt * x2
        mom = np.stack([wgt, wx, wx2, wx2 * x, wx2 * x2, wgt * y, wx * y, wx2 * y], axis=1).sum(axis=2)
        A = mom[:, _HANKEL]
        b = mom[:, 5:]
        lin = npts < 3                       # two points: a straight line; one: no speed
        if lin.any():
            A[lin, 2, :] = 0.0
            A[lin, :, 2] = 0.0
            A[lin, 2, 2] = 1.0
            b[lin, 2] = 0.0
        one = npts < 2
        if one.any():
            A[one] = np.eye(3)
            b[one] = 0.0
        coef = np.linalg.solve(A, b[..., None])[..., 0]
        speed = coef[:, 1] / (S * self.ppr)
        acc = 2.0 * coef[:, 2] / (S * S * self.ppr)
        self._append_segments(np.maximum(known, Tc[kr]), Tc[kr], speed, acc,
                              (~one).astype(np.float64))

    def _append_segments(self, key, T, speed, acc, valid) -> None:
        n = key.size
        buf = self._sbuf
        if self._shi + n > buf.shape[1]:
            live = self._shi - self._slo
            cap = buf.shape[1]
            while live + n > cap // 2:
                cap *= 2
            new = np.empty((5, cap))
            new[:, :live] = buf[:, self._slo:self._shi]
            self._sbuf, self._slo, self._shi = new, 0, live
            buf = new
        for row, v in enumerate((key, T, speed, acc, valid)):
            buf[row, self._shi:self._shi + n] = v
        self._shi += n

    @property
    def covered_until(self) -> int:
        """Sample index (exclusive) up to which TACHO frames have been received."""
        return 0 if self._now is None else int(self._now)

    def evaluate_causal(self, samples) -> tuple[np.ndarray, np.ndarray]:
        """(speed in Hz, valid) at sample indices from the edges up to each sample only.

        See "Causal speed" in the module notes: the value at sample s depends only on
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
        jj = np.clip(j, 0, None) + self._slo
        T, w, a, v = (self._sbuf[r, jj] for r in (1, 2, 3, 4))
        sp, valid = self._causal_speed(flat - T, w, a, v, before)
        return (sp * self.fs).reshape(s.shape), valid.reshape(s.shape)

    def causal_range(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
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
        # sample s is in segment k when keys[k] <= s < keys[k + 1]: cut at ceil(keys)
        cuts = np.clip(np.ceil(keys[first + 1:b + 1]), start, stop).astype(np.int64) if b > first else \
            np.empty(0, dtype=np.int64)
        if a < 0:       # samples before the first segment
            head = int(min(max(np.ceil(keys[0]), start), stop)) - start
        else:
            head = 0
        edges = np.concatenate(([start + head], cuts, [stop]))
        counts = np.diff(edges)
        seg = np.arange(first, first + counts.size) + lo
        x = np.arange(start + head, stop, dtype=np.float64)
        T, w, acc, v = (np.repeat(self._sbuf[r, seg], counts) for r in (1, 2, 3, 4))
        sp, valid = self._causal_speed(x - T, w, acc, v, np.zeros(x.size, dtype=bool))
        if head:
            sp = np.concatenate((np.full(head, np.nan if self._pruned else 0.0), sp))
            valid = np.concatenate((np.zeros(head, dtype=bool), valid))
        return sp * self.fs, valid

    def _causal_speed(self, tau, w, a, v, before) -> tuple[np.ndarray, np.ndarray]:
        """Speed (turns/sample) and validity tau samples after a segment's edge (notes)."""
        sp = w + a * tau
        with np.errstate(divide="ignore", invalid="ignore"):
            late = tau * w > _CAUSAL_SLACK / self.ppr   # edges overdue: the shaft slows
            cap = np.where(late, (_CAUSAL_SLACK / self.ppr) / np.where(late, tau, 1.0), np.inf)
        sp = np.clip(np.minimum(sp, cap), 0.0, None)
        valid = (v > 0) & (sp > 0) & ~before
        sp = np.where(valid, sp, 0.0)
        if before.any() and self._pruned:
            sp[before] = np.nan
        return sp, valid

    def _committed(self) -> tuple[np.ndarray, np.ndarray]:
        """The current run's committed edge times and pulse counts as arrays (cached
        while they do not change: one conversion per update for both fits)."""
        key = (self._run.rid if self._run is not None else None, self._c0, len(self._cT))
        if key != self._committed_key:
            self._committed_arrays = (np.asarray(self._cT), np.asarray(self._cn, dtype=np.float64))
            self._committed_key = key
        return self._committed_arrays

    def _provisional(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Knots of the current run beyond the final ones (one-sided windows), fitted when queried."""
        run = self._run
        if run is None:
            return None
        K = self._c0 + len(self._cT)
        if K < 2 or self._final >= K:
            return None
        key = (run.rid, K, self._final)
        if key != self._prov_key:
            self._prov = self._fit(np.arange(self._final, K), K)
            self._prov_key = key
        return self._prov

    def _append_knots(self, T: np.ndarray, th: np.ndarray, w: np.ndarray, rid: int) -> None:
        n = T.size
        buf = self._kbuf
        if self._khi + n > buf.shape[1]:  # compact, then grow (amortised O(1) per knot)
            live = self._khi - self._klo
            cap = buf.shape[1]
            while live + n > cap // 2:
                cap *= 2
            new = np.empty((4, cap))
            new[:, :live] = buf[:, self._klo:self._khi]
            self._kbuf, self._klo, self._khi = new, 0, live
            buf = new
        buf[0, self._khi:self._khi + n] = T
        buf[1, self._khi:self._khi + n] = th
        buf[2, self._khi:self._khi + n] = w
        buf[3, self._khi:self._khi + n] = rid
        self._khi += n

    def _knots(self, t_min: float = -math.inf, t_max: float = math.inf
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Final knots (those around [t_min, t_max]) then the provisional ones: T, turns, speed, run id."""
        T = self._kbuf[0, self._klo:self._khi]
        a = max(int(np.searchsorted(T, t_min, side="right")) - 1, 0)
        b = min(int(np.searchsorted(T, t_max, side="right")) + 1, T.size)
        k = self._kbuf[:, self._klo + a:self._klo + b]
        kT, kth, kw, kr = k[0], k[1], k[2], k[3].astype(np.int64)
        if b < T.size:
            return kT, kth, kw, kr
        prov = self._provisional()
        if prov is None:
            return kT, kth, kw, kr
        pT, pth, pw = prov
        rid = np.full(pT.size, self._run.rid, dtype=np.int64)
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


def tacho_frames_to_arrays(frames: Iterable, chan: int = 0) -> tuple[np.ndarray, list[np.ndarray]]:
    """(t0_unwrapped (F,), [edge offsets]) of the TACHO frames of input ``chan`` among ``frames``."""
    from cmsensord.protocol import FrameType, decode_tacho

    t0: list[int] = []
    edges: list[np.ndarray] = []
    for f in frames:
        if f.type == FrameType.TACHO and f.chan == chan:
            t0.append(f.t0_unwrapped)
            edges.append(decode_tacho(f.payload))
    return np.asarray(t0, dtype=np.int64), edges
