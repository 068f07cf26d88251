"""The Processor: decoded frames in, messages out, routed through the monitoring chain's parts.

No threads, ports or files: the live port, a replayed capture and a simulation
hand it the same :class:`~cmsensord.protocol.Frame` batches
(:mod:`cmsensord.source`), so live and replay give the same messages.  Per frame:

* a board reset or a frame of the mode the board is not in -> :mod:`.segments`;

* STATUS -> the block clock's rate, the channels, the tacho (:mod:`.clock`, :mod:`.shaft`);
* RMS (values per block) and RAW (:mod:`.raw`: counts -> m/s² -> block RMS) -> slots on the
  block clock -> microphone estimator (:mod:`.microphone`) -> AKF banks -> outlier flags
  waiting for a final speed -> decisions (:mod:`.severity`, :mod:`.speed_gate`);
* RAW samples of the vibration channels -> order chain (:mod:`.orders`);
* TACHO -> shaft speed (:mod:`.shaft`);
* RAW samples (or RMS values) of the vibration channels -> indicator records per interval
  (:mod:`.indicators`), written just before the decision of their stamp;
* indicator records, decisions and order blocks -> the alarm manager (:mod:`.alarms`):
  alarm events and /cm/alarms right after the message that caused them.

The Processor routes the frames by type into waiting batches; the RAW stage is
:mod:`.raw_stage`'s, the observations and decisions :mod:`.observing`'s (its bases).
Every message is built in :mod:`.messages`; every event goes through the
:class:`~cmsensord.monitor.events.EventLog`; both leave through :mod:`.output`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from cmsensord.config import Config
from cmsensord.frame_batch import Pending, rms_fields, select
from cmsensord.monitor.alarms import Alarms
from cmsensord.monitor.channels import ChannelSetup
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.diagnostics import Diagnostics
from cmsensord.monitor.events import Event, EventLog
from cmsensord.monitor.held import Held
from cmsensord.monitor.indicators import Indicators
from cmsensord.monitor.observing import Observing
from cmsensord.monitor.output import Output
from cmsensord.monitor.raw import RawInput
from cmsensord.monitor.raw_stage import RawStage
from cmsensord.monitor.rms_bounds import RmsBounds
from cmsensord.monitor.segments import SCAN_MIN, WIRE_FLAGS, Segments
from cmsensord.monitor.shaft import Shaft
from cmsensord.monitor.wake import SPAN_S, output_pieces, wake_t0
from cmsensord.protocol import Frame, FrameType, Status, decode_rms_rows

if TYPE_CHECKING:
    from cmsensord.monitor.capture import Captures
    from cmsensord.monitor.orders import OrderChain

#: the frame types as plain names: a FrameType.X lookup goes through the enum's __getattr__ (~1 µs per frame)
_RMS, _RAW, _TACHO, _STATUS = FrameType.RMS, FrameType.RAW, FrameType.TACHO, FrameType.STATUS
#: most RAW frames run through the chain in one call (bounds the per-call arrays)
MAX_BATCH = 1000
#: most RMS frames in one call (an observation each, no samples): ~70 % of a replay read of 4 channels
MAX_RMS_BATCH = 4000
#: most observations (slots x channels) in one call of the banks from RMS frames (diagnostics count in these)
MAX_RMS_RUN = 8000


class Processor(RawStage, Observing):
    """Frames in, messages out (see module docstring).

    ``auto_channels``: the channel list follows the board (the first RMS frame's
    C) instead of the configuration (used when the file lists no channels).
    ``diagnostics``: callable returning extra fields for ``/cm/diagnostics``
    (queue depth, drops, lag) — supplied by the live loop.  ``arrived``: (t0_unwrapped, wall clock ns)
    of the newest frame read, when it was read (the live reader's): the board's rate is first
    measured from it (:meth:`BlockClock.anchor`).  ``observe``: called with (first_slot,
    y, valid, seen: valid and not flat) of each block of observations before the banks.
    """

    def __init__(self, cfg: Config, sink, *, auto_channels: bool = False,
                 clock_ns: Callable[[], int] = time.time_ns,
                 diagnostics: Callable[[], dict] | None = None,
                 link_counters: Callable[[], dict] | None = None,
                 on_event: Callable[[dict], None] | None = None,
                 arrived: Callable[[], tuple[int, int] | None] | None = None,
                 observe: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None] | None = None):
        self.cfg, self.sink, self.clock_ns = cfg, sink, clock_ns
        self.observe = observe        # (first_slot, y, valid, seen: valid and not flat) of each block
        self.diagnostics, self.link_counters, self.arrived = diagnostics, link_counters, arrived
        self.clock = BlockClock()
        self.log = EventLog(sink, lambda: self.clock.floor_ns or self.clock_ns(), on_event,
                            lambda: self.clock.seg_stamp_ns)
        self.raw = RawInput(cfg)
        self.rms_bounds = RmsBounds()         # RMS values the board cannot send: missing, decode_error
        self.shaft = Shaft(cfg)
        self.orders: OrderChain | None = None   # once RAW blocks and a tacho come
        self._orders_refused: int | None = None  # the fs at which the order chain could not be made
        self.indicators = Indicators(cfg, self.clock, lambda: self.shaft.tacho, self.shaft.uncovered)
        self.alarms = Alarms(cfg, lambda: tuple(ch.name for ch in self.channels if ch.kind != "microphone"))
        self.output = Output(sink, self.log, self.alarms)
        self._out = self.output.out
        self.clock.steps.append(self.alarms.restepped)      # the alarms' timers move with the stamps
        self.observations = self.missing_observations = self.frames_lost = 0
        self.diag = Diagnostics(self.clock, clock_ns, self.link, lambda: self.observations, diagnostics)
        self.setup = ChannelSetup(cfg, auto_channels, self.clock, self.log, getattr(sink, "channels_known", None))
        self.segments = Segments(self.clock, self.setup, self.log, clock_ns, self._segment_ends)
        self.held = Held()          # live RAW: what waits for the next decision (monitor/held.py)
        self._hand_over = lambda: self.held.hand_over(self.severity, self.indicators, self.channels)
        self.captures: Captures | None = None
        if cfg.capture.enabled:
            from cmsensord.monitor.capture import Captures  # loaded only when captures are configured
            from cmsensord.monitor.capture_marks import CaptureMarks
            c = self.captures = Captures(cfg.capture, self.clock,
                                         CaptureMarks(cfg, lambda: self.shaft.tacho), cfg.indicators.envelope_band_hz)
            self.log.watch, self.log.owed, self.log.settle = c.watch, c.owed, c.settle
            if hasattr(sink, "expect_lag"):     # a capture, and the events after its trigger, come late
                c.expect = lambda raw: sink.expect_lag(Captures.lag_s(cfg, raw))

    def stamp_ns(self, t0_unwrapped: int) -> int:
        return self.clock.stamp_ns(t0_unwrapped)

    def event(self, kind: str, channel: str | None, message: str, stamp_ns: int | None = None, **extra: Any) -> None:
        self.log.emit(kind, channel, message, stamp_ns, **extra)

    def idle(self, stamp_ns: int) -> None:
        """A wake-up without frames at stream time ``stamp_ns``: the alarm state's saves due by then."""
        self._out(self.alarms.tick(stamp_ns))

    def ack(self, which: str | None, by: str | None = None) -> list[str]:
        """Acknowledge alarm ``which`` (None: all) by user ``by``, stamped with the newest alarm
        input's stamp: the names of the alarms acknowledged; KeyError for an unknown alarm."""
        out = self.alarms.ack(which, by)
        self._out(out)
        return [e.fields["alarm"] for e in out if isinstance(e, Event) and e.kind == "alarm_ack"]

    # ---- frames ------------------------------------------------------------
    def handle(self, frames: Sequence[Frame]) -> None:
        """Process a batch of decoded frames, in order."""
        if not frames:
            return
        if self.clock.anchor_ns is None:
            self.clock.anchor(frames[0].t0_unwrapped, self.clock_ns(), self.arrived() if self.arrived else None)
        if len(frames) < SCAN_MIN or type(frames) is list and len(frames) < MAX_BATCH:   # a live call
            self._few(frames)
        else:
            self._scanned(frames)
        self._feed_tacho()

    def _scanned(self, frames: Sequence[Frame]) -> None:
        """A long batch, checked in one pass (:meth:`Segments.runs`) but where a frame does not
        pass; each run of frames that passes by type (:meth:`_passed`)."""
        rms, raw = Pending(), Pending()
        for a, b, codes in self.segments.runs(frames):
            if codes is None:
                f = frames[a]
                if self.segments.check(f) or f.lost_before or f.flags > WIRE_FLAGS:   # a reset, the other mode, a break
                    rms, raw = self._flush(rms, raw)
                    if self._break(f):
                        continue
                rms, raw = self._frame(f, rms, raw)
                continue
            rms, raw = self._passed(frames[a:b], codes, rms, raw)
        self._flush(rms, raw)

    def _few(self, frames: Sequence[Frame]) -> None:
        """A live call's frames.  RAW and TACHO frames only that all pass the segment check
        (:meth:`Segments.passes`): the TACHO ones to the shaft (to wait for :meth:`_feed_tacho`),
        the RAW ones through the chain.  Else a long batch as :meth:`_scanned`, a short one frame
        at a time with no call per frame but the check: RAW frames extend the waiting batch and
        TACHO ones go to the shaft together, before any other frame (:meth:`_frame`)."""
        raws = [f for f in frames if f.type is _RAW]
        tachos = [f for f in frames if f.type is _TACHO]
        if len(raws) + len(tachos) == len(frames) and self.segments.passes(frames):
            if tachos:
                self.shaft.add_many(tachos)
            self._flush_raw(raws)
            return
        if len(frames) >= SCAN_MIN:
            self._scanned(frames)
            return
        rms, raw = Pending(), Pending()
        raws, tachos = [], []
        check = self.segments.check
        for f in frames:
            hit = check(f) or f.lost_before or f.flags > WIRE_FLAGS
            if not hit and f.type is _RAW:
                raws.append(f)
            elif not hit and f.type is _TACHO:
                tachos.append(f)
            else:
                if raws:
                    raw, raws = self._extend(raw, raws, False), []
                if tachos:
                    self.shaft.add_many(tachos)
                    tachos = []
                if hit:
                    rms, raw = self._flush(rms, raw)
                    if self._break(f):
                        continue
                rms, raw = self._frame(f, rms, raw)
        if raws:
            raw = self._extend(raw, raws, False)
        if tachos:
            self.shaft.add_many(tachos)
        self._flush(rms, raw)

    def _passed(self, frames: Sequence[Frame], codes: np.ndarray, rms: Pending,
                raw: Pending) -> tuple[Pending, Pending]:
        """A run of frames that passed the segment check, by type: its TACHO frames to the shaft
        first (they wait there for :meth:`_feed_tacho`, whatever comes between them), then the
        others in order, each run of RMS or RAW frames in one call, as one frame at a time would.
        A STATUS frame (which may make the tracker) ends a part: TACHO frames go first within
        their part only."""
        tacho = codes == int(_TACHO)            # an int: numpy looks up no dunders on the enum
        if tacho.any():
            cut = ((codes[:-1] == int(_STATUS)).nonzero()[0] + 1).tolist()
            if cut:
                for i, j in zip([0, *cut], [*cut, len(codes)]):
                    rms, raw = self._passed(frames[i:j], codes[i:j], rms, raw)
                return rms, raw
            self.shaft.add_many(select(frames, tacho))
            keep = ~tacho
            frames, codes = select(frames, keep), codes[keep]
            if not len(codes):
                return rms, raw
        cuts = ((codes[1:] != codes[:-1]).nonzero()[0] + 1).tolist()
        starts = [0, *cuts]
        single = iter(select(frames, (codes != int(_RMS)) & (codes != int(_RAW))))   # one at a time: built at once
        # plain ints: numpy comparing its int64 with an IntEnum looks up dunders on the enum
        for i, j, kind in zip(starts, [*cuts, len(codes)], codes[starts].tolist()):   # runs of one type
            if kind == _RMS:
                rms = self._extend(rms, frames[i:j], True)
            elif kind == _RAW:
                raw = self._extend(raw, frames[i:j], False)
            else:
                for _ in range(j - i):
                    rms, raw = self._frame(next(single), rms, raw)
        return rms, raw

    def _extend(self, batch: Pending, frames: Sequence[Frame], rms: bool) -> Pending:
        """``frames`` (all RMS, or all RAW) appended to the waiting ``batch``, run through the
        chain whenever it reaches ``MAX_RMS_BATCH`` or ``MAX_BATCH``, as one frame at a time
        would be; what waits."""
        k, n, most = 0, len(frames), MAX_RMS_BATCH if rms else MAX_BATCH
        while k < n:
            take = most - len(batch)
            batch.extend(frames[k:k + take])
            k += take
            if len(batch) >= most:               # bounded memory per bank call
                batch = self._flush(batch, Pending())[0] if rms else self._flush(Pending(), batch)[1]
        return batch

    def _frame(self, f: Frame, rms: Pending, raw: Pending) -> tuple[Pending, Pending]:
        """One frame that passed the segment check into the waiting batches (or handled)."""
        if f.type == _RMS:
            rms = self._extend(rms, (f,), True)
        elif f.type == _RAW:
            raw = self._extend(raw, (f,), False)
        elif f.type == _TACHO:
            self.shaft.add(f)
        elif f.type == _STATUS:
            rms, raw = self._status(f, rms, raw)
        return rms, raw

    def _status(self, f: Frame, rms: Pending, raw: Pending) -> tuple[Pending, Pending]:
        """A STATUS frame.  One that changes the board's time base, channels, mode or tacho ends
        what was decided and measured on the old board; one that changes its calibration (or the
        board) converts the RAW blocks in front of it first, with the old one."""
        st, news = self.setup.decode(f)
        if st is not None and (self.setup.recalibrates(f, st) or news):
            rms, raw = self._flush(rms, raw)    # the frames before it go first,
            if self.setup.status is not None:   # the newest RAW block too: it came before it
                self._flush_raw([], final=True)
        if st is not None and news:
            if self.shaft.waiting:              # and the shaft speed in front of it
                self._feed_tacho(end=True)
            rate = (st.fs, st.block_len) != (self.clock.fs, self.clock.block_len)
            self._release_decisions(final=True)  # decided on the old time base
            self.indicators.finish()             # intervals stamped on it too
            self.setup.apply(f, st)
            if rate or self.shaft.changes_tacho(st):
                self._restart_shaft(st)
        self.setup.status = st or self.setup.status
        if self.status is not None:
            self.shaft.ensure(self.status, self.clock)  # from now on decisions wait for it
            self._out(self.shaft.notes)
            self.shaft.notes.clear()
            if self.raw.waiting:
                self._flush_raw([])
        return rms, raw

    def _break(self, f: Frame) -> bool:
        """A break in the stream in front of ``f`` (the frames before it are processed): a
        board reset starts a new segment (its seq gap is no loss), a seq gap is counted as
        lost frames.  True when ``f`` is to be skipped (a frame of the other mode)."""
        if self.shaft.waiting:      # the edges in front of it first: what comes after may release what waits
            self._feed_tacho(end=True)
        if self.segments.pending(f):
            self.segments.gaps(f, None)
            self._release_decisions(final=True)     # decided on the old segment's time base
            return self.segments.start(f)
        self.frames_lost += self.segments.gaps(f, self.clock.stamp_ns(f.t0_unwrapped))
        return False

    def finish(self) -> None:
        """End of the stream: process what still waits (an incomplete last RAW block,
        samples waiting for a final tacho speed)."""
        self.segments.finish(self.link_counters() if self.link_counters else None)
        self._flush_raw([], final=True)
        self._feed_tacho(end=True)
        if self.orders is not None:
            self._out(self.orders.finish())
        self._hand_over()
        self.indicators.finish()
        self._release_decisions(final=True)
        self._out(self.indicators.take(None))
        if self.captures is not None:
            self.captures.finish(self._out, self.log.release)
        self._out(self.alarms.finish())
        self.log.summarise(final=True)
        self.log.flush()
        self.log.hold = False

    def link_quiet(self) -> None:
        """The link went quiet (``link_stalled``): what the board sent is reported now rather
        than when it resumes or the daemon stops: the open indicator intervals (partial) and
        the intervals and decisions waiting for the shaft speed, with the speed known so far
        (:meth:`Indicators.quiet`).  The order chain's samples wait on: its filter state
        carries on when the board resumes.  The sink writes what its reorder window holds."""
        self._hand_over()
        self.indicators.quiet()
        self._release_decisions(final=True)
        self._out(self.indicators.take(None))
        release_held = getattr(self.sink, "release_held", None)
        if release_held is not None:
            release_held()

    def _segment_ends(self) -> None:
        """Before a new time segment: what waits of the old one (the last RAW block, the
        indicator intervals, the order chain, stamped in their own segment)."""
        self._flush_raw([], final=True)
        self._hand_over()
        self.indicators.finish()
        self._restart_shaft()

    def _restart_shaft(self, status: Status | None = None) -> None:
        """The board's samples count anew (a reset, or the new rate of ``status``): the order chain
        tracks what it holds, and the shaft and the order chain start afresh."""
        if self.orders is not None:
            self._out(self.orders.finish())
            self.orders = None
        self.shaft.restart(status or self.status, self.clock)

    def _flush(self, rms: Pending, raw: Pending) -> tuple[Pending, Pending]:
        self._flush_rms(rms.joined())
        self._flush_raw(raw.joined())
        return Pending(), Pending()

    def _flush_rms(self, frames: Sequence[Frame]) -> None:
        """RMS frames (a list or a :class:`~cmsensord.frame_batch.FrameBatch`) -> observations
        on the block clock."""
        if not frames:
            return
        chans, lengths, t0 = rms_fields(frames)
        C = int(chans[0])
        other = (chans != C).nonzero()[0]       # the channel count changes mid-batch, or the board does
        cut = int(other[0]) if other.size else self.setup.odd_split(C, len(frames))
        if 0 < cut < len(frames):
            self._flush_rms(frames[:cut])
            self._flush_rms(frames[cut:])
            return
        if not (self.setup.agrees(C, frames) and self.setup.ready(C) and self.setup.accept(C, frames)):
            return
        self._board_channels(C)
        good = frames if np.all(lengths == 4 * C) else [f for f in frames if len(f.payload) == 4 * C]
        if len(good) < len(frames):             # only those frames are lost, each told at its t0
            for f in (f for f in frames if len(f.payload) != 4 * C):
                self.event("decode_error", None, f"RMS frame at t0 {f.t0_unwrapped} dropped: {len(f.payload)} bytes, "
                           f"not {4 * C} ({C} channel(s) of 4 bytes)", self.clock.stamp_ns(f.t0_unwrapped), count=1)
            if not good:
                return
            frames = good
            t0 = rms_fields(frames)[2]
        vals = decode_rms_rows(frames, C)
        self.clock.begin(int(t0[0]))            # the intervals it closes are stamped on its time base
        self._out(self.rms_bounds.check(vals, t0, self.channels, self.setup.status, self.clock.stamp_ns))
        per_slot = self.cfg.output.akf_trace or self.setup.microphones is not None or self.captures is not None
        for a, b in output_pieces(t0, self.wake_t0, round(SPAN_S * self.clock.fs)) if per_slot else ((0, len(t0)),):
            self._observe(t0[a:b], vals[a:b], max(1, MAX_RMS_RUN // len(self.channels)),
                          partial(self.indicators.rms, self.channels))
            if self.captures is not None:
                vib = [ch for ch in self.channels if ch.index < C]
                self._out(self.captures.rms([ch.name for ch in vib], t0[a:b], vals[a:b, [ch.index for ch in vib]],
                                            self.clock.fs, self.clock.block_len))

    def _board_channels(self, C: int) -> None:
        """The board now sends C channels: a new chain drains the old one's decisions first."""
        if self.setup.changed(C):
            if C > self.setup.n_board:
                if self.shaft.waiting:          # on the speed of the TACHO frames in front of it
                    self._feed_tacho(end=True)
                self._release_decisions(final=True)
            self._hand_over()
            self.setup.change(C)

    def write_diagnostics(self, stamp_ns: int) -> None:
        """One ``/cm/diagnostics`` message (with each decision; the live loop also writes one,
        stamped :meth:`Diagnostics.wall_stamp`, when none came for a while)."""
        self._out([self.diag.message(stamp_ns)])

    def link(self) -> dict:
        """The link's counters (:meth:`Segments.link`)."""
        return self.segments.link(self.link_counters() if self.link_counters else {})

    def check_wall(self, max_drift_s: float, *, idle: bool = False) -> None:
        """Live, with the queue drained: a step of the wall clock re-anchors the stamps to it, a board
        clock off it by more than ``max_drift_s`` starts a new segment at its measured rate, measured
        since the link's last silence; ``idle`` (no frames came): the step only (:meth:`Segments.check_wall`)."""
        self.segments.check_wall(self.clock_ns(), max_drift_s, self._hand_over, self.cfg.link.stall_s, idle=idle)

    def wake_t0(self) -> int | None:
        """t0 of the board block whose frames complete the next output (:mod:`.wake`)."""
        return wake_t0(self.clock, self.orders, self.setup.severity)
