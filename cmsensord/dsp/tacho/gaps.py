"""Edge intervals across lost TACHO frames: how many pulses they hold, or none taken.

The board sends one TACHO frame a block (docs/PROTOCOL.md), so a frame whose t0 lies past
the end of the frame before it leaves a stretch of time no frame covers: frames lost on
the link.  The edges in it are lost with it, and an edge interval across it holds an
unknown number of pulses.  An interval that is no longer than 1 + tol predicted periods
is one pulse (the rule of every interval, docs/tacho.md step 3).  A longer one holds k
pulses only when the speed on both sides says so: k = round(d x (1 / P + 1 / d2) / 2)
with P the predicted period before it and d2 the interval of the next two edges (not
across lost frames either), accepted when d / P and d / d2 are each within ``tol`` of k
(a shaft that kept its speed across the gap).  Otherwise the interval is no measurement:
the run ends where the frames stopped, without ``tacho_lost`` (the link's ``frames_lost``
says it), and the edge after the gap starts a new one, so no speed is fitted across it
(the angle goes on from the next whole pulse, as after a loss).  A gap longer than the
run's timeout ends the run at the timeout before any of this (``tacho_lost``).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from cmsensord.dsp.tacho.edges import SUB, EdgeRuns, IntArray, Run


class LostFrames(EdgeRuns):
    """The part of :class:`~cmsensord.dsp.tacho.TachoTracker` that knows the stretches no
    TACHO frame covers (``_holes``: start, end in 1/256 sample, those after the last
    committed edge) and applies the rule above to an edge interval across one."""

    _holes: deque[tuple[int, int]]

    def _note_holes_array(self, t0: IntArray) -> None:
        """The frames ``t0`` (in time order, after those fed before): the stretches between them."""
        if not t0.size:
            return
        prev = np.empty_like(t0)
        prev[0] = t0[0] if self._last_t0 is None else self._last_t0
        prev[1:] = t0[:-1]
        gap = np.flatnonzero(t0 - prev > self.block_len)
        if gap.size:
            self._add_holes(((prev[gap] + self.block_len) * SUB).tolist(), (t0[gap] * SUB).tolist())

    def _note_holes_list(self, t0: list[int]) -> None:
        """:meth:`_note_holes_array` of a live call's few frames, on Python ints."""
        prev, L = self._last_t0, self.block_len
        starts: list[int] = []
        ends: list[int] = []
        for t in t0:
            if prev is not None and t - prev > L:
                starts.append((prev + L) * SUB)
                ends.append(t * SUB)
            prev = t
        if starts:
            self._add_holes(starts, ends)

    def _add_holes(self, starts: list[int], ends: list[int]) -> None:
        """Keep the stretches [starts, ends); drop those no later interval can span (before the
        last committed edge, or, with no run, before the coverage)."""
        holes = self._holes
        cut = self._cq_last if self._run is not None else None
        if cut is None:
            cut = -1 if self._now is None else self._now * SUB
        while holes and holes[0][1] <= cut:
            holes.popleft()
        holes.extend(zip(starts, ends))
        self._marks.extend(zip(starts, ends))

    def _hole_between(self, a: int, b: int) -> int | None:
        """The start of the first stretch without frames between edges a and b (1/256 sample), or None."""
        for start, end in self._holes:
            if start > a and end <= b:
                return start
        return None

    def _across_gap(self, run: Run, q: int, P: float | None, final: bool) -> bool | None:
        """Edge q, the first pending one, with ``P`` the predicted period (None: none yet): None
        when its interval from the last committed edge spans no lost frames or is no longer
        than 1 + tol periods (the usual repair); else the rule of the module, and whether
        :meth:`_classify` goes on (False: it waits for the next edge, the speed after the gap,
        or a new run took the pending edges)."""
        cq_last = self._cq_last
        if cq_last is None:
            return None
        d = q - cq_last
        if P is not None and not d / P > 1.0 + self.tol:
            return None
        start = self._hole_between(cq_last, q)
        if start is None:
            return None
        pending = self._pending
        if P is not None and len(pending) < 2 and not final:
            return False
        k = 0
        if P is not None and len(pending) >= 2 and self._hole_between(q, pending[1]) is None:
            d2 = pending[1] - q
            k = int(round(0.5 * d * (1.0 / P + 1.0 / d2)))
            if not (k >= 1 and abs(d / P - k) < self.tol and abs(d / d2 - k) < self.tol):
                k = 0
        c = self.counters
        if k:
            pending.popleft()
            c.gap_pulses += k - 1
            self._commit(run, q, k)
        elif final:                                     # the run ends at its timeout: q alone, no speed
            pending.popleft()
            c.gap_breaks += 1
        else:
            self._break_run(run, start)
            return False
        return True

    def _break_run(self, run: Run, start: int) -> None:
        """End ``run`` (the current one) where the frames stopped (``start``, 1/256 sample), no
        event, and start a new run with the pending edges."""
        rest = list(self._pending)
        self._pending.clear()
        known = self._known_q
        assert self._cq_last is not None
        run.last_raw_q = self._cq_last
        self._end_run(run, start, silent=True, known_q=known)
        self.counters.gap_breaks += 1
        self._known_q = known
        self._start_run(rest[0])
        new = self._run
        assert new is not None
        for q in rest[1:]:
            new.prev_prev_raw_q, new.prev_raw_q, new.last_raw_q = new.prev_raw_q, new.last_raw_q, q
            self._pending.append(q)
        if self._pending:
            self._classify(new, final=False)
