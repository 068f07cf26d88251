"""What the board says about itself (STATUS) and which channels are monitored.

A STATUS frame (docs/PROTOCOL.md type 1) that changes fs, block_len, the
channel count or the mode is news: the block clock takes the new rate (and
re-anchors its slots), so does the severity chain (a decision is ``decision_period_s`` of
observations at it, with the ``decision_rule`` events of a board at that rate from the
start), and a ``config`` event says what the board sends.  The
channels come from the configuration, or from the board's first data frame's C
when the configuration lists none (``auto_channels``); configured channels the
board does not send are reported (a warning: their rules and bearings see no value)
and left out.  A board in RMS mode leaves the alarms on any indicator but ``accel_rms`` and
the severity index blind (and those of an operating state from the shaft speed): one
``config`` warning names them (:func:`~cmsensord.monitor.alarms.blind_in_rms_mode`), once a
run; a board in RAW mode at a rate whose records cannot be ``indicators.interval_s`` long (more
than :data:`~cmsensord.monitor.record_length.MAX_INTERVAL_SAMPLES` samples) gets one ``config``
warning giving the record length it gets instead (:func:`~cmsensord.monitor.record_length.capped_interval`),
once per rate, and so does a board in RMS mode whose blocks ``indicators.interval_s`` is not a
whole number of (:func:`~cmsensord.monitor.record_length.rounded_interval`), once per
fs/block_len.  With the first data, the severity chain (and the microphone estimator)
of the usable channels is made.  Then the channels' names are known: an alarm rule or a bearing naming none of them is a
:class:`~cmsensord.errors.ConfigError` (:mod:`cmsensord.config.channel_refs`).

A STATUS whose scale or offset is not finite, or whose scale is 0, is ignored
with a ``decode_error`` event: the previous one (its calibration) is kept.  One that
changes the scale or offset of a monitored channel that the configuration does not set
is told with a ``config`` event (the RAW blocks before it keep the old calibration).

An RMS frame carries as many values as STATUS says the board has channels (docs/PROTOCOL.md: its
``chan`` is C).  RMS frames of a count other than the one a STATUS announced (its first, or one that
changed the count) are dropped while that count is the chain's (or no chain is made yet): the
board's STATUS and its frames disagree, one ``decode_error`` for each ``CHANGE_FRAMES`` of them
in a row and for the rest of a run when it ends (:meth:`ChannelSetup.agrees`).

A data frame whose channel count is not the board's (:meth:`ChannelSetup.accept`)
is one odd frame, dropped and counted with a ``channels`` event, unless a
STATUS announces that count or ``CHANGE_FRAMES`` such frames come in a row: then
the board has changed.  Fewer channels: the channels no longer sent are
reported and observed as missing.  More channels: the channels are re-set (with
``auto_channels``, or when configured channels come back) and a new severity
chain is made (a ``channels`` event says so), and a ``channels`` event names the
monitored channels the count brings (back) into the stream and the board channels not
monitored, in one line.
A new chain's filters start afresh; a channel that keeps its name keeps its
:class:`~cmsensord.monitor.severity.ChannelView` (the run's decisions, failures, maximum and
timeline, for the exit summary), which notes where its filters restarted.  The view of every
name monitored in the run is kept (:attr:`ChannelSetup.views`), also of a channel no longer in
the stream (a count that dropped below its index, or channels re-set without it): it notes the
ADC seconds it left the stream, and came back, under its name.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from cmsensord.config import MAX_CHANNELS, ChannelConfig, Config, default_channels
from cmsensord.config.channel_refs import check_channel_refs
from cmsensord.monitor.alarms import blind_in_rms_mode
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.events import EventLog
from cmsensord.monitor.microphone import Microphones
from cmsensord.monitor.record_length import interval_note
from cmsensord.monitor.severity import ChannelView, SeverityChain
from cmsensord.protocol import (
    MAX_BLOCKS_PER_S,
    MAX_RAW_BLOCK,
    MODE_RAW,
    MODE_RMS,
    SETUP_FIELDS,
    Frame,
    Status,
    decode_status,
)

if TYPE_CHECKING:
    from cmsensord.dsp.acoustic.model import AcousticModel

#: data frames of another channel count in a row that mean the board changed (1 s of RMS blocks)
CHANGE_FRAMES = 100


def status_out_of_range(st: Status) -> str | None:
    """What in ``st`` is outside the protocol's ranges (mode 1 or 2, 1..8 channels, fs and
    block_len at least 1, a RAW block in one frame's payload) or past the daemon's
    :data:`~cmsensord.protocol.MAX_BLOCKS_PER_S`, or None. The set-up sizes the monitor's
    buffers, so one bad STATUS must not reach them."""
    if st.mode not in (MODE_RMS, MODE_RAW):
        return f"mode {st.mode} (the protocol's: 1 RMS, 2 RAW)"
    if not 1 <= st.n_channels <= MAX_CHANNELS:
        return f"{st.n_channels} channels (the protocol's: 1..{MAX_CHANNELS})"
    if st.fs < 1 or st.block_len < 1:
        return f"fs {st.fs} Hz, block_len {st.block_len} (each at least 1)"
    if st.mode == MODE_RAW and st.block_len > MAX_RAW_BLOCK:
        return f"block_len {st.block_len} in RAW mode (a frame carries at most {MAX_RAW_BLOCK} samples)"
    if st.fs > MAX_BLOCKS_PER_S * st.block_len:
        return (f"fs {st.fs} Hz / block_len {st.block_len}: {st.fs / st.block_len:,.0f} blocks a second (at most "
                f"{MAX_BLOCKS_PER_S:,})")
    return None


class ChannelSetup:
    """The board's STATUS, the monitored channels and their severity chain (see module docstring)."""

    def __init__(self, cfg: Config, auto_channels: bool, clock: BlockClock, log: EventLog,
                 on_channels: Callable[[tuple[str, ...]], None] | None = None):
        self.cfg, self.auto_channels, self.clock, self.log = cfg, auto_channels, clock, log
        self.status: Status | None = None
        self.channels: tuple[ChannelConfig, ...] = cfg.channels
        self.severity: SeverityChain | None = None
        self.microphones: Microphones | None = None
        #: the microphone calibrations the chains run on, by path (read once: :meth:`Microphones.create`)
        self.calibrations: dict[str, AcousticModel] = {}
        self._missing_said: int | None = None     # the board's channel count the missing ones were said for
        self._rms_told = False                  # the alarms an RMS-mode board leaves blind were named
        self._unlike_said: tuple[int, int] | None = None    # the rate unlike the commissioned one said
        self._interval_said: dict[int, str] = {}   # per mode, the last record-length line said
        self.n_board = 0                        # the board's channel count the chain was made for
        self._odd_run = 0                       # data frames of another count in a row
        self._odd_first: tuple[int, int] = (0, 0)   # the stamp and channel count of the run's first
        self.odd_dropped = 0                    # odd frames dropped in all
        self._views: dict[str, ChannelView] = {}    # each channel name's view, over every chain
        #: the channel count the newest STATUS announced (None: frames changed the board since)
        self.announced: int | None = None
        self._disagreeing = 0                   # RMS frames in a row disagreeing with it
        self._disagreeing_first: tuple[int, int, int] = (0, 0, 0)   # the run's first t0, count, announced
        #: called with the monitored channels' names each time a chain is made for them (the sink's
        #: ``channels_known``: the MQTT publisher's discovery and worst alarms)
        self.on_channels = on_channels

    def decode(self, f: Frame) -> tuple[Status | None, bool]:
        """A STATUS frame -> (its Status or None if bad, whether it changes the time base, the
        channels or the tacho)."""
        try:
            st = decode_status(f.payload)
        except ValueError as exc:
            self.log.emit("decode_error", None, f"bad STATUS payload at byte {f.offset}: {exc}",
                          self.clock.stamp_ns(f.t0_unwrapped))
            return None, False
        bad = [i for i, (a, b) in enumerate(zip(st.scale, st.offset))
               if not (math.isfinite(a) and a != 0.0 and math.isfinite(b))]
        if bad:
            self.log.emit("decode_error", None, f"STATUS at byte {f.offset} ignored: channel(s) "
                          f"{', '.join(map(str, bad))} with scale/offset "
                          f"{', '.join(f'{st.scale[i]:g}/{st.offset[i]:g}' for i in bad)}, not finite "
                          "(and a scale not 0): the previous STATUS is kept", self.clock.stamp_ns(f.t0_unwrapped))
            return None, False
        out_of_range = status_out_of_range(st)
        if out_of_range:
            kept = "the previous STATUS is kept" if self.status is not None else "no STATUS is in force yet"
            self.log.emit("decode_error", None, f"STATUS at byte {f.offset} ignored: {out_of_range}: {kept}",
                          self.clock.stamp_ns(f.t0_unwrapped))
            return None, False
        old = self.status
        return st, old is None or any(getattr(st, k) != getattr(old, k) for k in SETUP_FIELDS)

    def recalibrates(self, f: Frame, st: Status) -> bool:
        """Whether ``st`` changes the scale or offset of a monitored channel that the configuration
        does not set; a ``config`` event names them and the change."""
        old = self.status
        if old is None:
            return False
        own_scale = {ch.index for ch in self.channels if ch.scale is None}
        own_offset = {ch.index for ch in self.channels if ch.offset is None}
        moved = [f"{i} (scale {a:.7g} -> {b:.7g} m/s² per count, offset {c:.7g} -> {d:.7g} counts)"
                 for i, (a, b, c, d) in enumerate(zip(old.scale, st.scale, old.offset, st.offset))
                 if (a != b and i in own_scale) or (c != d and i in own_offset)]
        if moved:
            then = ": RAW samples from here on are converted with it" if st.mode == MODE_RAW else ""
            self.log.emit("config", None, f"board changed the calibration of channel {', '.join(moved)}{then}",
                          self.clock.stamp_ns(f.t0_unwrapped))
        return bool(moved)

    def apply(self, f: Frame, st: Status) -> None:
        """News from the board: the clock's and the severity chain's rate, the channel count it
        announces, and the config event."""
        if self.status is None or st.n_channels != self.status.n_channels:
            self.announced = st.n_channels
        rate = (st.fs, st.block_len) != (self.clock.fs, self.clock.block_len)
        if self.clock.set_rate(st.fs, st.block_len):
            self.log.emit("config", None, f"board changed fs/block_len to {st.fs}/{st.block_len}:"
                          " time base re-anchored")
        if rate and self.severity is not None:  # decisions of decision_period_s at the new rate, as at the start
            self.severity.set_rate(st.fs, st.block_len)
            self.log.add(self.severity.notes)
            self.severity.notes.clear()
        mode = {1: "RMS", 2: "RAW"}.get(st.mode, f"unknown({st.mode})")
        self.log.emit("config", None, f"board firmware {st.fw_version >> 8}.{st.fw_version & 0xFF}: "
                      f"{mode} mode, {st.n_channels} channel(s), fs {st.fs} Hz, block {st.block_len}"
                      + (f", tacho of {st.tacho_ppr} pulse(s) per revolution" if st.tacho_inputs else ""),
                      self.clock.stamp_ns(f.t0_unwrapped))
        self._unlike_commissioned(f, st)
        self._interval_unlike_records(f, st)
        blind = blind_in_rms_mode(self.cfg) if st.mode == MODE_RMS and not self._rms_told else None
        if blind is not None:
            self._rms_told = True
            self.log.emit("config", None, blind, self.clock.stamp_ns(f.t0_unwrapped), log_level=logging.WARNING)

    def _interval_unlike_records(self, f: Frame, st: Status) -> None:
        """A WARNING when the board's records cannot be ``indicators.interval_s`` long: a RAW
        record's sample cap, once per rate; an RMS record's whole blocks, once per fs/block_len."""
        line = interval_note(self.cfg, st.mode, st.fs, st.block_len)
        if line is not None and self._interval_said.get(st.mode) != line:
            self._interval_said[st.mode] = line
            self.log.emit("config", None, line, self.clock.stamp_ns(f.t0_unwrapped), log_level=logging.WARNING)

    def _unlike_commissioned(self, f: Frame, st: Status) -> None:
        """A WARNING, once per rate, when the board streams at another sample rate or block length
        than the capture the baselines were learned from (``commissioned``: another machine's
        site file, or a board set up anew); of the two, those the section gives are compared and
        named."""
        learned = self.cfg.commissioned
        rate = (st.fs, st.block_len)
        given = [(f"fs {learned.fs_hz:g} Hz", f"fs {st.fs} Hz",
                  abs(st.fs - learned.fs_hz) > 1e-3 * learned.fs_hz)] if learned.fs_hz is not None else []
        if learned.block_len is not None:
            given.append((f"block {learned.block_len}", f"block {st.block_len}", learned.block_len != st.block_len))
        if rate == self._unlike_said or not any(unlike for _, _, unlike in given):
            return
        self._unlike_said = rate
        then, now = ", ".join(g[0] for g in given), ", ".join(g[1] for g in given)
        learned_from = (learned.capture.rpartition("/")[2] or learned.capture) if learned.capture else "a capture"
        self.log.emit("config", None, f"the baselines were learned from {learned_from} at "
                      f"{then}; this board sends {now}: they and the alarm levels on them may not fit it "
                      "(cmsensord calibrate on this machine's healthy period)", self.clock.stamp_ns(f.t0_unwrapped),
                      log_level=logging.WARNING)

    def _odd(self, n: int) -> bool:
        """Whether data frames of ``n`` channels are odd: not the board's count, nor announced."""
        return not (self.severity is None or n == self.n_board
                    or self.status is not None and self.status.n_channels == n)

    def odd_split(self, n: int, n_frames: int) -> int:
        """How many of ``n_frames`` data frames of ``n`` channels in a row are odd before the one
        that makes ``CHANGE_FRAMES`` in a row (the board changed): the caller hands those first."""
        return CHANGE_FRAMES - 1 - self._odd_run if self._odd(n) else 0

    def accept(self, n: int, frames: Sequence[Frame]) -> bool:
        """Data frames in a row of ``n`` channels: True to process them (the board's count, or a
        change of the board), False when they are dropped as odd frames (:meth:`odd_split` cuts a
        call at the change, so any read drops the same ones).  Each run of odd frames is one
        ``channels`` event when it ends (:meth:`end_odd_run`)."""
        if not self._odd(n) or self._odd_run + len(frames) >= CHANGE_FRAMES:
            self.end_odd_run()
            return True
        if not self._odd_run:       # stamped now, in the time segment the frame came in
            self._odd_first = (self.clock.stamp_ns(frames[0].t0_unwrapped), n)
        self._odd_run += len(frames)
        self.odd_dropped += len(frames)
        return False

    def end_odd_run(self) -> None:
        """The run of odd frames (if any) is over: its ``channels`` event, at its first frame."""
        if self._odd_run:
            (stamp, n), run = self._odd_first, self._odd_run
            self.log.emit("channels", None, f"{run} RMS frame(s) of {n} channel(s) in a {self.n_board}-channel "
                          f"stream dropped ({self.odd_dropped} in all)", stamp, count=run,
                          total=self.odd_dropped)
        self._odd_run = 0

    def agrees(self, n: int, frames: Sequence[Frame]) -> bool:
        """RMS frames in a row of ``n`` channels: False when they are dropped as disagreeing with the
        count the STATUS announced (module docstring); True to go on (:meth:`ready`, :meth:`accept`)."""
        want = self.announced
        if want is None or n == want or (self.severity is not None and n != self.n_board):
            self.end_disagreeing()
            return True
        k = 0
        while k < len(frames):
            if not self._disagreeing:
                self._disagreeing_first = (frames[k].t0_unwrapped, n, want)
            take = min(len(frames) - k, CHANGE_FRAMES - self._disagreeing)
            self._disagreeing += take
            k += take
            if self._disagreeing >= CHANGE_FRAMES:
                self.end_disagreeing()
        return False

    def end_disagreeing(self) -> None:
        """The run of RMS frames disagreeing with STATUS (if any) is over: its ``decode_error``, at its first."""
        if self._disagreeing:
            (t0, n, want), run = self._disagreeing_first, self._disagreeing
            self.log.emit("decode_error", None, f"{run} RMS frame(s) of {n} channel(s) dropped: the board's STATUS "
                          f"says {want} channel(s)", self.clock.stamp_ns(t0), count=run)
        self._disagreeing = 0

    def changed(self, n_board: int) -> bool:
        """True when the board now sends ``n_board`` channels, not the chain's count: the
        caller drains the decisions of the chain, then calls :meth:`change`."""
        return self.severity is not None and n_board != self.n_board

    def change(self, n_board: int) -> None:
        """The board sends ``n_board`` channels from now on (see module docstring)."""
        old, self.n_board = self.n_board, n_board
        if n_board != self.announced:           # not as STATUS said: its frames are believed
            self.announced = None
        emit = self.log.emit
        if n_board < old:
            gone = [ch.name for ch in self.channels if ch.index >= n_board]
            emit("channels", None, f"board now sends {n_board} channel(s), not {old}"
                 + (f": channel(s) {', '.join(gone)} not in the stream (observations missing)"
                    if gone else ""), n_channels=n_board)
            self._mark_stream()
            return
        wanted = (default_channels(min(n_board, MAX_CHANNELS), self.cfg.monitor) if self.auto_channels
                  else tuple(ch for ch in self.cfg.channels if ch.index < n_board))
        re_set = [ch.name for ch in wanted] != [ch.name for ch in self.channels]
        if re_set:
            self.severity, self.channels = None, wanted
            self._setup(n_board)
            emit("channels", None, f"board now sends {n_board} channel(s), not {old}: channels "
                 f"re-set to {', '.join(ch.name for ch in self.channels)}", n_channels=n_board)
        known = {ch.index for ch in self.channels}
        idle = [str(i) for i in range(n_board) if i not in known]
        back = [ch.name for ch in self.channels if old <= ch.index < n_board] if not re_set else []
        said = ([f"channel(s) {', '.join(back)} now in the stream"] if back else []) + (
            [f"board channel(s) {', '.join(idle)} not configured, not monitored"] if idle else [])
        if said or not re_set:
            emit("channels", None, f"board now sends {n_board} channel(s), not {old}"
                 + (f": {'; '.join(said)}" if said else ""), n_channels=n_board)
        self._mark_stream()

    def ready(self, n_board: int) -> bool:
        """True when the severity chain exists (made now for a board sending ``n_board``
        channels if not yet); False while none of the channels is in the stream."""
        if self.severity is None:
            self._setup(n_board)
        return self.severity is not None

    def _setup(self, n_board: int) -> None:
        emit = self.log.emit
        if self.auto_channels and n_board != len(self.channels):
            if n_board > MAX_CHANNELS:
                emit("config", None, f"board sends {n_board} channels, more than the "
                     f"{MAX_CHANNELS} a configuration can name: ch0..ch{MAX_CHANNELS - 1} are "
                     f"monitored, the rest is not")
            self.channels = default_channels(min(n_board, MAX_CHANNELS), self.cfg.monitor)
        named = self.channels if self.auto_channels else self.cfg.channels
        check_channel_refs(self.cfg, named)
        usable = tuple(ch for ch in self.channels if ch.index < n_board)
        if len(usable) < len(self.channels) and self._missing_said != n_board:
            self._missing_said = n_board
            missing = ", ".join(f"{ch.name} (index {ch.index})" for ch in self.channels if ch.index >= n_board)
            indexes = "0" if n_board == 1 else f"0 to {n_board - 1}"
            emit("config", None, f"board sends {n_board} channel(s); configured channel(s) {missing} not in "
                 "the stream: not monitored, their alarm rules and bearings see no value" if usable else
                 f"board sends {n_board} channel(s) (index {indexes}); none of the configured channels is "
                 f"among them ({missing}): nothing is monitored until it sends them", log_level=logging.WARNING)
        if not usable:
            return
        self._missing_said = None
        self.n_board = n_board
        self.channels = usable
        if self.on_channels is not None:
            self.on_channels(tuple(ch.name for ch in usable))
        self.severity = SeverityChain(usable, fs=self.clock.fs, block_len=self.clock.block_len,
                                      trace_filter=self.cfg.output.akf_trace_filter)
        self.severity.adc_at = self.clock.seconds_at
        self._keep_views(self.severity)
        self._mark_stream()
        self.log.add(self.severity.notes)
        self.severity.notes.clear()
        self.microphones, events = Microphones.create(self.cfg, usable, fs=self.clock.fs,
                                                      block_len=self.clock.block_len, loaded=self.calibrations)
        self.log.add(events)

    def _keep_views(self, chain: SeverityChain) -> None:
        """The chain's channels take over the views of their names from the chains before it: the
        run's figures go on; the latest decision's flags and signal are the new filters' (none
        yet), and the view notes the restart at the ADC time now."""
        for c, view in enumerate(chain.views):
            kept = self._views.setdefault(view.name, view)
            if kept is not view:
                kept.anomaly, kept.outliers_first, kept.no_signal = view.anomaly, 0, False
                kept.restarted(self.clock.adc_seconds)
                chain.views[c] = kept

    @property
    def views(self) -> list[ChannelView]:
        """The view of every channel name monitored in the run, in the order first monitored."""
        return list(self._views.values())

    def _mark_stream(self) -> None:
        """Each view notes whether its channel is in the board's stream (a channel of the chain
        whose index the board sends): the ADC second it left, or the absence it came back from."""
        now = self.clock.adc_seconds
        sent = {ch.name for ch in self.channels if ch.index < self.n_board} if self.severity is not None else set()
        for name, view in self._views.items():
            if name not in sent and view.left_s is None:
                view.left_s = now
            elif name in sent and view.left_s is not None:
                view.came_back(now)
