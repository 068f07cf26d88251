"""TachoTracker: TACHO frames in, shaft speed and angle at any sample out.

Streaming, with repair of missed and spurious pulses, local least-squares
smoothing of the edge jitter, a causal speed for the order tracker, and final
values that do not depend on how frames are grouped.  The method and its
measured accuracy: docs/tacho.md.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from cmsensord.dsp.tacho.causal import CausalSpeed
from cmsensord.dsp.tacho.edges import (
    PREDICT_INTERVALS,
    SUB,
    FloatArray,
    TachoCounters,
    TachoEvent,
    TachoUpdate,
    _kernel,
)
from cmsensord.dsp.tacho.gaps import LostFrames
from cmsensord.dsp.tacho.smoothing import KnotSmoothing

_FEW_FRAMES = 64  # up to this many frames an update prepares its edges on Python ints
#: knots (and causal segments) kept at most: 60 s of 2184 pulses a second (255 ppr at 514 rpm),
#: 1.3 s of the densest tacho a board sends (1023 edges a block); about 10 MB of buffers
HISTORY_MAX = 1 << 17
#: the longest run timeout [s] (and the longest ``timeout_s``: the configuration's bound)
MAX_TIMEOUT_S = 10


class TachoTracker(LostFrames, KnotSmoothing, CausalSpeed):
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
    history_max : at most this many knots, and as many causal segments, are kept, however
        dense the edges (a bound on memory; None: no bound, for a whole record held offline).
        The default keeps history_s of a tacho up to HISTORY_MAX / history_s pulses a second.
    causal_window : committed edges in the one-sided fit of the causal speed
        (default 16 ppr, within 3..64).

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
                 max_timeout_s: float = MAX_TIMEOUT_S, history_s: float = 60.0,
                 causal_window: int | None = None, history_max: int | None = HISTORY_MAX):
        h, m = _checked(fs, ppr, block_len, half_window, tol, timeout_s, timeout_periods, max_timeout_s,
                        history_s, causal_window)
        if history_max is not None and not (isinstance(history_max, (int, np.integer)) and history_max >= 16):
            raise ValueError(f"history_max must be an integer >= 16 or None, got {history_max!r}")
        self.fs = float(fs)
        self.ppr = int(ppr)
        self.block_len = int(block_len)
        self.half_window = int(h)
        self.tol = float(tol)
        self.timeout_s = float(timeout_s)
        self.timeout_periods = float(timeout_periods)
        self.max_timeout_s = float(max_timeout_s)
        self.history_s = float(history_s)
        self.history_max = None if history_max is None else int(history_max)
        self.causal_window = int(m)
        self._timeout_hi = int(round(self.max_timeout_s * self.fs * SUB))  # 1/256 sample
        self._timeout_lo = int(round(self.timeout_s * self.fs * SUB))
        # tricube weights over the pulse positions k - h .. k + h (docs/tacho.md, step 4)
        u = np.arange(-self.half_window, self.half_window + 1) / (self.half_window + 1)
        self._kernel = (1.0 - np.abs(u) ** 3) ** 3
        self._offsets = np.arange(-self.half_window, self.half_window + 1)
        self._committed_key = None
        self._committed_arrays = None
        self.counters = TachoCounters()
        self._now = None  # coverage end, samples (exclusive)
        self._last_q = None  # last edge received
        self._run = None  # the current (not ended) run
        self._runs = {}
        self._next_rid = 0
        self._held = 0.0  # turns held after the last ended valid run
        self._had_loss = False
        # the current run's committed edges (times in samples, pulse counts), from index _c0
        self._cT = []
        self._cn = []
        self._c0 = 0
        self._cq_last = None  # last committed edge, 1/256 sample
        self._n_last = 0
        self._pending = deque()  # edges of the current run not yet classified
        self._hist = deque(maxlen=PREDICT_INTERVALS)  # (mid q, pulses/q)
        self._holes = deque()  # stretches no TACHO frame covers after the last committed edge
        self._marks = deque()  # the same, not yet in the causal segments
        self._final = 0  # knots finalised in the current run (centres 0 .. _final-1)
        # final knots of all runs: times (samples), turns, speed (turns/sample), run id
        self._kbuf = np.empty((4, 1024))  # rows: time, turns, speed, run id; live columns [_klo, _khi)
        self._klo = 0
        self._khi = 0
        self._prov = None  # provisional knots
        self._events = []
        self._last_t0 = None
        self._prov_key = None
        self._pruned = False
        # causal segments (see "Causal speed"): rows key, T, speed, acceleration, valid
        u = np.arange(self.causal_window) / self.causal_window
        self._ckernel = (1.0 - u ** 3) ** 3          # weight of the edge j places back
        self._cback = np.arange(self.causal_window)  # j: the edges of a causal window
        self._sbuf = np.empty((5, 1024))
        self._slo = 0
        self._shi = 0
        self._seg_todo = []  # (committed index, known at) to fit
        self._known_q = 0                             # the edge (or time) being handled
        self._unsettled = False     # knots to fit before the smoothed speed is read (_settle)
        self._lazy = False          # in feed_flat: the update leaves them

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
        n_ok = self._in_order(t0)
        sizes = np.fromiter((len(e) for e in edges[:n_ok]), dtype=np.int64, count=n_ok)
        full = np.flatnonzero(sizes)
        off = np.concatenate([edges[i] for i in full.tolist()], axis=None).astype(np.int64) if full.size \
            else np.empty(0, dtype=np.int64)
        return self._update(t0, n_ok, sizes, off)

    def update_flat(self, t0_unwrapped: Sequence[int] | np.ndarray, counts: npt.ArrayLike,
                    offsets: npt.ArrayLike) -> TachoUpdate:
        """:meth:`update` with the edges of all frames in one array: ``counts`` (F,) edges per
        frame and ``offsets`` (sum of counts,) their offsets from their frame's t0, frame by
        frame (what :func:`cmsensord.protocol.decode_tacho_many` gives).  The same results as
        :meth:`update` with ``offsets`` split by ``counts``, without a Python object per frame."""
        t0 = np.asarray(t0_unwrapped, dtype=np.int64).reshape(-1)
        counts = np.asarray(counts, dtype=np.int64).reshape(-1)
        off = np.asarray(offsets).reshape(-1).astype(np.int64)
        if counts.size != t0.size or int(counts.sum()) != off.size or (counts < 0).any():
            raise ValueError(f"expected one edge count per frame summing to the offsets: {t0.size} t0 values, "
                             f"{counts.size} counts summing to {int(counts.sum())}, {off.size} offsets")
        n_ok = self._in_order(t0)
        sizes = counts[:n_ok]
        return self._update(t0, n_ok, sizes, off[:int(sizes.sum())])

    def feed_flat(self, t0_unwrapped: Sequence[int] | np.ndarray, counts: npt.ArrayLike,
                  offsets: npt.ArrayLike) -> list[TachoEvent]:
        """:meth:`update_flat` returning only the events: the knots of the smoothed speed are
        fitted when it is next asked for (:meth:`evaluate`, :attr:`final_until`), not now.  The
        same knots, so the same values: the fit of a knot waits for its complete window
        whenever it is made.  For a caller feeding ten times a second that asks for the
        smoothed speed about once a second (the live daemon's Processor): one fit, not ten."""
        self._lazy = True
        try:
            return self.update_flat(t0_unwrapped, counts, offsets).events
        finally:
            self._lazy = False

    def feed_few(self, t0_unwrapped: list[int], counts: list[int], offsets: list[int]) -> list[TachoEvent]:
        """:meth:`feed_flat` of a few frames given as Python lists (a live call's ten or so):
        the same checks and results, on Python ints, without arrays of them; any other case
        (frames out of time order, many frames, offsets not u32) through :meth:`feed_flat`.
        With the compiled kernel (``edge_kernel``), the checks and the edges' lists in one
        step (``edge_lists``: None for the frames that need the checks in Python) and the
        regular edges in another (:meth:`_few_edges`)."""
        lists: tuple[list[int], list[int], int] | None = None
        if _kernel is not None and self.edge_kernel and self.batch_edges:
            lists = _kernel.edge_lists(t0_unwrapped, counts, offsets, self.block_len, self._last_t0, _FEW_FRAMES)
        if lists is None:
            if not self._few_ok(t0_unwrapped, counts, offsets):
                return self.feed_flat(np.asarray(t0_unwrapped, dtype=np.int64), counts,
                                      np.asarray(offsets, dtype=np.int64))      # raises as it does
            if t0_unwrapped:
                lists = self._edge_lists(t0_unwrapped, counts, offsets)
        self._events = []
        if lists is not None:
            q, adv, end = lists
            self._note_holes_list(t0_unwrapped)
            self._take_edges(q, adv, end, t0_unwrapped[-1], one_step=True)
        ev, self._events = self._events, []
        self._unsettled = True          # as _settled in feed_flat: the knots fitted when asked for
        return ev

    def _few_ok(self, t0: list[int], counts: list[int], offsets: list[int]) -> bool:
        """Whether :meth:`feed_few` takes the frames on Python ints: a count >= 0 per frame, the
        counts adding up to the offsets, at most ``_FEW_FRAMES`` frames in time order (after
        those fed before), u32 offsets."""
        if (len(counts) != len(t0) or sum(counts) != len(offsets) or min(counts, default=0) < 0
                or len(t0) > _FEW_FRAMES):
            return False
        prev = self._last_t0
        for t in t0:
            if prev is not None and t < prev:
                return False
            prev = t
        return not (offsets and (min(offsets) < 0 or max(offsets) > 0xFFFFFFFF))

    def _in_order(self, t0: np.ndarray) -> int:
        """How many frames come before the first one stepping back in time."""
        if not t0.size:
            return 0
        prev = np.empty(t0.size, dtype=np.int64)
        prev[0] = t0[0] if self._last_t0 is None else self._last_t0
        prev[1:] = t0[:-1]
        back = np.flatnonzero(t0 < prev)
        return int(back[0]) if back.size else t0.size

    def _update(self, t0: np.ndarray, n_ok: int, sizes: np.ndarray, off: np.ndarray) -> TachoUpdate:
        """The frames t0 (F,), of which the first n_ok are in time order, with ``sizes`` (n_ok,)
        edges each, their offsets ``off`` frame after frame."""
        self._events = []
        F = t0.size
        if F == 0:
            return self._settled([])
        # Frames without edges only advance the coverage, and a timeout check at the
        # end of each of them is the same as one check at the end of the last one
        # before the next edge (the run's timeout changes only with an edge, and the
        # checks see a non-decreasing time).  So: one running maximum of the frame
        # ends, and the frames with edges one by one.
        err, bad_offsets = None, False
        if n_ok < F:
            prev = int(t0[n_ok - 1]) if n_ok else self._last_t0
            err = ValueError(f"TACHO frames must come in time order: t0 {int(t0[n_ok])} after t0 {prev}")
        few = err is None and F <= _FEW_FRAMES
        if not (few and self._few_frames(t0.tolist(), sizes.tolist(), off.tolist())):
            full = np.flatnonzero(sizes)
            ends = np.maximum.accumulate(t0[:n_ok] + self.block_len) if n_ok else t0[:0]
            self._note_holes_array(t0[:n_ok])            # lost frames, before their edges are judged
            if full.size:                                # all edges at once: q in 1/256 sample
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
                first = np.cumsum(sizes[full]) - sizes[full]     # the first edge of each frame
                adv = np.full(q.size, -1, dtype=np.int64)        # the coverage before it: the frames before
                adv[first] = np.where(full > 0, ends[np.maximum(full - 1, 0)], -1)
                self._edges(q[order], adv)
            if n_ok:
                self._advance(int(ends[n_ok - 1]))
                self._last_t0 = int(t0[n_ok - 1])
            if err is not None:
                if bad_offsets:                          # the frame's t0 was taken, as before
                    self._last_t0 = int(t0[n_ok])
                raise err
        ev = self._events
        self._events = []
        return self._settled(ev)

    def _settled(self, events: list[TachoEvent]) -> TachoUpdate:
        """The end of an update: the knots fitted (or, for :meth:`feed_flat`, left to
        :meth:`_settle`), and what the update returns."""
        self._unsettled = True
        if self._lazy:
            return TachoUpdate(events, math.nan, self.valid, self.counters)
        self._settle()
        return TachoUpdate(events, self.final_until, self.valid, self.counters.snapshot())

    def _settle(self) -> None:
        """Fit the knots whose windows the updates since the last call completed, and prune."""
        if self._unsettled:
            self._unsettled = False
            self._finalise(ended=False)
            self._prune()

    def _few_frames(self, t0: list[int], sizes: list[int], off: list[int]) -> bool:
        """What the array code of :meth:`_update` does with frames all in time order, on Python
        ints (a live call brings about ten frames): False, changing nothing, when an offset is
        not u32 (the array code reports it)."""
        if off and (min(off) < 0 or max(off) > 0xFFFFFFFF):
            return False
        self._note_holes_list(t0)
        self._take_edges(*self._edge_lists(t0, sizes, off), t0[-1])
        return True

    def _edge_lists(self, t0: list[int], sizes: list[int], off: list[int]) -> tuple[list[int], list[int], int]:
        """The edges of frames in time order (at least one; ``sizes`` edges each, their offsets
        ``off`` frame after frame): q (1/256 sample, in time order within each frame), the
        coverage end before each (samples: the frames before; -1: none, or not a frame's first
        edge), and the coverage end after them all (``edge_lists`` of the kernel is the same)."""
        L = self.block_len
        q: list[int] = []
        adv: list[int] = []
        pos, end = 0, -1                 # end: the coverage of the frames before (in time order: the last one's)
        for t, n in zip(t0, sizes):
            if n == 1:
                q.append(off[pos] + t * SUB)
                adv.append(end)
                pos += 1
            elif n:
                base = t * SUB
                q += sorted([o + base for o in off[pos:pos + n]])    # time order within the frame
                adv += [end] + [-1] * (n - 1)
                pos += n
            end = t + L
        return q, adv, end

    def _take_edges(self, q: list[int], adv: list[int], end: int, t0_last: int, one_step: bool = False) -> None:
        """The edges of :meth:`_edge_lists`, then the coverage up to ``end`` (the last frame's
        t0 ``t0_last``); ``one_step`` (:meth:`feed_few`): through :meth:`_few_edges`, else
        :meth:`_edges` (the same state)."""
        if q:
            if one_step:
                self._few_edges(q, adv)
            else:
                self._edges(q, adv)             # lists: arrays only for enough edges
        self._advance(end)
        self._last_t0 = t0_last

    # ------------------------------------------------------------------ output
    @property
    def valid(self) -> bool:
        return self._run is not None and self._run.valid

    @property
    def final_until(self) -> float:
        """Sample index (float) below which speed, angle and validity are final."""
        self._settle()
        run = self._run
        if run is None:
            return float(self._now) if self._now is not None else 0.0
        if self._final >= 1:
            return self._cT[self._final - 1 - self._c0]
        return run.first_q / SUB

    @property
    def covered_until(self) -> int:
        """Sample index (exclusive) up to which TACHO frames have been received."""
        return 0 if self._now is None else int(self._now)

    def speed_at(self, samples: npt.ArrayLike) -> FloatArray:
        """Shaft speed in Hz (revolutions per second) at the sample indices."""
        return self.evaluate(samples)[0]


def _checked(fs, ppr, block_len, half_window, tol, timeout_s, timeout_periods, max_timeout_s, history_s,
             causal_window) -> tuple[int, int]:
    """:class:`TachoTracker`'s settings checked (ValueError naming the first one out of range):
    its smoothing half window and causal window, defaults filled in from ``ppr``."""
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
    return int(h), int(m)
