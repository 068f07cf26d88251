"""Tacho edges and their repair: absolute edge times, runs, loss, missed and extra pulses.

Steps 1-3 of docs/tacho.md: each edge becomes an absolute time in 1/256 sample;
edges form runs that end at a timeout (``tacho_lost``, ``tacho_restored``); an
interval that is a whole multiple of the predicted one counts missed pulses, a
short one followed by a regular one is a spurious edge and is removed; a long one
across lost frames follows :mod:`cmsensord.dsp.tacho.gaps`.  The
committed edges feed the smoothing and the causal speed.  Also the event and
counter types of :class:`~cmsensord.dsp.tacho.TachoTracker`, and
:class:`TachoState`, the state its parts share.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import asdict, dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from cmsensord.dsp.tacho.regular import MARGIN, MIN_EDGES, RegularState, regular_prefix

try:  # the compiled step of a live call's regular edges is optional: the Python path gives the same
    from cmsensord.dsp import _trackerkernel as _kernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _kernel = None

SUB = 256  # edge resolution: 1/256 sample (docs/PROTOCOL.md, TACHO)

LOST = "tacho_lost"
RESTORED = "tacho_restored"
MISSED = "tacho_missed_pulse"
EXTRA = "tacho_extra_pulse"

_MAX_MISSED_RUN = 8  # at most this many consecutive pulses repaired as missed
PREDICT_INTERVALS = 4  # committed intervals behind the predicted next interval
#: edges the first pass of regular ones looks ahead (doubled while they all are regular)
SPAN_START = 256
#: edges the first step of the compiled kernel is handed (doubled while they all are regular)
FEW_SPAN_START = 16


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
    gap_pulses: int = 0  # pulses counted in lost TACHO frames (the speed before and after says how many)
    gap_breaks: int = 0  # intervals across lost TACHO frames not taken (their pulses unknown): a new run after

    def as_dict(self) -> dict[str, int]:
        return asdict(self)

    def snapshot(self) -> TachoCounters:
        """A copy (what dataclasses.replace gives, without its per-field work: every update)."""
        return TachoCounters(**vars(self))


class TachoUpdate(NamedTuple):
    """What one :meth:`TachoTracker.update` produced."""

    events: list[TachoEvent]
    final_until: float  # values at samples < final_until are final
    valid: bool  # a run with a measured speed is active (at the coverage end)
    counters: TachoCounters


@dataclass
class Run:
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


FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


class TachoState(ABC):
    """The state shared by the parts of :class:`~cmsensord.dsp.tacho.TachoTracker`
    (:class:`EdgeRuns`, :class:`~cmsensord.dsp.tacho.smoothing.KnotSmoothing`,
    :class:`~cmsensord.dsp.tacho.causal.CausalSpeed`): the attributes its
    ``__init__`` sets and the methods one part calls on another."""

    # configuration
    fs: float
    ppr: int
    block_len: int
    half_window: int
    tol: float
    timeout_s: float
    timeout_periods: float
    max_timeout_s: float
    history_s: float
    history_max: int | None  # knots (and causal segments) kept at most; None: no bound
    causal_window: int
    use_kernel: bool
    _timeout_hi: int  # 1/256 sample
    _timeout_lo: int
    _kernel: FloatArray  # tricube weights of the smoothing window
    _offsets: npt.NDArray[np.signedinteger]  # pulse positions -h .. h of the window
    _ckernel: FloatArray  # weights of the causal window
    _cback: IntArray  # 0 .. causal_window - 1
    # coverage, runs and events
    counters: TachoCounters
    _now: int | None  # coverage end, samples (exclusive)
    _last_q: int | None  # last edge received
    _last_t0: int | None
    _run: Run | None  # the current (not ended) run
    _runs: dict[int, Run]
    _next_rid: int
    _held: float  # turns held after the last ended valid run
    _had_loss: bool
    _events: list[TachoEvent]
    _known_q: int  # the edge (or time) being handled
    # the current run's committed edges (times in samples, pulse counts), from index _c0
    _cT: list[float]
    _cn: list[int]
    _c0: int
    _cq_last: int | None  # last committed edge, 1/256 sample
    _n_last: int
    _committed_key: tuple[int | None, int, int] | None
    _committed_arrays: tuple[FloatArray, FloatArray] | None
    _pending: deque[int]  # edges of the current run not yet classified
    _hist: deque[tuple[float, float]]  # (mid q, pulses/q)
    _holes: deque[tuple[int, int]]  # stretches no TACHO frame covers (lost frames), 1/256 sample
    _marks: deque[tuple[int, int]]  # the same, for the causal speed (a segment each once the edges pass it)
    # knots: finalised ones of all runs (rows time, turns, speed, run id; live columns
    # [_klo, _khi)), the provisional ones of the current run
    _final: int
    _kbuf: FloatArray
    _klo: int
    _khi: int
    _prov: tuple[FloatArray, FloatArray, FloatArray] | None
    _prov_key: tuple[int, int, int] | None
    _pruned: bool
    # causal segments: rows key, T, speed, acceleration, valid; live columns [_slo, _shi)
    _sbuf: FloatArray
    _slo: int
    _shi: int
    _seg_todo: list[tuple[int, float]]  # (committed index, known at) to fit

    @abstractmethod
    def _committed(self) -> tuple[FloatArray, FloatArray]:
        """The current run's committed edge times and pulse counts (:class:`EdgeRuns`)."""

    @abstractmethod
    def _timeout_q(self, run: Run) -> int:
        """The run's timeout in 1/256 sample (:class:`EdgeRuns`)."""

    @abstractmethod
    def _finalise(self, ended: bool) -> None:
        """Fit the knots whose windows are complete (``KnotSmoothing``)."""

    @abstractmethod
    def _settle(self) -> None:
        """Fit the knots the updates since the last call left to fit (``TachoTracker``)."""

    @staticmethod
    @abstractmethod
    def _tail(w0: FloatArray, tau: FloatArray, c: float) -> tuple[FloatArray, FloatArray]:
        """Speed after a run's last edge and its integral (``KnotSmoothing``)."""

    @abstractmethod
    def _across_gap(self, run: Run, q: int, P: float | None, final: bool) -> bool | None:
        """Pending edge q across lost frames (``LostFrames``): None when not, else whether the
        classification goes on."""

    @abstractmethod
    def _flush_segments(self, upto: int | None = None) -> None:
        """Fit the causal segments of the newly committed edges (``CausalSpeed``)."""

    @abstractmethod
    def _append_segments(self, key: FloatArray, T: FloatArray, speed: FloatArray, acc: FloatArray,
                         valid: FloatArray) -> None:
        """Append causal segments (``CausalSpeed``)."""


