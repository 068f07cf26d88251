"""Event-triggered captures: the signal around a trigger, with its spectrum and envelope spectrum.

:class:`Captures` holds, per stream (RAW samples at fs, or in RMS mode the block RMS
at fs / block length), a bounded ring of the last ``pre_s + post_s + HOLD_S``
seconds of every channel, indexed by board sample (RAW: the sample counter t0;
RMS: t0 / block length), and beyond it, up to ``MAX_KEPT_BYTES``, the samples a trigger
not taken yet may need. An event record whose kind is in ``capture.triggers``
(:meth:`watch`, called by the event log for every event it writes, in stamp order) or a
periodic tick every ``capture.every_s`` of board time (every sample when that is shorter than
one, said by a ``config`` event at the stream's start; queued as the samples pass it and
taken by :meth:`settle`, which the event log calls before it writes the records from a
stamp on) starts a capture of its channel (of every channel for an event without one), so
ticks and events are taken in stamp order whatever the reads: the samples from ``pre_s``
before the trigger's board sample to ``post_s`` after it, written once the stream has passed
its end (:meth:`raw`, :meth:`rms`; in RAW mode also once the tacho covers it, at most the
indicators' ``MAX_WAIT_S`` later, as its spectra are marked at the speed there), as three
messages stamped at the trigger
(:mod:`cmsensord.sinks.capture_schema`) in one :class:`MessageGroup` (one chunk of the log:
after a crash the capture is complete or absent); until then the event log writes no event
from the trigger's stamp on (:meth:`owed`). A capture starting within
``min_interval_s`` of the channel's last one, one whose size would exceed
``max_mb_per_hour`` in the hour of board time, one whose ``pre_s`` reaches back
before the stream's first sample (refused at once: it does not count as the
channel's last capture), one whose first samples have left the ring, and one still
open at the end of the stream are not written: a
``capture_skipped`` event says which and why; a written one has its ``capture``
event. A capture is written whole or not at all.

An ``operating_state`` trigger may be restricted to the states entered
(``capture.operating_states``).  :meth:`manual` (``cmsensord capture-now`` over the
control socket) starts a capture with trigger ``manual`` at the newest sample
received: ``pre_s`` from the ring, ``post_s`` still to come; it is not held back
by ``min_interval_s`` (an operator asked for it) but counts against the hourly
budget.  In RAW mode the spectrum and the envelope spectrum carry the shaft speed
over the capture and the lines at it (1x, each bearing's defect frequencies:
:mod:`.capture_marks`).  Both spectra are RMS per bin
(:mod:`cmsensord.dsp.capture_spectra`); the envelope spectrum demodulates the band the
indicators do (``indicators.envelope_band_hz``, else 0.08-0.4 fs).  A step of the wall clock
(:meth:`~cmsensord.monitor.clock.BlockClock.restep`) moves every stamp held (the board index
of each stamp, the last capture of each channel, the hour's budget, the ticks and captures
to come) by its shift: ``min_interval_s`` and the budget count the stream's time.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cmsensord.config import ChannelConfig, Config
from cmsensord.config.capture import CaptureConfig
from cmsensord.dsp.capture_spectra import amplitude_spectrum, envelope_rms_spectrum
from cmsensord.dsp.indicators.envelope import envelope_band
from cmsensord.monitor.capture_marks import CaptureMarks
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.events import HOLD_S as EVENT_HOLD_S
from cmsensord.monitor.events import Event
from cmsensord.monitor.indicators import MAX_WAIT_S
from cmsensord.monitor.messages import Message, MessageGroup
from cmsensord.sinks.capture_schema import capture_topics

__all__ = ["Captures"]

#: seconds the ring holds beyond pre_s + post_s: how late a trigger may come (decisions wait for the tacho)
HOLD_S = 20.0
#: the most the ring holds beyond its capacity for triggers not taken yet (a large read's samples
#: come before the decisions that may trigger on them) [bytes]
MAX_KEPT_BYTES = 32e6
#: a stamp past any stream's: the event log released to the end
_END = 1 << 62
#: why a capture whose pre_s reaches back before the stream's first sample is skipped
TOO_EARLY = "its pre_s reaches back before the stream's start"
#: JSON bytes per sample counted against max_mb_per_hour
BYTES_PER_SAMPLE = 12
#: the envelope spectrum is kept up to this frequency [Hz]
ENVELOPE_MAX_HZ = 1000.0


@dataclass
class _Pending:
    channel: str
    column: int
    start: int
    end: int
    trigger_idx: int
    stamp_ns: int
    trigger: dict[str, str]


class _Ring:
    """The last ``capacity`` samples of C channels, by board sample index; lost samples NaN.
    Samples from ``keep_from`` on stay beyond that, up to ``most`` samples in all."""

    def __init__(self, capacity: int, most: int) -> None:
        self.capacity = capacity
        self.most = max(capacity, most)
        self.blocks: deque[tuple[int, np.ndarray]] = deque()
        self.held = 0

    def add(self, first: int, x: np.ndarray, keep_from: int | None = None) -> None:
        self.blocks.append((first, x.astype(np.float32)))
        self.held += len(x)
        while self.held - len(self.blocks[0][1]) >= self.capacity:
            head, y = self.blocks[0]
            if keep_from is not None and head + len(y) > keep_from and self.held <= self.most:
                break
            self.held -= len(self.blocks.popleft()[1])

    @property
    def oldest(self) -> int | None:
        return self.blocks[0][0] if self.blocks else None

    @property
    def newest_end(self) -> int | None:
        return self.blocks[-1][0] + len(self.blocks[-1][1]) if self.blocks else None

    def window(self, a: int, b: int, column: int) -> np.ndarray:
        out = np.full(b - a, np.nan)
        for first, x in self.blocks:
            lo, hi = max(a, first), min(b, first + len(x))
            if lo < hi:
                out[lo - a:hi - a] = x[lo - first:hi - first, column]
        return out


class Captures:
    """Triggers -> captures of the channels' signal (see the module docstring)."""

    def __init__(self, cfg: CaptureConfig, clock: BlockClock,
                 marks: CaptureMarks | None = None, envelope_band_hz: tuple[float, ...] | None = None) -> None:
        self.cfg = cfg
        clock.steps.append(self.restepped)
        self.envelope_band_hz = envelope_band_hz    # indicators.envelope_band_hz (None: the default)
        self.marks = marks
        self.stamp_of = clock.stamp_ns      # board t0 -> stamp [ns]
        self.source = ""
        self.rate = 0.0
        self.ticks = 1                      # board samples per index (RMS: block length)
        self.channels: list[str] = []
        self.units: dict[str, str] = {}     # each channel's unit
        self.ring: _Ring | None = None
        self.anchors: deque[tuple[int, int]] = deque(maxlen=64)   # (index, stamp_ns)
        self.pending: list[_Pending] = []
        self.last_ns: dict[str, int] = {}
        self.budget: deque[tuple[int, int]] = deque()             # (stamp_ns, bytes) of the last hour
        self.next_tick: int | None = None
        self.step = 1                       # indices between periodic ticks (at least one)
        self.ticks_due: deque[tuple[int, int]] = deque()          # (index, stamp_ns) of ticks not taken yet
        self.first_idx: int | None = None                         # the stream's first index
        self.settled_ns: int | None = None                        # triggers up to it are taken
        self.settled_idx: int | None = None                       # ... its board index
        self.out: list[Any] = []
        #: told at the start of each stream whether its samples are RAW (the sink expects its lag)
        self.expect: Callable[[bool], None] = lambda raw: None

    def restepped(self, shift_ns: int) -> None:
        """The wall clock stepped: every stamp held moves by ``shift_ns``, as the time base did."""
        self.anchors = deque(((idx, at + shift_ns) for idx, at in self.anchors), maxlen=self.anchors.maxlen)
        self.last_ns = {name: at + shift_ns for name, at in self.last_ns.items()}
        self.budget = deque((at + shift_ns, n) for at, n in self.budget)
        self.ticks_due = deque((idx, at + shift_ns) for idx, at in self.ticks_due)
        if self.settled_ns is not None:
            self.settled_ns += shift_ns
        for p in self.pending:
            p.stamp_ns += shift_ns

    @staticmethod
    def lag_s(cfg: Config, raw: bool) -> float:
        """How far behind the stream a capture of ``cfg``, and the events it holds back, are
        written at most (the sink's reorder window holds that long): its ``post_s``, the event
        log's hold of the event that triggers it (``events.HOLD_S``), the longest decision period
        (the stream is handed over up to each decision) and, of ``raw`` samples, the wait for the
        tacho to cover it (at most ``MAX_WAIT_S``)."""
        period = max(cfg.monitor.decision_period_s, *(ch.monitor.decision_period_s for ch in cfg.channels))
        return cfg.capture.post_s + EVENT_HOLD_S + period + (MAX_WAIT_S if raw else 0.0)

    # ---- triggers ------------------------------------------------------------
    def watch(self, kind: str, channel: str | None, message: str, stamp_ns: int, fields: dict) -> None:
        """An event written to the log: a trigger when its kind is configured."""
        if kind not in self.cfg.triggers or self.ring is None:
            return
        if kind == "anomaly_onset" and self.cfg.anomaly_akf and fields.get("filter") != self.cfg.anomaly_akf:
            return
        if kind == "operating_state" and self.cfg.operating_states and \
                (fields.get("details") or {}).get("state") not in self.cfg.operating_states:
            return
        idx = self._index_of(stamp_ns)
        if idx is not None:
            self._trigger(channel, idx, stamp_ns, {"kind": kind, "message": message})

    def manual(self, channel: str | None) -> dict[str, Any]:
        """``cmsensord capture-now``: a capture of ``channel`` (None: every channel) around the
        newest sample received; the control socket's answer (``ok``, and ``captures``: per
        channel its trigger stamp, first board index, seconds kept, or why it was skipped)."""
        ring = self.ring
        if ring is None or ring.newest_end is None:
            return {"ok": False, "error": "no samples received yet: nothing to capture"}
        if channel is not None and channel not in self.channels:
            return {"ok": False, "error": f"no channel named {channel!r} (channels: {', '.join(self.channels)})"}
        idx = ring.newest_end
        stamp = self.stamp_of(idx * self.ticks)
        before = len(self.pending)
        skipped = self._trigger(channel, idx, stamp, {"kind": "manual", "message": "cmsensord capture-now"})
        started = {p.channel: p for p in self.pending[before:]}
        rows: list[dict[str, Any]] = []
        for name in self.channels:
            if channel not in (None, name):
                continue
            p = started.get(name)
            if p is None:
                why = skipped.get(name, "skipped")
                if why == TOO_EARLY:        # the seconds of samples still to come before pre_s is held
                    why += f"; try again in {self._wait_s(idx):.3g} s"
                rows.append({"channel": name, "skipped": why})
            else:
                rows.append({"channel": name, "stamp_ns": stamp, "first_sample": p.start,
                             "source": self.source, "pre_s": self.cfg.pre_s, "post_s": self.cfg.post_s})
        return {"ok": True, "captures": rows}

    def _index_of(self, stamp_ns: int) -> int | None:
        """The board index at ``stamp_ns`` (from the last block stamped at or before it)."""
        best = None
        for idx, st in self.anchors:
            if st <= stamp_ns:
                best = (idx, st)
        if best is None:
            best = self.anchors[0] if self.anchors else None
        if best is None:
            return None
        return best[0] + round((stamp_ns - best[1]) * self.rate / 1e9)

    def _trigger(self, channel: str | None, idx: int, stamp_ns: int, trigger: dict[str, str]) -> dict[str, str]:
        """Captures of ``channel`` (None: each) around board index ``idx`` started (pending), or a
        ``capture_skipped`` event for each refused; returns why, per channel refused."""
        pre, post = round(self.cfg.pre_s * self.rate), round(self.cfg.post_s * self.rate)
        skipped: dict[str, str] = {}
        for col, name in enumerate(self.channels):
            if channel not in (None, name):
                continue
            why = self._too_early(idx - pre) \
                or self._refusal(name, stamp_ns, pre + post, trigger["kind"] == "manual")
            if why is not None:
                self._event("capture_skipped", name, f"{name}: capture on {trigger['kind']} skipped: {why}",
                            stamp_ns)
                skipped[name] = why
                continue
            if trigger["kind"] != "manual":     # someone's look does not hold back the next alarm's
                self.last_ns[name] = stamp_ns
            self.budget.append((stamp_ns, (pre + post) * BYTES_PER_SAMPLE))
            self.pending.append(_Pending(name, col, idx - pre, idx + post, idx, stamp_ns, trigger))
        return skipped

    def _wait_s(self, idx: int) -> float:
        """Seconds of samples still to come after board index ``idx`` before a capture's pre_s is held."""
        return ((self.first_idx or 0) + round(self.cfg.pre_s * self.rate) - idx) / self.rate

    def _too_early(self, start: int) -> str | None:
        """Why a capture from board index ``start`` cannot be: it begins before the stream's first
        sample; else None."""
        if self.first_idx is None or start >= self.first_idx:
            return None
        return TOO_EARLY

    def _refusal(self, name: str, stamp_ns: int, n: int, manual: bool = False) -> str | None:
        last = self.last_ns.get(name)
        if not manual and last is not None and stamp_ns - last < self.cfg.min_interval_s * 1e9:
            return f"{(stamp_ns - last) / 1e9:.3g} s after the last one (capture.min_interval_s " \
                   f"{self.cfg.min_interval_s:g})"
        while self.budget and stamp_ns - self.budget[0][0] >= 3600e9:
            self.budget.popleft()
        used = sum(b for _, b in self.budget)
        if used + n * BYTES_PER_SAMPLE > self.cfg.max_mb_per_hour * 1e6:
            return f"{used / 1e6:.1f} MB written in the last hour (capture.max_mb_per_hour " \
                   f"{self.cfg.max_mb_per_hour:g})"
        return None

    def owed(self) -> int | None:
        """The earliest stamp of the events still to come from here (a capture in progress, an
        event not handed over yet), or None: the event log writes nothing from it on."""
        events = [e if isinstance(e, Event) else e.written for e in self.out]   # a capture: its event
        stamps = [p.stamp_ns for p in self.pending] + [e.stamp_ns for e in events if e.stamp_ns is not None]
        return min(stamps, default=None)

    def _event(self, kind: str, channel: str | None, message: str, stamp_ns: int, **fields: Any) -> None:
        self.out.append(Event(kind, channel, message, stamp_ns, fields))

    # ---- the streams ---------------------------------------------------------
    def raw(self, channels: Sequence[ChannelConfig], t0: np.ndarray, y: np.ndarray, fs: float) -> list[Any]:
        """RAW blocks of ``channels``: t0 (B,) first sample of each, y (B, L, C) in each channel's
        unit (m/s^2; a microphone's Pa); what became complete."""
        self._start("raw", [ch.name for ch in channels], fs, 1)
        self.units = {ch.name: ch.physical_unit for ch in channels}
        for b in range(len(t0)):
            self._add(int(t0[b]), y[b])
        return self._complete()

    def rms(self, channels: list[str], t0: np.ndarray, vals: np.ndarray, fs: float, block_len: int) -> list[Any]:
        """RMS rows: t0 (n,) of each block, vals (n, C) of the channels; what became complete."""
        self._start("rms", channels, fs / block_len, block_len)
        for k in range(len(t0)):
            self._add(int(t0[k]) // block_len, vals[k:k + 1])
        return self._complete()

    def _start(self, source: str, channels: list[str], rate: float, ticks: int) -> None:
        if self.ring is not None and (source, channels, rate) == (self.source, self.channels, self.rate):
            return
        self.source, self.channels, self.rate, self.ticks = source, list(channels), rate, ticks
        self.expect(source == "raw")
        self.ring = _Ring(int((self.cfg.pre_s + self.cfg.post_s + HOLD_S) * rate),
                          int(MAX_KEPT_BYTES / (4 * max(1, len(channels)))))
        self.settled_ns = self.settled_idx = None
        self.anchors.clear()
        self.next_tick = None
        self.step = max(1, round(self.cfg.every_s * rate))
        self.ticks_due.clear()
        self.first_idx = None
        for p in self.pending:
            self._event("capture_skipped", p.channel, f"{p.channel}: capture on {p.trigger['kind']} skipped: "
                        "the stream changed (mode, rate or channels)", p.stamp_ns)
        self.pending.clear()

    def _add(self, idx: int, x: np.ndarray) -> None:
        assert self.ring is not None
        stamp = self.stamp_of(idx * self.ticks)
        if self.first_idx is None:
            self.first_idx = idx
        self.anchors.append((idx, stamp))
        self.ring.add(idx, x, self._keep_from())
        if self.cfg.every_s > 0:
            if self.next_tick is None:
                self.next_tick = idx + self.step
                if self.cfg.every_s * self.rate < 0.5:
                    self._event("config", None, f"capture.every_s {self.cfg.every_s:g} is shorter than "
                                f"one sample of the {self.source.upper()} stream ({1 / self.rate:g} s): a "
                                "periodic tick every sample", stamp)
            while self.next_tick < idx + len(x):
                self.ticks_due.append((self.next_tick, self.stamp_of(self.next_tick * self.ticks)))
                self.next_tick += self.step

    def _keep_from(self) -> int | None:
        """The first sample a capture may still need: its pre_s before the earliest trigger
        not taken yet (the ticks due, the events the log has not written), or a pending start."""
        starts = [p.start for p in self.pending]
        if self.ticks_due:
            starts.append(self.ticks_due[0][0] - round(self.cfg.pre_s * self.rate))
        if self.settled_idx is not None:
            starts.append(self.settled_idx - round(self.cfg.pre_s * self.rate))
        return min(starts, default=None)

    def settle(self, upto_ns: int | None) -> None:
        """The periodic ticks stamped up to ``upto_ns`` (None: all) start their captures: called by
        the event log before it writes the records from there on, so ticks and events trigger in
        stamp order (a tick first at one stamp), whatever the reads."""
        if upto_ns is not None and (self.settled_ns is None or upto_ns > self.settled_ns):
            self.settled_ns, self.settled_idx = upto_ns, self._index_of(upto_ns)
        while self.ticks_due and (upto_ns is None or self.ticks_due[0][1] <= upto_ns):
            tick, stamp = self.ticks_due.popleft()
            self._trigger(None, tick, stamp, {"kind": "periodic", "message": f"every {self.cfg.every_s:g} s"})

    def _speed_waits(self, p: _Pending, end: int) -> bool:
        """Whether a complete RAW capture waits for the tacho to cover its window (its marks are
        read off the tacho's speed there), at most as long past its end as an indicator interval."""
        return (self.source == "raw" and self.marks is not None and self.marks.waits(p.end)
                and end - p.end <= MAX_WAIT_S * self.rate)

    def _complete(self, final: bool = False) -> list[Any]:
        ring = self.ring
        assert ring is not None
        end, oldest = ring.newest_end, ring.oldest
        still = []
        for p in self.pending:
            if oldest is not None and p.start < oldest:
                why = TOO_EARLY if p.start < (self.first_idx or 0) else \
                    "its first samples are no longer held"
                self._event("capture_skipped", p.channel, f"{p.channel}: capture on {p.trigger['kind']} "
                            f"skipped: {why}", p.stamp_ns)
            elif end is not None and end >= p.end and (final or not self._speed_waits(p, end)):
                self.out.extend(self._messages(p, ring.window(p.start, p.end, p.column)))
            else:
                still.append(p)
        self.pending = still
        out, self.out = self.out, []
        return out

    def finish(self, emit: Callable[[list[Any]], object], release: Callable[[int], None]) -> None:
        """End of the stream: every trigger taken and every capture complete by now written, in
        stamp order (``emit`` hands the event log what it makes, ``release`` lets the log write
        on to the next capture owed); those still open are skipped."""
        release(_END)
        while self.ring is not None and (self.pending or self.out):
            before = len(self.pending)
            out = self._complete(final=True)
            if not out and len(self.pending) == before:
                break                           # the ones left end past the stream
            emit(out)
            release(_END)
        for p in self.pending:
            self._event("capture_skipped", p.channel, f"{p.channel}: capture on {p.trigger['kind']} skipped: "
                        "the stream ended before its post_s", p.stamp_ns)
        self.pending.clear()
        out, self.out = self.out, []
        emit(out)

    def _messages(self, p: _Pending, x: np.ndarray) -> list[Any]:
        wave_t, spec_t, env_t = capture_topics(p.channel)
        head = {"channel": p.channel, "trigger": p.trigger}
        unit = self.units.get(p.channel, "m/s^2")
        lost = ~np.isfinite(x)
        filled = np.where(lost, 0.0, x)
        samples = [round(v, 6) for v in filled.tolist()]
        group: list[Message] = [Message(wave_t, "capture_waveform", p.stamp_ns, {
            **head, "source": self.source, "sample_rate_hz": self.rate, "first_sample": p.start,
            "pre_s": self.cfg.pre_s, "post_s": self.cfg.post_s, "unit": unit, "missing": int(lost.sum()),
            "samples": samples, **({"lost": np.flatnonzero(lost).tolist()} if lost.any() else {})})]
        f, A = amplitude_spectrum(filled, self.rate)
        marks = self.marks.fields(p.channel, p.start, p.end, self.rate / 2) \
            if self.source == "raw" and self.marks is not None else {}
        group.append(Message(spec_t, "capture_spectrum", p.stamp_ns, {
            **head, "kind": "spectrum", "freq_start_hz": 0.0, "freq_step_hz": float(f[1] - f[0]),
            "unit": unit, "amplitude": np.round(A, 6).tolist(), **marks}))
        if self.source == "raw":
            fe, Ae, band = envelope_rms_spectrum(filled, self.rate, envelope_band(self.rate, self.envelope_band_hz))
            keep = fe <= ENVELOPE_MAX_HZ
            if "marks" in marks:
                marks = {**marks, "marks": [m for m in marks["marks"] if m["freq_hz"] <= ENVELOPE_MAX_HZ]}
            group.append(Message(env_t, "capture_spectrum", p.stamp_ns, {
                **head, "kind": "envelope", "freq_start_hz": 0.0, "freq_step_hz": float(fe[1] - fe[0]),
                "band_hz": [float(band[0]), float(band[1])], "unit": unit,
                "amplitude": np.round(Ae[keep], 6).tolist(), **marks}))
        written = Event("capture", p.channel, f"{p.channel}: captured {len(x) / self.rate:g} s around "
                        f"{p.trigger['kind']} ({len(x)} samples, {int(lost.sum())} lost)", p.stamp_ns,
                        {"samples": len(x)})
        dropped = Event("capture_skipped", p.channel, f"{p.channel}: capture on {p.trigger['kind']} not "
                        "written: the log is not being written (disk error)", p.stamp_ns,
                        {"samples": len(x)})
        return [MessageGroup(tuple(group), written, dropped)]
