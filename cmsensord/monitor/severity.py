"""The severity chain of Kim et al. 2023: an AKF bank per channel, outlier counts, decisions.

Per observation slot the channels' banks (:class:`~cmsensord.dsp.akf.AkfBank`,
eqs. 3-15) flag outliers; the flags wait in a :class:`SpeedGate` while the
decision's f_r may come from the tacho, then the decider
(:class:`~cmsensord.dsp.severity.AnomalyDecider`, Fig. 3, eqs. 16-18) makes one
decision per period.  A decision becomes a ``/cm/<channel>/severity`` message
per channel and the events of what changed (anomaly onset/clear, severity
change, failure), and updates the channels' :class:`ChannelView`.

With a commissioned baseline the banks watch block RMS / baseline, and the
combined severity (``monitor.severity``) also grades the period's level against
it (:func:`~cmsensord.dsp.severity.level_severity`); its severity messages then
carry ``severity_akf``, ``severity_level``, ``level_ratio`` and the channel's ``level_alert`` and
``level_danger``.

A decision with no signal (:class:`~cmsensord.dsp.severity.Decision` ``no_signal``: its level
below ``monitor.signal_floor`` of the baseline, or, RAW with ``monitor.flat_signal``, blocks
whose samples are all one ADC count) carries ``signal_lost: true`` in its message, and its
change is a ``signal_lost`` or ``signal_back`` event naming why.  With ``monitor.flat_signal``
a flat block goes to the banks as no observation (it says nothing about the machine), and the
event says for how many board seconds the blocks were flat, each block at the rate it came at
(a STATUS can change the rate inside a decision).
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from cmsensord.config import NOMINAL_RATE_HZ, ChannelConfig
from cmsensord.config.settings import MAX_DECISION_PERIOD_S, decision_period_for
from cmsensord.dsp.akf import AkfBank, AkfBlock, bank_r
from cmsensord.dsp.severity import HOLD_EVENT_DECISIONS, NOT_LOOKED, AnomalyDecider, Decision
from cmsensord.monitor import messages
from cmsensord.monitor.events import Event
from cmsensord.monitor.speed_gate import SpeedGate
from cmsensord.monitor.timeline import SeverityTimeline
from cmsensord.protocol import COUNT_MAX
from cmsensord.sinks.schemas import severity_topic

#: observation slots whose decisions may wait for a final tacho speed (5 s at 100 Hz)
PENDING_DECISION_SLOTS = 500
#: a block rate within this fraction of the nominal 100 Hz gets no ``decision_rule`` note (an
#: import at 20480 Hz in blocks of 205: 99.9 blocks/s, its counts within 0.1 % of the paper's times)
RATE_NOTE_TOLERANCE = 0.01
#: the newest restarts and absences a channel's view keeps for the exit summary (a board whose
#: channel count goes up and down for months keeps the count of the older ones only)
KEPT_SPANS = 5


@dataclass
class ChannelView:
    """Per-channel figures for the status line and the exit summary: the latest decision's, and
    the counts, maximum and timeline of every decision of the run on the channel's name (a new
    chain made for a new set of channels takes over the view of each name it keeps), and when
    the channel was not in the board's stream (:class:`~cmsensord.monitor.channels.ChannelSetup`
    keeps those)."""

    name: str
    severity: float = 0.0
    max_severity: float = 0.0
    anomaly: list[int] = field(default_factory=list)
    outliers_first: int = 0       # outliers in the last period of the most sensitive AKF
    decisions: int = 0
    judged: int = 0               # decisions after the filters' transient
    failures: int = 0
    no_signal: bool = False       # the last decision had no signal: its severity is held
    timeline: SeverityTimeline = field(default_factory=SeverityTimeline)
    restarts: list[float] = field(default_factory=list)   # ADC seconds where its filters started afresh
    left_s: float | None = None   # the ADC second it left the board's stream (None: in it)
    absences: list[tuple[float, float]] = field(default_factory=list)   # (left, back) ADC seconds, ended ones
    restarts_before: int = 0      # restarts older than the newest KEPT_SPANS, counted only
    absences_before: int = 0      # absences older than the newest KEPT_SPANS, counted only

    def restarted(self, t_s: float) -> None:
        """Its filters started afresh at ADC second ``t_s`` (the newest :data:`KEPT_SPANS` kept)."""
        self.restarts.append(t_s)
        if len(self.restarts) > KEPT_SPANS:
            del self.restarts[0]
            self.restarts_before += 1

    def came_back(self, t_s: float) -> None:
        """Its channel is in the board's stream again at ADC second ``t_s``, since :attr:`left_s`
        (the newest :data:`KEPT_SPANS` absences kept)."""
        if self.left_s is not None:
            self.absences.append((self.left_s, t_s))
            self.left_s = None
        if len(self.absences) > KEPT_SPANS:
            del self.absences[0]
            self.absences_before += 1


class SeverityChain:
    """Banks, decider and views of the monitored ``channels`` (see module docstring)."""

    def __init__(self, channels: tuple[ChannelConfig, ...], *, fs: int, block_len: int,
                 trace_filter: int):
        self.channels = channels
        mons = [ch.monitor for ch in channels]
        n = mons[0].n                   # the same for every channel (config rule)
        self.R = np.stack([bank_r(m.r_min, m.r_max, m.n) for m in mons])
        self.bank = AkfBank(self.R, window=[m.window for m in mons], z_c=[m.z_c for m in mons],
                            p0=[m.p0 for m in mons], q0=[m.q0 for m in mons])
        period = max(1, round(mons[0].decision_period_s * fs / block_len))
        combined = [m.combined for m in mons]
        self.baseline = np.array([m.baseline or 1.0 for m in mons])   # the bank watches y / baseline
        self.combined = np.array(combined) if any(combined) else None  # severity also grades the level
        self.decider = AnomalyDecider(
            len(channels), n, f_r=[m.f_r for m in mons], c=[m.c for m in mons], period=period,
            level_alert=[m.level_alert for m in mons] if any(combined) else None,
            level_danger=[m.level_danger for m in mons], signal_floor=[m.signal_floor for m in mons],
            flat_signal=[m.flat_signal for m in mons] if any(m.flat_signal for m in mons) else None)
        self.index = np.array([ch.index for ch in channels])     # board column of each channel
        self.views = [ChannelView(name=ch.name, anomaly=[0] * n) for ch in channels]
        self.trace_i = min(trace_filter, n) - 1
        self.gate = SpeedGate(PENDING_DECISION_SLOTS)   # (outlier, valid[, level ratio]) per slot
        self.rate = fs / block_len
        #: (the chain slot a rate took over at, its board second, the rate), oldest first: the rates
        #: of the decision in progress's slots on
        self._rates: list[tuple[int, float, float]] = [(0, 0.0, self.rate)]
        self.start_slot: int | None = None      # the block clock's slot of this chain's first observation
        self._start_s = 0.0
        #: the run's ADC seconds before a block clock slot (the clock's, each rate's stretch at its rate)
        self.adc_at: Callable[[int], float] = lambda slot: slot / self.rate
        self.cfg_f_r = np.array([m.f_r for m in mons])
        self.notes: list[Event] = self._rate_notes(fs, block_len)  # events for the processor to emit
        self._tacho_too_fast = np.zeros(len(channels), dtype=bool)
        self.no_signal = [False] * len(channels)   # the last decision had no signal (held)
        self.flat_said = [False] * len(channels)   # a flat_blocks event said since a decision without
        # what every severity message of a channel repeats: its name, topic and the bank's R
        self._names = [ch.name for ch in channels]
        self._topics = [severity_topic(ch.name) for ch in channels]
        self._r_rows = self.R.tolist()

    def _rate_notes(self, fs: int, block_len: int) -> list[Event]:
        """What the decision rule means at this block rate, when it is more than
        :data:`RATE_NOTE_TOLERANCE` from the nominal one (its counts of observations then stand
        for other times than the paper's), and channels whose f_r no decision can reach."""
        period, mon = self.decider.nominal_period, self.channels[0].monitor
        notes = []
        if abs(self.rate - NOMINAL_RATE_HZ) > RATE_NOTE_TOLERANCE * NOMINAL_RATE_HZ:
            notes.append(Event("decision_rule", None, (
                f"board block rate {self.rate:.4g} blocks/s (fs {fs} / block {block_len}), not "
                f"{NOMINAL_RATE_HZ:g}: a decision is {period} observations ({period / self.rate:.3g} s); "
                f"f_r {mon.f_r:.4g} is {mon.f_r / period:.0%} of them; the window N = {mon.window} "
                f"observations is {mon.window / self.rate:.3g} s")))
        for ch, f_r in zip(self.channels, self.cfg_f_r):
            if f_r >= period:
                notes.append(Event("decision_rule", ch.name, (
                    f"{ch.name}: f_r {f_r:.4g} >= the {period} observations per decision at "
                    f"{self.rate:.4g} blocks/s: no decision can flag an anomaly (set f_r below {period})")))
        return notes

    def set_rate(self, fs: int, block_len: int) -> None:
        """The board's block rate changed (its decisions are all out): a decision is
        ``decision_period_s`` of the new rate's observations from the period in progress on
        (:meth:`AnomalyDecider.set_period`), told in :attr:`notes` as at the start."""
        slot = self.decider.slot
        seconds = self._seconds(slot)
        first = bisect.bisect_right(self._rates, slot - self.decider.phase, key=lambda r: r[0]) - 1
        self.rate = fs / block_len
        self._rates = [*self._rates[max(first, 0):], (slot, seconds, self.rate)]
        self.decider.set_period(max(1, round(self.channels[0].monitor.decision_period_s * self.rate)))
        self.notes += self._rate_notes(fs, block_len)

    def _seconds(self, slot: int) -> float:
        """The board seconds of the chain's first ``slot`` slots (a slot of the decision in
        progress or later)."""
        start, seconds, rate = self._rates[max(0, bisect.bisect_right(self._rates, slot, key=lambda r: r[0]) - 1)]
        return seconds + (slot - start) / rate

    def _slots_seconds(self, slots: np.ndarray) -> float:
        """The board seconds of the chain slots ``slots`` (of the decision just made or later),
        each at the rate its block came at."""
        starts = np.array([r[0] for r in self._rates])
        rates = np.array([r[2] for r in self._rates])
        return float((1.0 / rates[np.maximum(np.searchsorted(starts, slots, side="right") - 1, 0)]).sum())

    def checked_f_r(self, f_r: np.ndarray) -> np.ndarray:
        """The tacho's f_r, or the configured one where the tacho's is not below the observations
        per decision (an event when that starts and when it ends)."""
        period = self.decider.period
        fast = f_r >= period
        for c in np.flatnonzero(fast != self._tacho_too_fast):
            name = self.channels[c].name
            msg = (f"{name}: tacho f_r {f_r[c]:.4g} Hz >= the {period} observations per decision: "
                   f"using the configured f_r {self.cfg_f_r[c]:.4g}; {self._longer_decision(f_r[c])}" if fast[c] else
                   f"{name}: tacho f_r {f_r[c]:.4g} Hz below the {period} observations per decision again")
            self.notes.append(Event("decision_rule", name, msg))
        self._tacho_too_fast = fast
        return np.where(fast, self.cfg_f_r, f_r)

    def _longer_decision(self, f_r: float) -> str:
        """The ``decision_period_s`` whose decisions at this block rate outnumber a tacho's ``f_r``
        [Hz], and the speeds it takes; or that none up to the longest does."""
        longer = decision_period_for(f_r, self.rate)
        if longer is None:
            return (f"no decision_period_s up to {MAX_DECISION_PERIOD_S:g} fits a machine this fast (f_r below "
                    f"{MAX_DECISION_PERIOD_S * self.rate:.4g} Hz)")
        top = round(longer * self.rate)
        return (f"for a machine this fast give a longer decision: monitor: {{decision_period_s: {longer}}} "
                f"in --config (the tacho's f_r below {top} Hz, {60 * top:,} rpm)")

    def observe(self, first_slot: int, y: np.ndarray, valid: np.ndarray, full: bool = False,
                flat: np.ndarray | None = None) -> tuple[np.ndarray, AkfBlock | None]:
        """Observations (T, C) of slots first_slot.. / baseline through the banks; their flags
        (and level ratios, combined severity; the counts of flat RAW blocks, NaN where they move
        or none were looked at) wait. Returns what the banks watched, and with ``full`` their
        every output (for the AKF trace; else None: only the flags are formed)."""
        y = y / self.baseline
        out = None
        flat_on = self.decider.flat_signal
        seen = self.seen(valid, flat)
        if full:
            out = self.bank.process(y, seen)
            outlier = out.outlier
        else:
            outlier = self.bank.outliers(y, seen)[0]
        if self.gate.end is None:
            self.gate.restart(first_slot)
        if self.start_slot is None:
            self.start_slot = first_slot
            self._start_s = self.adc_at(first_slot)  # the run's ADC seconds at the chain's start
        rows = [outlier, valid]
        if flat_on is not None:
            rows.append(np.full(y.shape, NOT_LOOKED) if flat is None else flat)
        if self.combined is not None:
            rows.append(np.where(self.combined & seen, y, np.nan))
        self.gate.push(*rows)
        return y, out

    def release(self, upto: int, *, final: bool, bounded: bool,
                f_r: Callable[[int], np.ndarray] | None) -> list[Decision]:
        """Decisions of the slots before ``upto`` (see :meth:`SpeedGate.release`); ``f_r(end)``
        gives the f_r of the period ending at slot ``end`` (None: the configured f_r)."""
        got = self.gate.release(upto, final=final, bounded=bounded)
        if got is None:
            return []
        first, (outl, valid, *rest) = got
        d = self.decider
        flat = rest.pop(0) if d.flat_signal is not None else None
        level = rest[0] if rest else None
        n = outl.shape[0]
        if f_r is None:                         # the configured f_r: every period in one call
            return d.update(outl, valid, level=level, flat=flat)
        decisions = []
        pos = 0
        while pos < n:                          # one call per decision period: its own f_r
            take = min(n - pos, d.period - d.phase)
            fr = f_r(first + pos + take) if f_r is not None and d.phase + take == d.period else None
            if fr is not None:
                fr = self.checked_f_r(np.asarray(fr, dtype=np.float64))
            part = None if level is None else level[pos:pos + take]
            decisions += d.update(outl[pos:pos + take], valid[pos:pos + take], f_r=fr, level=part,
                                  flat=None if flat is None else flat[pos:pos + take])
            pos += take
        return decisions

    def seen(self, valid: np.ndarray, flat: np.ndarray | None) -> np.ndarray:
        """``valid`` (T, C) without the flat blocks (``flat``: their counts, ``monitor.flat_signal``
        on): the observations that say something about the machine."""
        on = self.decider.flat_signal
        if on is None or flat is None or not (dead := (flat >= 0) & on).any():
            return valid
        return valid & ~dead

    def trace(self, stamps: list[int], y: np.ndarray, valid: np.ndarray, out: AkfBlock) -> list:
        """``/cm/<channel>/akf`` messages of one AKF per channel (output.akf_trace_filter), in
        time order: the channels' messages of one slot side by side."""
        i = self.trace_i
        z = out.z(y)
        per = [messages.akf_trace(ch.name, stamps, i, y[:, c], valid[:, c], out.x_prior[:, c, i],
                                  out.x_hat[:, c, i], out.Y[:, c, i], z[:, c, i],
                                  out.outlier[:, c, i], out.Q[:, c, i], self.bank.z_c[c])
               for c, ch in enumerate(self.channels)]
        return [m for row in zip(*per) for m in row]

    def decision(self, d: Decision, stamp: int) -> list:
        """Per channel: its severity message, then the events of what changed."""
        C = len(self.channels)
        extras = [self._extra(d, c) for c in range(C)] if self.combined is not None else [{}] * C
        if d.no_signal is not None and d.no_signal.any():
            extras = [{**e, "signal_lost": True} if lost else e for e, lost in zip(extras, d.no_signal.tolist())]
        msgs = messages.severities(stamp, self._names, d, self._r_rows, extras, self._topics)
        prev, prev_sev = d.prev_anomaly.tolist(), d.prev_severity.tolist()
        t_s = self._start_s + self._seconds(d.slot)      # the run's ADC seconds, not the chain's
        judged, held = not d.transient, d.held_max >= HOLD_EVENT_DECISIONS
        out: list = []
        for c, m in enumerate(msgs):
            out.append(m)
            msg = m.msg
            sev, anomaly = msg["severity_index"], msg["anomaly"]
            v = self.views[c]                   # the channel's view, from its message
            v.severity, v.anomaly, v.outliers_first = sev, anomaly, msg["outliers"][0]
            v.max_severity = max(v.max_severity, sev)
            v.decisions += 1
            if judged:
                v.judged += 1
                v.timeline.add(t_s, sev)
            if d.no_signal is not None and bool(d.no_signal[c]) != self.no_signal[c]:
                out.append(self._signal_event(c, d, stamp, sev))
            out += self._flat_note(c, d, stamp)
            if held or anomaly != prev[c] or sev != prev_sev[c]:    # else no event (no failure change)
                out += self._note(c, d, msg, stamp, prev[c], prev_sev[c])
        return out

    def mark_no_signal(self, records: list, d: Decision) -> list:
        """``records`` (the indicator records that go out with decision ``d``), those of a channel
        whose decision has no signal, or a flat block (``monitor.flat_signal``: fewer than make it
        one of no signal, but their samples, a rail's, would count in the record's waveform), marked
        ``signal_lost: true`` (the alarms do not judge them: the record the signal goes in is held
        with its decision)."""
        lost_c = None if d.no_signal is None else d.no_signal
        if d.flat is not None and self.decider.flat_signal is not None:
            flat = (d.flat[:, 2] > 0) & self.decider.flat_signal
            lost_c = flat if lost_c is None else lost_c | flat
        if lost_c is not None and lost_c.any():
            lost = {name for name, x in zip(self._names, lost_c.tolist()) if x}
            for m in records:
                if getattr(m, "schema", None) == "indicators" and m.msg.get("channel") in lost:
                    m.msg["signal_lost"] = True
        return records

    def _signal_event(self, c: int, d: Decision, stamp: int, sev: float) -> Event:
        """``signal_lost`` when channel ``c``'s decision has no signal (its level below
        ``monitor.signal_floor``, or flat blocks: :meth:`_flat_event`), ``signal_back`` when it
        has again."""
        name, ratio = self.channels[c].name, float(d.level[c])
        lost = self.no_signal[c] = self.views[c].no_signal = bool(d.no_signal is not None and d.no_signal[c])
        if lost and d.flat_quarter is not None and d.flat_share is not None and (d.flat_quarter[c] or d.flat_share[c]):
            return self._flat_event(c, d, stamp, sev)
        if lost and d.quietest is not None:
            ratio = float(d.quietest[c])        # the quarter the signal went in
        what = {"level_ratio": ratio, "severity_index": sev}
        if not lost and not np.isfinite(ratio):     # no baseline: back from flat blocks
            return Event("signal_back", name, f"{name}: signal back: its samples move again; severity and "
                         "alarms judged again", stamp, {"severity_index": sev})
        if lost:
            floor = self.channels[c].monitor.signal_floor
            return Event("signal_lost", name, (
                f"{name}: no signal: level {100 * ratio:.3g} % of the healthy baseline (below "
                f"{100 * floor:g} %, monitor.signal_floor): a sensor, cable or ADC fault, or the machine "
                f"stopped; severity {sev:.2f} and the channel's alarms held until it is back"), stamp, what)
        return Event("signal_back", name, f"{name}: signal back: level {ratio:.3g} x the healthy baseline; "
                     "severity and alarms judged again", stamp, what)

    def _flat_note(self, c: int, d: Decision, stamp: int) -> list[Event]:
        """A ``flat_blocks`` warning when channel ``c``'s decision (past the transient, with
        ``monitor.flat_signal`` on for it) has flat blocks, fewer than make it one of no signal,
        and none was said since a decision without (once an episode: the records holding them go
        unjudged by the alarms, which should not pass unsaid)."""
        on = self.decider.flat_signal
        lost = any(x is not None and x[c] for x in (d.no_signal, d.flat_quarter, d.flat_share))
        counts = None if d.flat is None or on is None or not on[c] or d.transient or lost else d.flat[c].tolist()
        flat = counts is not None and counts[2] > 0
        if counts is None or not flat or self.flat_said[c]:
            self.flat_said[c] = flat
            return []
        self.flat_said[c] = True
        name = self.channels[c].name
        lo, hi, n, seen = counts
        at = f"{lo:.0f} counts" if lo == hi else f"{lo:.0f} to {hi:.0f} counts"
        return [Event("flat_blocks", name, (
            f"{name}: {n:.0f} of {seen:.0f} blocks flat (intermittent: a loose connector or cable?), at {at}: "
            "left out of the severity, and the channel's indicator records holding them are not judged by "
            "the alarms; a quarter of a decision's blocks flat is no signal"), stamp, {"count": int(n)})]

    def _flat_event(self, c: int, d: Decision, stamp: int, sev: float) -> Event:
        """``signal_lost`` of channel ``c``, whose decision has flat blocks (``monitor.flat_signal``):
        the count they sit at (the ADC's rail: 0 or its full scale), for how long (each block at its
        rate), and, with no quarter all flat, how many of the blocks looked at were (intermittent)."""
        name = self.channels[c].name
        lo, hi, n, seen = d.flat[c].tolist() if d.flat is not None else (0.0, 0.0, 0.0, 0.0)
        if lo == hi:
            rail = " (the ADC's rail)" if lo in (0, COUNT_MAX) else " (no noise at all)"
            what = f"every sample at {lo:.0f} counts{rail}"
        else:
            what = f"every block flat, at {lo:.0f} to {hi:.0f} counts"
        if d.flat_quarter is not None and not d.flat_quarter[c]:
            what = f"{n:.0f} of {seen:.0f} blocks flat (intermittent), {what.removeprefix('every block flat, ')},"
        slots = d.flat_slots
        secs = 0.0 if slots is None else self._slots_seconds(d.slot - len(slots) + np.flatnonzero(slots[:, c]))
        return Event("signal_lost", name, (
            f"{name}: no signal: {what} for {secs:.3g} s of the decision: a sensor, cable or ADC "
            f"fault (monitor.flat_signal); severity {sev:.2f} and the channel's alarms held until it is back"),
            stamp, {"severity_index": sev})

    def _extra(self, d: Decision, c: int) -> dict:
        """The combined severity's fields of channel ``c``'s message (none in the paper's mode)."""
        if self.combined is None or not self.combined[c]:
            return {}
        dec = self.decider
        assert dec.level_alert is not None and dec.level_danger is not None
        extra = {"severity_akf": float(d.severity_akf[c]), "severity_level": float(d.severity_level[c]),
                 "level_alert": float(dec.level_alert[c]), "level_danger": float(dec.level_danger[c])}
        if np.isfinite(d.level[c]):
            extra["level_ratio"] = float(d.level[c])
        return extra

    def _held(self, c: int, d: Decision, stamp: int) -> list[Event]:
        """An event when a flag has been kept HOLD_EVENT_DECISIONS decisions by the hysteresis alone."""
        name, f_r = self.channels[c].name, float(d.f_r[c])
        held = np.flatnonzero(d.held[c] == HOLD_EVENT_DECISIONS)
        if not held.size:
            return []
        lo = self.decider.c[c] * f_r
        which = ", ".join(f"AKF_{i + 1}" for i in held)
        return [Event("anomaly_held", name, (
            f"{name}: {which} anomaly flag held {HOLD_EVENT_DECISIONS} decisions by the hysteresis alone "
            f"({lo:.3g} <= outliers < f_r {f_r:.3g}): it neither sets anew nor clears; if the machine "
            "is healthy, commission it (cmsensord calibrate)"), stamp, {"filters": [int(i + 1) for i in held]})]

    def _note(self, c: int, d: Decision, msg: dict, stamp: int, prev: list[int], prev_sev: float) -> list[Event]:
        """The events of what changed for channel ``c`` with the decision (its severity message
        ``msg``; its flags ``prev`` and severity index ``prev_sev`` before)."""
        name, n, R = self.channels[c].name, self.bank.n, self.R[c]
        sev, level, anomaly, failure = msg["severity_index"], msg["level"], msg["anomaly"], msg["failure"]
        v = self.views[c]
        events = self._held(c, d, stamp) if d.held_max >= HOLD_EVENT_DECISIONS else []
        if anomaly == prev:
            changed: list[int] = []
        else:
            changed = [i for i, (a, b) in enumerate(zip(anomaly, prev)) if a != b]
        for i in changed:
            cnt = msg["outliers"][i]
            what = {"filter": i + 1, "count": cnt}
            if anomaly[i]:
                events.append(Event("anomaly_onset", name, f"{name}: AKF_{i + 1} (R={R[i]:.4g}) anomaly: "
                                    f"{cnt} outliers in the period >= f_r {d.f_r[c]:.4g}", stamp, what))
            else:
                events.append(Event("anomaly_clear", name, f"{name}: AKF_{i + 1} (R={R[i]:.4g}) anomaly "
                                    f"cleared: {cnt} outliers < c*f_r", stamp, what))
        where = {"severity_index": sev, "level": level}
        if sev != prev_sev:
            events.append(Event("severity_change", name, f"{name}: severity index {prev_sev:.2f} -> "
                                f"{sev:.2f} (level {level}/{n})", stamp, where))
        was_failure = bool(prev[-1]) or prev_sev >= 1.0
        if failure and not was_failure:
            v.failures += 1
            why = (f"AKF_{n} with R_max={R[-1]:.4g} flags an anomaly" if anomaly[-1] else
                   f"level {float(d.level[c]):.2f} x baseline >= level_danger")
            events.append(Event("failure", name, f"{name}: FAILURE: {why}", stamp, where))
        elif was_failure and not failure:
            why = (f"AKF_{n} back below c*f_r" if prev[-1] else
                   f"level {float(d.level[c]):.2f} x baseline below level_danger")
            events.append(Event("failure_clear", name, f"{name}: failure condition cleared ({why})", stamp, where))
        return events