class EdgeRuns(TachoState):
    """The edge part of :class:`~cmsensord.dsp.tacho.TachoTracker`: coverage and
    timeouts, runs, the look-ahead classification of each edge and its commitment
    as pulses.  ``batch_edges`` False: every edge by the edge-by-edge path (the reference
    that the one-pass path for regular edges equals)."""

    batch_edges = True
    edge_kernel = True  # a live call's regular edges in one compiled step when the kernel is built

    def _advance(self, end: int) -> None:
        """The frames so far cover up to ``end`` (exclusive): coverage and timeout check."""
        now = self._now
        if now is None or end > now:
            self._now = now = end
        self._check_timeout(now * SUB)

    def _timeout_q(self, run: Run) -> int:
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
        if run is None or q_now <= run.last_raw_q + self._timeout_lo:    # the timeout is at least _timeout_lo
            return
        stop_q = run.last_raw_q + self._timeout_q(run)
        if q_now > stop_q:
            self._end_run(run, stop_q)

    def _edges(self, q: IntArray | list[int], adv: IntArray | list[int]) -> None:
        """The edges q (1/256 sample) in arrival order, each after advancing the coverage to
        adv (samples; -1: no advance before it), as :meth:`_advance` and :meth:`_edge` one
        after the other would; runs of regular edges are committed in one pass
        (:mod:`cmsensord.dsp.tacho.regular`), the rest edge by edge.  Each pass looks at most
        ``span`` edges ahead (``SPAN_START``, doubled while every edge it looked at was regular),
        so edges that are not regular (noise on the tacho line: a thousand a block) cost a
        bounded pass each, not one over all the edges still to come.  q and adv: arrays or
        Python lists (a live call's few edges: arrays only when there are enough for the pass)."""
        ql = q if isinstance(q, list) else q.tolist()
        al = adv if isinstance(adv, list) else adv.tolist()
        j, m = 0, len(ql)
        qa: IntArray | None = None
        aa: IntArray | None = None
        span = SPAN_START
        while j < m:
            n_scalar = 1
            st = self._regular_state() if self.batch_edges and m - j >= MIN_EDGES else None
            if st is not None:
                if qa is None or aa is None:
                    qa, aa = np.asarray(q, dtype=np.int64), np.asarray(adv, dtype=np.int64)
                now = self._now if self._now is not None else 0
                a = aa[j:j + span]
                adv_q = np.where(a >= 0, np.maximum(a, now) * SUB, -1)
                k = regular_prefix(st, qa[j:j + span], adv_q, self.tol, self.timeout_periods, self._timeout_lo,
                                   self._timeout_hi)
                span = 2 * span if k == a.size else SPAN_START     # a pass costs what it commits, or SPAN_START
                if k:
                    self._commit_regular(qa[j:j + k], a[:k])
                    j += k
                else:
                    n_scalar = MIN_EDGES            # not worth trying again at once
            for i in range(j, min(m, j + n_scalar)):
                self._one_edge(ql[i], al[i])
            j += n_scalar

    def _one_edge(self, q: int, adv: int) -> None:
        """Edge ``q`` after the coverage reached ``adv`` (-1: no advance): in one step when the
        repair simply commits it (:meth:`_regular_edge`), else :meth:`_advance` and :meth:`_edge`."""
        if not (self.batch_edges and self._regular_edge(q, adv)):
            if adv >= 0:
                self._advance(adv)
            self._edge(q)

    def _few_edges(self, q: list[int], adv: list[int]) -> None:
        """:meth:`_edges` of a live call's few edges (Python lists): with the compiled kernel,
        each stretch of regular edges in one step (:meth:`_regular_run`), the edge that stops
        it as :meth:`_edges` takes it; without the kernel (or ``edge_kernel`` False),
        :meth:`_edges`.  The same state after it either way.  Each step is handed at most
        ``span`` edges (``FEW_SPAN_START``, doubled while it commits them all): the kernel
        checks every edge it is handed, so edges that are not regular cost a bounded step
        each, not one over all the edges still to come."""
        if _kernel is None or not (self.edge_kernel and self.batch_edges):
            self._edges(q, adv)
            return
        j, m = 0, len(q)
        span = FEW_SPAN_START
        while j < m:
            n = min(span, m - j)
            k = self._regular_run(q, adv, 0) if n == m else self._regular_run(q[j:j + n], adv[j:j + n], 0)
            j += k
            if k == n:
                span *= 2
                continue
            span = FEW_SPAN_START
            self._one_edge(q[j], adv[j])
            j += 1

    def _regular_run(self, q: list[int], adv: list[int], j: int) -> int:
        """:meth:`_regular_edge` of the edges q[j], q[j + 1], ... as long as each is regular,
        in one call of the compiled ``regular_edges`` (the same checks and arithmetic; a ratio
        within ``MARGIN`` of 1 +- tol stops it, leaving that edge to the Python path): how
        many edges it committed."""
        run = self._run
        last, cq_last, now = self._last_q, self._cq_last, self._now
        if (run is None or last is None or cq_last is None or now is None or self._pending
                or len(self._hist) < 2 or run.prev_raw_q is None or run.prev_prev_raw_q is None):
            return 0
        k, self._now, pp, p, q_last = _kernel.regular_edges(
            q, adv, j, self._hist, self._cT, self._cn, self._seg_todo, run.prev_prev_raw_q, run.prev_raw_q,
            run.last_raw_q, last, cq_last, now, self._n_last, self._c0 + len(self._cT), self.tol,
            self.timeout_periods, self._timeout_lo, self._timeout_hi, MARGIN)
        if k:
            run.prev_prev_raw_q, run.prev_raw_q, run.last_raw_q = pp, p, q_last
            run.committed += k
            self._n_last += k
            self._cq_last = self._last_q = self._known_q = q_last
            c = self.counters
            c.edges += k
            c.pulses += k
        return k

    def _regular_edge(self, q: int, adv: int) -> bool:
        """:meth:`_advance` (``adv`` >= 0) and :meth:`_edge` of edge q in one step when the
        repair simply commits it as one pulse: the run goes on (no timeout at the coverage
        or at q), q is after the last edge received, nothing is pending, and its interval
        ratio to the prediction is within 1 +- tol.  The same checks and arithmetic, so the
        same state after it; False, having changed nothing, for any other edge (a live
        call's few edges go one by one: this saves the calls of the general path)."""
        run = self._run
        last, cq_last, now = self._last_q, self._cq_last, self._now
        if (run is None or last is None or q <= last or cq_last is None or now is None or self._pending
                or len(self._hist) < 2):
            return False
        stop_q = run.last_raw_q + self._timeout_q(run)      # EdgeRuns._check_timeout's, before the edge
        if adv >= 0 and adv > now:
            now = adv
        if now * SUB > stop_q or q > stop_q:
            return False
        P = self._predict()
        if P is None or not P > 0:
            return False
        r = (q - cq_last) / P                               # _classify's ratio
        if not 1.0 - self.tol <= r <= 1.0 + self.tol:
            return False
        self._now = now
        self.counters.edges += 1
        self._last_q = self._known_q = q
        run.prev_prev_raw_q, run.prev_raw_q, run.last_raw_q = run.prev_raw_q, run.last_raw_q, q
        self._commit(run, q, 1)
        return True

    def _regular_state(self) -> RegularState | None:
        """The state :func:`~cmsensord.dsp.tacho.regular.regular_prefix` starts from, or None
        when the run is not in the steady state it assumes (a full history, nothing pending)."""
        run = self._run
        if (run is None or self._pending or len(self._hist) < PREDICT_INTERVALS or self._now is None
                or run.prev_prev_raw_q is None or run.prev_raw_q is None or run.committed < 2
                or self._cq_last != run.last_raw_q):
            return None
        mid, rate = zip(*self._hist)
        return RegularState(list(mid), list(rate), (run.prev_prev_raw_q, run.prev_raw_q, run.last_raw_q))

    def _commit_regular(self, q: IntArray, adv: IntArray) -> None:
        """Edges q that :func:`~cmsensord.dsp.tacho.regular.regular_prefix` found regular:
        what :meth:`_advance` and :meth:`_edge` do for each, done once for all."""
        run = self._run
        assert run is not None and self._cq_last is not None
        m = q.size
        ql = q.tolist()
        if (adv >= 0).any() and self._now is not None:
            self._now = max(self._now, int(adv.max()))
        d = np.diff(q, prepend=self._cq_last)
        prev = np.concatenate(([self._cq_last], q[:-1]))
        self._hist.extend(zip((prev + 0.5 * d).tolist(), (1.0 / d).tolist()))
        T = (q / SUB).tolist()
        i0 = self._c0 + len(self._cT)
        self._cT.extend(T)
        self._cn.extend(range(self._n_last + 1, self._n_last + m + 1))
        self._n_last += m
        self._seg_todo.extend(zip(range(i0, i0 + m), T))
        raw = [run.prev_prev_raw_q, run.prev_raw_q, run.last_raw_q] + ql
        run.prev_prev_raw_q, run.prev_raw_q, run.last_raw_q = raw[-3:]
        run.committed += m
        self._cq_last = self._last_q = self._known_q = ql[-1]
        self.counters.edges += m
        self.counters.pulses += m

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
        self._classify(run, final=False)

    def _start_run(self, q: int) -> None:
        base = 0.0
        if self._runs or self._khi:
            base = (math.floor(self._held * self.ppr + 1e-9) + 1) / self.ppr
        run = Run(rid=self._next_rid, base=base, first_q=q, last_raw_q=q)
        self._next_rid += 1
        self._run = run
        self._runs[run.rid] = run
        self._cT, self._cn, self._c0 = [], [], 0
        self._pending.clear()
        self._hist.clear()
        self._final = 0
        self._n_last = 0
        self._cq_last = None
        self._commit(run, q, 0)

    def _commit(self, run: Run, q: int, npulses: int) -> None:
        """Commit edge q of ``run`` (the current one) as ``npulses`` pulses after the
        previous committed edge."""
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
        cq_last = self._cq_last
        if n < 2 or cq_last is None:  # two intervals imply a committed edge
            return None
        t_ref = hist[-1][0]
        xs = [h[0] - t_ref for h in hist]
        rt = [h[1] for h in hist]
        xm, ym = sum(xs) / n, sum(rt) / n
        sxx = sum([(x - xm) ** 2 for x in xs])          # lists: the values sum() adds, sooner
        slope = sum([(x - xm) * (r - ym) for x, r in zip(xs, rt)]) / sxx if sxx > 0 else 0.0
        r0 = ym + slope * (cq_last - t_ref - xm)  # pulse rate at the last committed edge
        d_last = 1.0 / rt[-1]
        disc = r0 * r0 + 2.0 * slope
        if r0 <= 0 or disc <= 0:
            return d_last
        d = 2.0 / (r0 + math.sqrt(disc))  # solves slope/2 d^2 + r0 d = 1 pulse
        return min(max(d, 0.5 * d_last), 2.0 * d_last)

    def _classify(self, run: Run, final: bool) -> None:
        """Commit (or drop) pending edges of ``run`` (the current one); waits for one
        look-ahead edge unless ``final``."""
        tol = self.tol
        c = self.counters
        while self._pending:
            q = self._pending[0]
            P = self._predict()
            cq_last = self._cq_last
            across = self._across_gap(run, q, P, final) if self._holes else None
            if across is not None:      # an interval across lost frames (gaps.py)
                if across:
                    continue
                return
            if P is None or cq_last is None:  # a prediction implies a committed edge
                self._pending.popleft()
                self._commit(run, q, 1)
                continue
            d = q - cq_last
            r = d / P
            if r < 1.0 - tol:
                if len(self._pending) < 2:
                    if not final:
                        return  # wait for the next edge
                    self._pending.popleft()
                    c.irregular += 1
                    self._commit(run, q, 1)
                    continue
                r2 = (self._pending[1] - cq_last) / P
                self._pending.popleft()
                if abs(r2 - 1.0) < tol:
                    c.extra += 1
                    self._events.append(TachoEvent(EXTRA, q / SUB, 1,
                                                   f"spurious tacho pulse removed at sample {q / SUB:.1f}"))
                    continue
                c.irregular += 1
                self._commit(run, q, 1)
                continue
            self._pending.popleft()
            m = int(round(r))
            if r > 1.0 + tol and 2 <= m <= _MAX_MISSED_RUN and abs(r - m) < tol:
                c.missed += m - 1
                self._events.append(TachoEvent(
                    MISSED, (cq_last + d / m) / SUB, m - 1,
                    f"{m - 1} missed tacho pulse(s) inserted after sample {cq_last / SUB:.1f}"))
                self._commit(run, q, m)
                continue
            if r > 1.0 + tol:
                c.irregular += 1
            self._commit(run, q, 1)

    def _end_run(self, run: Run, stop_q: int, silent: bool = False, known_q: int | None = None) -> None:
        """End ``run`` (the current one) at its timeout ``stop_q`` (1/256 sample); ``silent``:
        where lost frames began (``LostFrames``), no ``tacho_lost`` (the link said it), its
        causal speed 0 from ``known_q`` on, where that was decided (default: ``stop_q``)."""
        key_q = stop_q if known_q is None else known_q
        self._known_q = key_q
        self._classify(run, final=True)
        run.ended = True
        run.stop = stop_q / SUB
        self._flush_segments(key_q)
        key = np.array([key_q / SUB])
        self._append_segments(key, key, np.zeros(1), np.zeros(1), np.zeros(1))
        self._finalise(ended=True)
        self._prov = None
        if run.valid:
            # the angle at the stop, from the tail of the last knot
            T_last, th_last, w_last, _ = self._kbuf[:, self._khi - 1]  # the run's last knot
            _, dturn = self._tail(np.array([w_last]), np.array([run.stop - T_last]), 1.0 / self.ppr)
            run.end_turns = float(th_last + dturn[0])
            self._held = run.end_turns
            if not silent:
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

    def _committed(self) -> tuple[FloatArray, FloatArray]:
        """The current run's committed edge times and pulse counts as arrays (cached
        while they do not change: one conversion per update for both fits)."""
        key = (self._run.rid if self._run is not None else None, self._c0, len(self._cT))
        arrays = self._committed_arrays
        if key != self._committed_key or arrays is None:
            arrays = (np.asarray(self._cT, dtype=np.float64), np.asarray(self._cn, dtype=np.float64))
            self._committed_arrays = arrays
            self._committed_key = key
        return arrays

