"""The Processor's observations and decisions (a base of
:class:`~cmsensord.monitor.processor.Processor`): observations (RMS values or RAW block RMS) on
the block clock's slots (re-anchored at a jump) -> the microphones' estimator, the AKF banks (or,
live RAW with orders, :mod:`.held` until a decision may be due) -> the decisions whose shaft
speed is final, each after the indicator records and events of its stamp."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from cmsensord.monitor.alarms import Alarms
from cmsensord.monitor.diagnostics import Diagnostics
from cmsensord.monitor.events import Event
from cmsensord.monitor.figures import Stage
from cmsensord.monitor.slots import observation_rows

__all__ = ["Observing", "MAX_RUN_SLOTS"]

#: most observation slots (received or missing) in one call: gaps inside a batch cannot inflate it
#: (twice the most RAW frames of a call, the Processor's ``MAX_BATCH``)
MAX_RUN_SLOTS = 2000
#: most messages of a replay's decisions handed to the sink together (a release may hold thousands)
MAX_RUN_MESSAGES = 256
#: indicator records waiting for the decision of their stamp at most (then written anyway)
MAX_RECORDS = 1000


class Observing(Stage):
    """Observations through the banks, decisions released (see the module docstring)."""

    observe: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None] | None
    diagnostics: Callable[[], dict] | None
    observations: int
    missing_observations: int
    alarms: Alarms
    diag: Diagnostics

    if TYPE_CHECKING:
        def _feed_tacho(self, end: bool = False, before: int | None = None) -> None: ...
        def write_diagnostics(self, stamp_ns: int) -> None: ...

    def _observe(self, t0: np.ndarray, vals: np.ndarray, max_slots: int = MAX_RUN_SLOTS,
                 placed: Callable[[np.ndarray, np.ndarray], None] | None = None,
                 flat: np.ndarray | None = None) -> None:
        """Observations (n, C_board) of the blocks starting at t0 (RAW: with their ``flat`` counts) -> slots
        -> the chain, at most ``max_slots`` slots (received or missing) a call; ``placed`` is first given
        each run of blocks on one time base (before the next re-anchoring)."""
        self._out(self.shaft.check_silent(self.clock, t0))
        while len(t0):
            slots, n = self.clock.place(t0)
            if placed is not None:
                placed(t0[:n], vals[:n])
            a = 0
            while a < n:                        # bounded memory: at most max_slots slots a run
                top = self.clock.next_slot + max_slots
                b = n if slots[n - 1] < top else a + int(np.searchsorted(slots[a:n], top))
                self._run(slots[a:b], vals[a:b], None if flat is None else flat[a:b])
                a = b
            if n == len(t0):
                return
            at = int(t0[n])
            if self.shaft.waits_before(at):     # the speed in front of the jump, on the old anchor
                self._feed_tacho(before=at)
            said = self.clock.jump_words(at)
            self.clock.reanchor(at)
            self.event("config", None, f"{said}: time base re-anchored", self.clock.stamp_ns(at))
            t0, vals, flat = t0[n:], vals[n:], None if flat is None else flat[n:]

    def _run(self, slots: np.ndarray, vals: np.ndarray, flat: np.ndarray | None = None) -> None:
        """Observations (RAW: and flat counts) on their slots -> the banks (or what waits for a decision)."""
        first, sev = self.clock.next_slot, self.setup.severity
        assert sev is not None, "observations before the board's channels are known"
        y, valid = observation_rows(first, slots, vals, sev.index)
        flat = None if flat is None else observation_rows(first, slots, flat, sev.index)[0]
        T = len(y)
        mics, trace = self.setup.microphones, self.cfg.output.akf_trace
        stamps = [self.clock.slot_stamp_ns(first + k) for k in range(T)] if mics or trace else []
        if mics is not None:
            self._out(mics.step(y, valid, stamps))
        if self.observe is not None:
            self.observe(first, y, valid, sev.seen(valid, flat))
        self.clock.advance(T)
        n_valid = int(np.count_nonzero(valid))
        self.observations += n_valid
        self.missing_observations += valid.size - n_valid
        if self._holding(mics is None and not trace):
            self.held.add_rows(first, y, valid, flat)
            self._release_decisions(final=False)
            return
        self._hand_over()
        y, out = sev.observe(first, y, valid, full=trace, flat=flat)
        if out is not None:
            self._out(sev.trace(stamps, y, valid, out))
        self._release_decisions(final=False)

    def _release_decisions(self, final: bool, bounded: bool = False) -> None:
        """Decisions of the slots whose tacho speed is final (f_r: the period's mean speed);
        with ``bounded``, also those waiting longer than the speed gate allows."""
        sev = self.setup.severity
        waiting = self.indicators.records
        if sev is None or len(waiting) > MAX_RECORDS:       # no decision to wait for / bounded
            self._out(self.indicators.take(None if sev is None else waiting[-MAX_RECORDS].stamp_ns))
        if sev is None or not (sev.gate.waiting or self.held.rows):
            return
        tacho = self.cfg.tacho.f_r_from_tacho and self.shaft.tacho is not None
        if tacho and not final and not self.held.decision_due(sev, self.shaft.tracker(), self.clock, bounded):
            return
        self._hand_over()
        upto = self.shaft.final_slot(self.clock) if tacho and not final else self.clock.next_slot
        cfg_f_r = np.array([ch.monitor.f_r for ch in self.channels])
        f_r = (lambda end: self.shaft.period_f_r(self.clock, cfg_f_r, end, sev.decider.period)) if tacho else None
        run: list = []      # a replay's decisions (nothing watching the writes) go out together up to events
        together = self.diagnostics is None and not self.alarms.watching and self.captures is None
        for d in sev.release(upto, final=final, bounded=bounded, f_r=f_r):
            stamp = self.clock.slot_end_ns((sev.start_slot or 0) + d.slot - 1)   # d.slot: from the chain's start
            if run and (sev.notes or self.log.due(stamp)):    # events to write before it
                run = self._out(run)
            if sev.notes:
                self._out([dataclasses.replace(e, stamp_ns=stamp) for e in sev.notes])
                sev.notes.clear()
            self.log.release(stamp)             # events well before it, at a point set by the stream
            out = sev.decision(d, stamp)
            records = sev.mark_no_signal(self.indicators.take(stamp), d)
            run += records + out
            if self.diagnostics is None:        # nothing in it depends on what is written
                run.append(self.diag.message(stamp))
            if not together or len(run) >= MAX_RUN_MESSAGES or Event in map(type, out) \
                    or Event in map(type, records):         # events: to the log first
                run = self._out(run)
            if self.diagnostics is not None:    # the live loop's figures after the writes
                self.write_diagnostics(stamp)
        self._out(run)

    def _holding(self, plain: bool) -> bool:
        """Whether a call's observations wait in :attr:`held` (``plain``: no microphone or AKF
        trace): RAW with orders and the tacho's f_r, no observer or captures, the banks started."""
        sev = self.setup.severity
        return (plain and self.orders is not None and self.observe is None and self.captures is None
                and self.cfg.tacho.f_r_from_tacho and self.shaft.tacho is not None
                and sev is not None and sev.gate.end is not None)
