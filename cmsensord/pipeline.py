"""Per-channel monitoring state and the frame-to-message processing step.

The :class:`Processor` owns what happens between decoded frames and the sink,
and nothing else: no threads, no ports, no files.  Live port, replayed capture
and simulation all hand it the same :class:`~cmsensord.protocol.Frame` objects
(DESIGN.md: one source interface), so live and replay give the same messages.

For RMS frames (PROTOCOL.md type 2) it

1. places each frame on the board's block clock: slot = (t0_unwrapped - t0 of
   the first RMS frame) / block_len.  A slot with no frame (lost frame, seq
   gap) is a *missing observation*: a time update of the AKFs, never a zero;
2. runs the channels x n AKF bank (``dsp.akf``; seed 000 eqs. 3-15);
3. counts outliers into the 1-s anomaly decisions and severity index
   (``dsp.severity``; Fig. 3, eqs. 16-18);
4. writes ``/cm/<channel>/severity`` per decision, ``/cm/<channel>/akf`` per
   observation (when enabled), ``/cm/events`` and ``/cm/diagnostics``.

A channel of kind ``microphone`` (seed 002) is watched through its sound: z_k =
(block RMS)^2 [Pa^2] goes through the acoustic estimator (``dsp.acoustic``,
eqs. 6-38), sqrt(x^_k) takes the place of the channel's observation in the bank
(step 2), and ``/cm/<channel>/vibration_estimate`` is written per block.

Timestamps come from the ADC clock: t = anchor + (t0_unwrapped - t0_first)/fs,
the anchor being the wall clock when the first frame was received
(PROTOCOL.md rule 4).  RAW and TACHO frames are counted and otherwise left to
the raw chain.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol, Sequence

import numpy as np

from cmsensord.config import ChannelConfig, Config, default_channels
from cmsensord.dsp.akf import AkfBank, bank_r
from cmsensord.dsp.rms import rows_physical, rows_rms
from cmsensord.dsp.severity import AnomalyDecider, Decision
from cmsensord.protocol import Frame, FrameType, Status, decode_status, decode_tacho

log = logging.getLogger("cmsensord")

DEFAULT_FS = 25000
DEFAULT_BLOCK_LEN = 250
#: a jump of the block clock larger than this (or backwards) is a time jump
#: (board reset, t0 reloaded): the clock is re-anchored instead of inserting
#: hours of missing observations.
MAX_GAP_S = 600.0
#: most RMS frames run through the bank in one call (bounds the per-call arrays:
#: 4 x (T, C, n) float64 = 1.3 MB for T = 1000, C = 4, n = 10)
MAX_BATCH = 1000
#: RAW frames held while waiting for the first STATUS (its scale/offset): 2 s of 4 channels
RAW_WAIT_FRAMES = 800
#: TACHO frames kept while no order chain exists (RMS mode, or before the first RAW block)
TACHO_WAIT_FRAMES = 200
#: observation slots whose decisions may wait for a final tacho speed (5 s at 100 Hz)
PENDING_DECISION_SLOTS = 500


#: how events go to the log (the journal): per-AKF flags are detail, the
#: severity index and everything about the link or the disk is news.
_LOG_LEVEL = {
    "anomaly_onset": logging.DEBUG, "anomaly_clear": logging.DEBUG,
    "failure": logging.WARNING, "frames_lost": logging.WARNING, "link_lost": logging.WARNING,
    "decode_error": logging.WARNING, "queue_overflow": logging.WARNING,
    "disk_error": logging.ERROR, "link_stalled": logging.WARNING,
}


#: disk_error events that report routine work or a recovery (details.action)
_DISK_NEWS = frozenset({"resumed", "retention", "salvaged"})


class Sink(Protocol):
    def write(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> None: ...


class ListSink:
    """A sink that keeps messages in memory (tests, the simulate summary)."""

    def __init__(self) -> None:
        self.messages: list[tuple[str, int, dict]] = []

    def write(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> None:
        self.messages.append((topic, stamp_ns, msg))

    def topic(self, name: str) -> list[dict]:
        return [m for t, _, m in self.messages if t == name]


@dataclass
class ChannelView:
    """Latest per-channel figures for the status line and the exit summary."""

    name: str
    severity: float = 0.0
    max_severity: float = 0.0
    anomaly: list[int] = field(default_factory=list)
    outliers_first: int = 0       # outliers in the last period of the most sensitive AKF
    decisions: int = 0
    failures: int = 0


class Processor:
    """Frames in, messages out (see module docstring).

    ``auto_channels``: the channel list follows the board (the first RMS frame's
    C) instead of the configuration (used when the file lists no channels).
    ``diagnostics``: callable returning extra fields for ``/cm/diagnostics``
    (queue depth, drops, lag) — supplied by the live loop.
    """

    def __init__(self, cfg: Config, sink: Sink, *, auto_channels: bool = False,
                 clock_ns: Callable[[], int] = time.time_ns,
                 diagnostics: Callable[[], dict] | None = None,
                 link_counters: Callable[[], dict] | None = None,
                 on_event: Callable[[dict], None] | None = None,
                 observe: Callable[[int, np.ndarray, np.ndarray], None] | None = None):
        self.cfg = cfg
        self.sink = sink
        self.auto_channels = auto_channels
        self.clock_ns = clock_ns
        self.diagnostics = diagnostics
        self.link_counters = link_counters
        self.on_event = on_event
        self.observe = observe        # (first_slot, y, valid) of each block the bank watches
        self.fs = DEFAULT_FS
        self.block_len = DEFAULT_BLOCK_LEN
        self.status: Status | None = None
        self.anchor_ns: int | None = None      # wall clock at the first frame
        self.t0_first: int | None = None       # t0_unwrapped of the first frame
        self.slot0_t0: int | None = None       # t0_unwrapped of slot 0 (first RMS frame)
        self.next_slot = 0                     # next observation slot expected
        self.channels: tuple[ChannelConfig, ...] = cfg.channels
        self.bank: AkfBank | None = None
        self.decider: AnomalyDecider | None = None
        self.views: list[ChannelView] = []
        self.observations = 0
        self.missing_observations = 0
        self.frames_lost = 0
        self.events: deque[dict] = deque(maxlen=1000)   # recent events, for status/summary
        self.event_counts: dict[str, int] = {}
        self.started_wall = time.monotonic()
        self._last_stamp_ns = 0
        self._raw_waiting: list[Frame] = []
        self._tacho_waiting: list[Frame] = []
        self.tacho = None                       # TachoTracker, once the board sends TACHO frames
        self.orders = None                      # OrderChain, once RAW blocks and a tacho come
        self._pending: list[tuple] = []     # (outlier, valid, level ratio or None) awaiting f_r
        self._baseline = np.ones(1)         # per channel: the bank watches block RMS / baseline
        self._combined: np.ndarray | None = None   # per channel: severity also grades the level
        self._pending_slots = 0
        self._no_channels = False
        self.raw_dropped = 0
        self.acoustic = None                    # seed-002 estimator of the microphone channels
        self._mic_cols: list[int] = []

    # ---- time base -------------------------------------------------------
    def stamp_ns(self, t0_unwrapped: int) -> int:
        """ADC sample index -> ns since the epoch (PROTOCOL.md rule 4)."""
        assert self.anchor_ns is not None and self.t0_first is not None
        return self.anchor_ns + (t0_unwrapped - self.t0_first) * 1_000_000_000 // self.fs

    def slot_stamp_ns(self, slot: int) -> int:
        assert self.slot0_t0 is not None
        return self.stamp_ns(self.slot0_t0 + slot * self.block_len)

    @property
    def board_seconds(self) -> float:
        """The board's clock (t0_unwrapped / fs) at the end of the processed observations."""
        if self.slot0_t0 is None:
            return 0.0
        return (self.slot0_t0 + self.next_slot * self.block_len) / self.fs

    @property
    def adc_seconds(self) -> float:
        """ADC time covered by the observations processed so far."""
        return self.next_slot * self.block_len / self.fs

    # ---- events ------------------------------------------------------------
    def event(self, kind: str, channel: str | None, message: str, stamp_ns: int | None = None,
              **extra: Any) -> None:
        if stamp_ns is None:
            stamp_ns = self._last_stamp_ns or self.clock_ns()
        msg = {"kind": kind, "channel": channel, "message": message, **extra}
        self.sink.write("/cm/events", "event", stamp_ns, msg)
        self.events.append(msg)
        self.event_counts[kind] = self.event_counts.get(kind, 0) + 1
        level = _LOG_LEVEL.get(kind, logging.INFO)
        if kind == "disk_error" and (extra.get("details") or {}).get("action") in _DISK_NEWS:
            level = logging.INFO        # routine or good news from the sink, not an error
        log.log(level, "%s: %s", kind, message)
        if self.on_event is not None:
            self.on_event(msg)

    # ---- frames ------------------------------------------------------------
    def handle(self, frames: Sequence[Frame]) -> None:
        """Process a batch of decoded frames, in order."""
        if not frames:
            return
        if self.anchor_ns is None:
            self.anchor_ns = self.clock_ns()
            self.t0_first = frames[0].t0_unwrapped
        rms: list[Frame] = []
        raw: list[Frame] = []
        RMS, RAW, STATUS, TACHO = FrameType.RMS, FrameType.RAW, FrameType.STATUS, FrameType.TACHO
        for f in frames:
            if f.lost_before:
                self._flush_rms(rms)
                self._flush_raw(raw)
                rms, raw = [], []
                self.frames_lost += f.lost_before
                self.event("frames_lost", None, f"{f.lost_before} frame(s) lost before seq {f.seq} "
                           f"(seq gap)", self.stamp_ns(f.t0_unwrapped), count=f.lost_before)
            if f.type == RMS:
                rms.append(f)
                if len(rms) >= MAX_BATCH:          # bounded memory per bank call
                    self._flush_rms(rms)
                    rms = []
            elif f.type == RAW:
                raw.append(f)
                if len(raw) >= MAX_BATCH:
                    self._flush_raw(raw)
                    raw = []
            elif f.type == TACHO:
                if f.chan == self.cfg.tacho.input:
                    self._tacho_waiting.append(f)
                    if len(self._tacho_waiting) > TACHO_WAIT_FRAMES and self.tacho is None:
                        del self._tacho_waiting[0]      # no STATUS yet: keep only the newest
            elif f.type == STATUS:
                st = self._decode_status(f)
                if st is not None and self._status_news(st):
                    # what the board says changes the time base or the channels: the
                    # frames before it are processed first, and its event comes after them
                    self._flush_rms(rms)
                    self._flush_raw(raw)
                    rms, raw = [], []
                    self._apply_status(f, st)
                self.status = st or self.status
                if self.tacho is None and self.status is not None:
                    self._ensure_tacho()        # from now on decisions wait for its speed
                if self._raw_waiting and self.status is not None:
                    self._flush_raw([])
        self._flush_rms(rms)
        self._flush_raw(raw)
        self._feed_tacho()

    def finish(self) -> None:
        """End of the stream: process what still waits (an incomplete last RAW block,
        samples waiting for a final tacho speed)."""
        self._flush_raw([], final=True)
        self._feed_tacho()
        if self.orders is not None:
            self.orders.finish()
        self._release_decisions(final=True)

    def _decode_status(self, f: Frame) -> Status | None:
        try:
            return decode_status(f.payload)
        except ValueError as exc:
            self.event("decode_error", None, f"bad STATUS payload at byte {f.offset}: {exc}")
            return None

    def _status_news(self, st: Status) -> bool:
        old = self.status
        return old is None or (st.fs, st.block_len, st.n_channels, st.mode) != (
            old.fs, old.block_len, old.n_channels, old.mode)

    def _apply_status(self, f: Frame, st: Status) -> None:
        if st.fs > 0 and st.block_len > 0 and (st.fs, st.block_len) != (self.fs, self.block_len):
            if self.slot0_t0 is not None:
                self.event("config", None, f"board changed fs/block_len to {st.fs}/{st.block_len}:"
                           " time base re-anchored")
                self.slot0_t0 = None
            self.fs, self.block_len = st.fs, st.block_len
        mode = {1: "RMS", 2: "RAW"}.get(st.mode, f"unknown({st.mode})")
        self.event("config", None, f"board firmware {st.fw_version >> 8}.{st.fw_version & 0xFF}: "
                   f"{mode} mode, {st.n_channels} channel(s), fs {st.fs} Hz, block {st.block_len}",
                   self.stamp_ns(f.t0_unwrapped))

    def _setup(self, n_board: int) -> None:
        if self.auto_channels and n_board != len(self.channels):
            self.channels = default_channels(n_board, self.cfg.monitor)
        usable = tuple(ch for ch in self.channels if ch.index < n_board)
        if len(usable) < len(self.channels):
            missing = [ch.name for ch in self.channels if ch.index >= n_board]
            self.event("config", None, f"board sends {n_board} channel(s); configured channel(s) "
                       f"{', '.join(missing)} not in the stream")
        if not usable:
            if not self._no_channels:
                self._no_channels = True
                self.event("config", None, f"none of the configured channels is among the board's "
                           f"{n_board}: observations are not monitored until it sends them")
            return
        self._no_channels = False
        self.channels = usable
        mons = [ch.monitor for ch in usable]
        n = mons[0].n                   # the same for every channel (config rule)
        R = np.stack([bank_r(m.r_min, m.r_max, m.n) for m in mons])
        self.bank = AkfBank(R, window=[m.window for m in mons], z_c=[m.z_c for m in mons],
                            p0=[m.p0 for m in mons], q0=[m.q0 for m in mons])
        period = max(1, round(mons[0].decision_period_s * self.fs / self.block_len))
        combined = [m.combined for m in mons]
        self._baseline = np.array([m.baseline or 1.0 for m in mons])
        self._combined = np.array(combined) if any(combined) else None
        self.decider = AnomalyDecider(
            len(usable), n, f_r=[m.f_r for m in mons], c=[m.c for m in mons], period=period,
            level_alert=[m.level_alert for m in mons] if any(combined) else None,
            level_danger=[m.level_danger for m in mons])
        self._index = np.array([ch.index for ch in usable])
        self.views = [ChannelView(name=ch.name, anomaly=[0] * n) for ch in usable]
        self._trace_i = min(self.cfg.output.akf_trace_filter, n) - 1
        self._R = R
        self._setup_acoustic(usable)

    def _setup_acoustic(self, usable) -> None:
        """Microphone channels (kind: microphone): the seed-002 estimator, one model per channel."""
        self.acoustic = None
        self._mic_cols = [c for c, ch in enumerate(usable) if ch.kind == "microphone"]
        if not self._mic_cols:
            return
        from cmsensord.acoustic_model import load_calibration
        from cmsensord.dsp.acoustic import AcousticEstimator, Guards

        models = []
        block_s = self.block_len / self.fs
        for c in self._mic_cols:
            ch = usable[c]
            path = ch.calibration or self.cfg.acoustic.calibration
            model = load_calibration(path)
            if abs(model.block_s - block_s) > 1e-9:
                self.event("config", ch.name, f"{ch.name}: acoustic calibration {path} was made with "
                           f"{model.block_s * 1e3:g} ms blocks, the board sends {block_s * 1e3:g} ms: "
                           "the vibration estimate is biased; calibrate with this board setting")
            models.append(model)
        self.acoustic = AcousticEstimator(models, Guards(zeta_max=self.cfg.acoustic.zeta_max))

    def _flush_rms(self, frames: list[Frame]) -> None:
        """Place RMS frames on the block clock and run them through the bank."""
        if not frames:
            return
        C = frames[0].chan
        if any(f.chan != C for f in frames):        # channel count changed mid-batch: split
            cut = next(i for i, f in enumerate(frames) if f.chan != C)
            self._flush_rms(frames[:cut])
            self._flush_rms(frames[cut:])
            return
        if self.bank is None:
            self._setup(C)
            if self.bank is None:
                return
        t0 = np.fromiter((f.t0_unwrapped for f in frames), dtype=np.int64, count=len(frames))
        try:
            vals = np.frombuffer(b"".join(f.payload for f in frames), dtype="<f4")
            vals = vals.reshape(len(frames), C)
        except ValueError:
            self.event("decode_error", None, f"RMS payload length does not match C = {C}")
            return
        self._observe(t0, vals)

    def _flush_raw(self, frames: list[Frame], final: bool = False) -> None:
        """RAW blocks -> m/s² -> the board's block RMS (dsp.rms) -> the same bank.

        RAW frames arriving before the first STATUS (no scale/offset yet) wait,
        at most RAW_WAIT_FRAMES of them; the oldest beyond that are dropped and counted.
        """
        if frames:
            self._raw_waiting.extend(frames)
        if not self._raw_waiting:
            return
        if self.status is None and not self._raw_overrides_complete():
            over = len(self._raw_waiting) - RAW_WAIT_FRAMES
            if over > 0:
                del self._raw_waiting[:over]
                self.raw_dropped += over
                self.event("decode_error", None, f"{over} RAW frame(s) dropped: no STATUS "
                           "(scale/offset) from the board yet")
            return
        frames, self._raw_waiting = self._raw_waiting, []
        C = self.status.n_channels if self.status is not None else 1 + max(f.chan for f in frames)
        if not final:
            # the newest block may still be missing channels (its frames can straddle a
            # read or a batch): it waits for a frame of a later block, or for finish()
            last = frames[-1].t0_unwrapped
            k = len(frames)
            while k > 0 and frames[k - 1].t0_unwrapped == last:
                k -= 1
            if len(frames) - k < C:
                frames, self._raw_waiting = frames[:k], frames[k:]
            if not frames:
                return
        if self.bank is None:
            self._setup(C)
            if self.bank is None:
                return
        L = self.block_len
        good = [f for f in frames if f.chan < C and len(f.payload) == 2 * L]
        if len(good) < len(frames):
            self.event("decode_error", None, f"{len(frames) - len(good)} RAW frame(s) with a channel "
                       f">= {C} or a payload that is not {L} samples skipped")
        if not good:
            return
        t0 = np.fromiter((f.t0_unwrapped for f in good), dtype=np.int64, count=len(good))
        chan = np.fromiter((f.chan for f in good), dtype=np.int64, count=len(good))
        counts = np.frombuffer(b"".join(f.payload for f in good), dtype="<u2").reshape(len(good), L)
        blocks, row = np.unique(t0, return_inverse=True)
        if np.any(np.diff(t0) < 0):             # out of order: a board reset; keep arrival order
            blocks, first = np.unique(t0, return_index=True)
            order = np.argsort(first)
            blocks = blocks[order]
            row = np.argsort(order)[row]
        scale, offset = self.raw_calibration()
        rms = rows_rms(counts, scale[chan], offset[chan])
        vals = np.full((len(blocks), C), np.nan, dtype=np.float32)
        vals[row, chan] = rms
        self._observe(blocks, vals)
        self._feed_orders(blocks, row, chan, counts, scale, offset)

    def _feed_orders(self, blocks, row, chan, counts, scale, offset) -> None:
        """RAW blocks (and the TACHO frames so far) to the order chain of the machine."""
        vib = tuple(ch for ch in self.channels if ch.kind != "microphone")   # orders of vibration only
        if self.orders is None:
            if not (vib and self.cfg.orders.enabled and self.bank is not None and self._ensure_tacho()):
                return
            from cmsensord.orders import OrderChain     # scipy is loaded only for the raw chain
            self.orders = OrderChain(self.cfg, vib, self.tacho, fs=self.fs,
                                     write=self.sink.write, event=self.event, stamp=self.stamp_ns)
        L = self.block_len
        index = [ch.index for ch in vib]
        sel = np.isin(chan, index)
        pos = {int(b): i for i, b in enumerate(index)}
        y = np.full((len(blocks), L, len(vib)), np.nan)
        cal = rows_physical(counts[sel], scale[chan[sel]], offset[chan[sel]])
        y[row[sel], :, [pos[int(c)] for c in chan[sel]]] = cal
        # blocks are consecutive here except across lost ones: feed contiguous runs
        cuts = np.flatnonzero(np.diff(blocks) != L) + 1
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(blocks)]):
            self.orders.add_samples(int(blocks[a]), y[a:b].reshape(-1, len(vib)))

    def _ensure_tacho(self) -> bool:
        """Create the TachoTracker once the board has said it has a tacho (STATUS)."""
        if self.tacho is None and self.status is not None and self.status.tacho_inputs > 0:
            from cmsensord.dsp.tacho import TachoTracker

            ppr = self.cfg.tacho.ppr or self.status.tacho_ppr
            h = max(1, round(self.cfg.tacho.smoothing_revs * ppr))
            m = min(64, max(2, round(self.cfg.tacho.causal_revs * ppr)))
            self.tacho = TachoTracker(self.fs, ppr, block_len=self.block_len, half_window=h,
                                      timeout_s=self.cfg.tacho.timeout_s, causal_window=m)
        return self.tacho is not None

    def _feed_tacho(self) -> None:
        """TACHO frames -> shaft speed (events), then what waited for a final speed."""
        if self._tacho_waiting and self._ensure_tacho():
            frames, self._tacho_waiting = self._tacho_waiting, []
            t0 = np.fromiter((f.t0_unwrapped for f in frames), dtype=np.int64, count=len(frames))
            edges = []
            for f in frames:
                try:
                    edges.append(decode_tacho(f.payload))
                except ValueError as exc:
                    self.event("decode_error", None, f"bad TACHO payload at byte {f.offset}: {exc}")
                    edges.append(np.empty(0, dtype=np.uint32))
            u = self.tacho.update(t0, edges)
            for ev in u.events:
                self.event(ev.kind, None, ev.message, self.stamp_ns(int(ev.sample)), count=int(ev.count))
            if self.orders is not None:
                self.orders.tacho_updated()
        self._release_decisions(final=False, tacho_fed=True)

    # ---- decisions with the tacho speed as f_r (Fig. 3) ---------------------
    def _f_r_from_tacho(self) -> bool:
        return self.cfg.tacho.f_r_from_tacho and self.tacho is not None

    def _release_decisions(self, final: bool, tacho_fed: bool = False) -> None:
        """Outlier counts wait until the tacho speed is final for their decision period,
        so f_r (the mean speed of the period) does not depend on how the stream was read.
        Right after the tacho was fed (``tacho_fed``), counts more than
        PENDING_DECISION_SLOTS behind are released anyway: the tacho has stopped coming."""
        if not self._pending:
            return
        first = self.next_slot - self._pending_slots
        if final or not self._f_r_from_tacho():
            upto = self.next_slot
        else:
            upto = int((self.tacho.final_until - self.slot0_t0) // self.block_len)
            upto = min(upto, self.next_slot)
            if tacho_fed and self._pending_slots > PENDING_DECISION_SLOTS:
                upto = max(upto, self.next_slot - PENDING_DECISION_SLOTS)
        n = upto - first
        if n <= 0:
            return
        outl = np.concatenate([o for o, _, _ in self._pending])
        valid = np.concatenate([v for _, v, _ in self._pending])
        lv = None if self._combined is None else np.concatenate([x for _, _, x in self._pending])
        self._pending = [(outl[n:], valid[n:], None if lv is None else lv[n:])] if outl.shape[0] > n else []
        self._pending_slots = outl.shape[0] - n
        outl, valid = outl[:n], valid[:n]
        d = self.decider
        pos = 0
        while pos < n:                          # one call per decision period: its own f_r
            take = min(n - pos, d.period - d.phase)
            f_r = None
            if self._f_r_from_tacho() and d.phase + take == d.period:
                f_r = self._period_f_r(first + pos + take)
            part = None if lv is None else lv[pos:pos + take]
            for dec in d.update(outl[pos:pos + take], valid[pos:pos + take], f_r=f_r, level=part):
                self._write_decision(dec)
            pos += take

    def _period_f_r(self, end_slot: int) -> np.ndarray:
        """Mean tacho speed [Hz] over the decision period ending at ``end_slot``, per channel
        (the configured f_r where the tacho has no valid speed)."""
        slots = np.arange(end_slot - self.decider.period, end_slot)
        hz, _, ok = self.tacho.evaluate(self.slot0_t0 + slots * self.block_len)
        cfg_fr = np.array([ch.monitor.f_r for ch in self.channels])
        if ok.mean() < 0.5:
            return cfg_fr
        return np.full(len(self.channels), float(np.mean(hz[ok])))

    def _raw_overrides_complete(self) -> bool:
        return all(ch.scale is not None and ch.offset is not None for ch in self.cfg.channels)

    def raw_calibration(self) -> tuple[np.ndarray, np.ndarray]:
        """Per board channel scale/offset: STATUS, overridden by the configuration."""
        st = self.status
        n = max(st.n_channels if st else 0, 1 + max((ch.index for ch in self.cfg.channels), default=0))
        scale = np.ones(n, dtype=np.float32)
        offset = np.zeros(n, dtype=np.float32)
        if st is not None:
            scale[:len(st.scale)] = st.scale
            offset[:len(st.offset)] = st.offset
        for ch in self.cfg.channels:
            if ch.scale is not None:
                scale[ch.index] = ch.scale
            if ch.offset is not None:
                offset[ch.index] = ch.offset
        return scale, offset

    def _observe(self, t0: np.ndarray, vals: np.ndarray) -> None:
        """Observations (n, C_board) of the blocks starting at t0 -> slots -> bank."""
        if self.slot0_t0 is None:
            self.slot0_t0 = int(t0[0]) - self.next_slot * self.block_len
        slots = (t0 - self.slot0_t0) // self.block_len
        # time jumps (board reset, t0 reload) and duplicates split the batch
        max_gap = int(MAX_GAP_S * self.fs / self.block_len)
        prev = np.concatenate(([self.next_slot - 1], slots[:-1]))
        bad = np.flatnonzero((slots <= prev) | (slots - prev > max_gap))
        if bad.size:
            b = int(bad[0])
            if b > 0:
                self._run(slots[:b], vals[:b])
            old = self.next_slot
            self.slot0_t0 = int(t0[b]) - self.next_slot * self.block_len
            self.event("config", None, f"board clock jumped (t0 {int(t0[b])} after slot {old - 1}): "
                       "time base re-anchored", self.stamp_ns(int(t0[b])))
            self._observe(t0[b:], vals[b:])
            return
        self._run(slots, vals)

    def _run(self, slots: np.ndarray, vals: np.ndarray) -> None:
        T = int(slots[-1]) + 1 - self.next_slot
        y = np.full((T, len(self.channels)), np.nan)
        valid = np.zeros((T, len(self.channels)), dtype=bool)
        rows = slots - self.next_slot
        y[rows] = vals[:, self._index]
        valid[rows] = True
        valid &= np.isfinite(y)
        first_slot = self.next_slot
        if self.acoustic is not None:
            self._estimate_vibration(first_slot, y, valid)
        if self.observe is not None:
            self.observe(first_slot, y, valid)
        y = y / self._baseline                  # the bank watches block RMS / baseline
        out = self.bank.process(y, valid)
        level = None if self._combined is None else np.where(self._combined, y, np.nan)
        self._pending.append((out.outlier, valid, level))
        self._pending_slots += T
        self.next_slot += T
        self.observations += int(valid.sum())
        self.missing_observations += int((~valid).sum())
        self._last_stamp_ns = self.slot_stamp_ns(self.next_slot - 1)
        if self.cfg.output.akf_trace:
            self._write_trace(first_slot, y, valid, out)
        self._release_decisions(final=False)

    def _estimate_vibration(self, first_slot: int, y: np.ndarray, valid: np.ndarray) -> None:
        """Microphone columns of y: block RMS [Pa] -> z = RMS^2 -> seed-002 estimator -> x^, the
        vibration energy [(m/s^2)^2] -> sqrt(x^) [m/s^2 RMS] replaces them in y (the bank watches
        it like an accelerometer's block RMS); /cm/<ch>/vibration_estimate per block."""
        cols = self._mic_cols
        ok = valid[:, cols]
        z = y[:, cols] ** 2
        est = self.acoustic.process(z, ok)
        rms = np.sqrt(np.maximum(est.x_hat, 0.0))
        y[:, cols] = np.where(ok, rms, np.nan)
        fields = [a.T.tolist() for a in (rms, est.x_hat, est.P_x, est.a_hat, est.P_a, est.y_hat,
                                          est.P_y, est.z_pred)]
        zl, okl = z.T.tolist(), ok.T.tolist()
        stamps = [self.slot_stamp_ns(first_slot + k) for k in range(y.shape[0])]
        for j, c in enumerate(cols):
            name = self.channels[c].name
            topic = f"/cm/{name}/vibration_estimate"
            xr, xh, px, ah, pa, yh, py, zp = (f[j] for f in fields)
            for k, stamp in enumerate(stamps):
                self.sink.write(topic, "vibration_estimate", stamp, {
                    "channel": name, "x_hat": _num(xr[k]), "x_ms": _num(xh[k]), "x_ms_var": _num(px[k]),
                    "a_hat": _num(ah[k]), "a_var": _num(pa[k]), "y_hat": _num(yh[k]),
                    "y_var": _num(py[k]), "z": zl[j][k] if okl[j][k] else None, "z_pred": _num(zp[k]),
                    "missing": not okl[j][k]})

    def _write_trace(self, first_slot, y, valid, out) -> None:
        i = self._trace_i
        zc = self.bank.z_c
        for c, ch in enumerate(self.channels):
            topic = f"/cm/{ch.name}/akf"
            xp = out.x_prior[:, c, i]
            xh = out.x_hat[:, c, i]
            sd = np.sqrt(out.Y[:, c, i])
            lo = (xp - zc[c] * sd).tolist()
            hi = (xp + zc[c] * sd).tolist()
            z = ((y[:, c] - xp) / sd).tolist()
            yl = y[:, c].tolist()
            xpl, xhl = xp.tolist(), xh.tolist()
            ol = out.outlier[:, c, i].tolist()
            ql = out.Q[:, c, i].tolist()
            for k in range(len(yl)):
                stamp = self.slot_stamp_ns(first_slot + k)
                if valid[k, c]:
                    msg = {"channel": ch.name, "filter": i + 1, "y": yl[k], "x_hat": xhl[k],
                           "x_prior": xpl[k], "lower": lo[k], "upper": hi[k], "z": z[k],
                           "outlier": bool(ol[k]), "q_hat": ql[k], "missing": False}
                else:
                    msg = {"channel": ch.name, "filter": i + 1, "y": None, "x_hat": _num(xhl[k]),
                           "x_prior": _num(xpl[k]), "lower": _num(lo[k]), "upper": _num(hi[k]),
                           "z": None, "outlier": False, "q_hat": _num(ql[k]), "missing": True}
                self.sink.write(topic, "akf", stamp, msg)

    def _write_decision(self, d: Decision) -> None:
        stamp = self.slot_stamp_ns(d.slot)
        n = self.bank.n
        for c, ch in enumerate(self.channels):
            sev = float(d.severity[c])
            level = int(round(sev * n))
            anomaly = d.anomaly[c].tolist()
            failure = bool(anomaly[-1]) or sev >= 1.0
            msg = {
                "channel": ch.name, "severity_index": sev, "level": level,
                "anomaly": anomaly, "outliers": d.cnt[c].tolist(), "f_r": float(d.f_r[c]),
                "r": self._R[c].tolist(), "failure": failure, "missing": int(d.missing[c]),
                "transient": d.transient,
            }
            if self._combined is not None and self._combined[c]:
                msg["severity_akf"] = float(d.severity_akf[c])
                msg["severity_level"] = float(d.severity_level[c])
                if np.isfinite(d.level[c]):
                    msg["level_ratio"] = float(d.level[c])
            self.sink.write(f"/cm/{ch.name}/severity", "severity", stamp, msg)
            v = self.views[c]
            v.severity, v.anomaly, v.outliers_first = sev, anomaly, int(d.cnt[c, 0])
            v.max_severity = max(v.max_severity, sev)
            v.decisions += 1
            prev = d.prev_anomaly[c]
            for i in np.flatnonzero(d.anomaly[c] != prev):
                r = self._R[c, i]
                cnt = int(d.cnt[c, i])
                if d.anomaly[c, i]:
                    self.event("anomaly_onset", ch.name, f"{ch.name}: AKF_{i + 1} (R={r:.4g}) anomaly: "
                               f"{cnt} outliers in the period >= f_r {d.f_r[c]:.4g}", stamp,
                               filter=int(i + 1), count=cnt)
                else:
                    self.event("anomaly_clear", ch.name, f"{ch.name}: AKF_{i + 1} (R={r:.4g}) anomaly "
                               f"cleared: {cnt} outliers < c*f_r", stamp, filter=int(i + 1), count=cnt)
            prev_sev = float(d.prev_severity[c])
            if sev != prev_sev:
                self.event("severity_change", ch.name, f"{ch.name}: severity index {prev_sev:.2f} -> "
                           f"{sev:.2f} (level {level}/{n})", stamp, severity_index=sev, level=level)
            was_failure = bool(prev[-1]) or prev_sev >= 1.0
            if failure and not was_failure:
                v.failures += 1
                why = (f"AKF_{n} with R_max={self._R[c, -1]:.4g} flags an anomaly" if anomaly[-1] else
                       f"level {float(d.level[c]):.2f} x baseline >= level_danger")
                self.event("failure", ch.name, f"{ch.name}: FAILURE: {why}", stamp,
                           severity_index=sev, level=level)
            elif was_failure and not failure:
                self.event("failure_clear", ch.name, f"{ch.name}: failure condition cleared "
                           f"(AKF_{n} back below c*f_r)", stamp, severity_index=sev, level=level)
        self._write_diagnostics(stamp)

    def _write_diagnostics(self, stamp: int) -> None:
        msg: dict[str, Any] = {
            "link": self.link_counters() if self.link_counters else {},
            "queue_depth": 0, "queue_drops": 0, "lag_s": 0.0,
            "observations": self.observations,
            "uptime_s": round(time.monotonic() - self.started_wall, 3),
        }
        if self.diagnostics is not None:
            msg.update(self.diagnostics())
        self.sink.write("/cm/diagnostics", "diagnostics", stamp, msg)

    def lag_s(self) -> float:
        """Wall-clock lag of the newest processed observation (live mode)."""
        if not self._last_stamp_ns:
            return 0.0
        return max(0.0, (self.clock_ns() - self._last_stamp_ns) / 1e9)


def _num(x: float):
    return None if x != x else x
