"""The shaft speed: TACHO frames (docs/PROTOCOL.md type 4) of the configured input ->
:class:`~cmsensord.dsp.tacho.TachoTracker`, created once a STATUS announces a tacho.

Until then at most ``TACHO_WAIT_FRAMES`` of the newest TACHO frames wait.  The
tracker's events (pulses lost, missed, restored ...) are returned as events;
the speed is read by the order chain and, as the decisions' f_r, by the
severity chain (:meth:`Shaft.period_f_r`).

A TACHO frame lost on the link (a gap in the input's t0 sequence) is a frame
loss, reported as such by the decoder's ``frames_lost``: the tracker counts the
pulses in it, or starts again after it, without an event (:mod:`cmsensord.dsp.tacho.gaps`),
and a missed pulse it finds next to lost frames, or in frames whose edges were dropped as
bad input, is not reported as ``tacho_missed_pulse`` (counted in
:attr:`Shaft.missed_in_lost_frames`).  TACHO frames that stop coming while the
data goes on (none lost) are told once, ``SILENT_S`` of board time on
(:meth:`Shaft.check_silent`); a STATUS announcing no tacho, or other pulses per
revolution, ends the tracker (:meth:`Shaft.changes_tacho`).
"""

from __future__ import annotations

import struct
from collections import deque
from collections.abc import Sequence
from operator import lt
from typing import TYPE_CHECKING

import numpy as np

from cmsensord.config import Config
from cmsensord.frame_batch import FrameBatch, Pending
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.events import Event
from cmsensord.protocol import Frame, ProtocolError, Status, decode_tacho, decode_tacho_many

try:  # the compiled reading of a live call's payloads is optional: read_tacho_payloads is the same
    from cmsensord.dsp import _trackerkernel as _kernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _kernel = None

if TYPE_CHECKING:
    from cmsensord.dsp.tacho import TachoTracker

#: TACHO frames kept while no tacho tracker exists (no STATUS announcing one yet)
TACHO_WAIT_FRAMES = 200
#: up to this many waiting TACHO frames are checked on Python ints (a live call), more on columns
_FEW_FRAMES = 64
#: board seconds of observations past the newest TACHO frame that make the tacho silent (``tacho_lost``)
SILENT_S = 10.0
#: gaps of lost TACHO frames remembered (the tracker reports a missed pulse a few frames late)
LOST_GAPS = 64


#: up to this many TACHO payloads (a live call's ten or so) are read one by one with struct
FEW_TACHO = 32


def decode_tacho_lists(payloads: Sequence[bytes]) -> tuple[list[int], list[int], list[tuple[int, str]]]:
    """The edge counts, the edge offsets (frame after frame) and the (index, message) of each
    malformed payload of TACHO ``payloads``, as Python lists (what a live call feeds the
    tracker; the numbers and messages of :func:`~cmsensord.protocol.decode_tacho_many`): a list of
    well-formed payloads in one compiled step (``_trackerkernel.tacho_payloads``) when the
    kernel is built, any other payload by payload (:func:`read_tacho_payloads`)."""
    if _kernel is not None and type(payloads) is list:
        got = _kernel.tacho_payloads(payloads)
        if got is not None:
            return got[0], got[1], []
    return read_tacho_payloads(payloads)


def read_tacho_payloads(payloads: Sequence[bytes]) -> tuple[list[int], list[int], list[tuple[int, str]]]:
    """:func:`decode_tacho_lists` payload by payload with struct, a malformed one with
    :func:`~cmsensord.protocol.decode_tacho`'s message."""
    counts: list[int] = []
    offsets: list[int] = []
    bad = []
    for i, p in enumerate(payloads):
        n = len(p)
        if n >= 2:
            c = p[0] | p[1] << 8
            if n == 2 + 4 * c:
                counts.append(c)
                if c:
                    offsets += struct.unpack_from(f"<{c}I", p, 2)
                continue
        try:
            decode_tacho(p)
        except ProtocolError as exc:
            bad.append((i, str(exc)))
        counts.append(0)
    return counts, offsets, bad


class Shaft:
    """TACHO frames -> tacho tracker (see module docstring)."""

    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.waiting = Pending()                 # TACHO frames of the input, in order (lists or batches)
        self.tacho: TachoTracker | None = None  # once STATUS announces a tacho
        self._prev_t0: int | None = None         # t0 of the last TACHO frame fed
        self._fed_t0: int | None = None          # newest t0 given to the tracker
        self._bad_ppr: int | None = None
        self.notes: list[Event] = []             # events of ensure(), for the processor to emit
        self._gaps: deque[tuple[int, int]] = deque(maxlen=LOST_GAPS)   # [first, end) samples not covered
        self._silences: deque[tuple[int, int]] = deque(maxlen=LOST_GAPS)   # those gaps of SILENT_S or more
        self.missed_in_lost_frames = 0
        self._silent_since: int | None = None    # told: no TACHO frame from this sample on
        self.other_inputs: set[int] = set()      # the inputs of TACHO frames not the configured one

    def add(self, f: Frame) -> None:
        """A TACHO frame of any input; only the configured one is kept."""
        self.add_many([f])

    def add_many(self, frames: Sequence[Frame]) -> None:
        """TACHO frames of any input, in order; only the configured one's are kept (at most
        ``TACHO_WAIT_FRAMES``, the newest, until the tracker exists: only :meth:`ensure`
        makes it, so it cannot appear between them).  A batch's frames stay columns."""
        inp = self.cfg.tacho.input
        if type(frames) is FrameBatch:
            mine = frames.cols.chan == inp
            if not mine.all():
                self.other_inputs.update(np.unique(frames.cols.chan[~mine]).tolist())
            self.waiting.extend(frames if mine.all() else frames.take(np.flatnonzero(mine)))
        else:
            kept = [f for f in frames if f.chan == inp]
            if len(kept) < len(frames):
                self.other_inputs.update(f.chan for f in frames if f.chan != inp)
            self.waiting.extend(kept)
        if self.tacho is None and len(self.waiting) > TACHO_WAIT_FRAMES:
            newest = self.waiting.joined()[-TACHO_WAIT_FRAMES:]   # no STATUS yet: keep only the newest
            self.waiting = Pending()
            self.waiting.extend(newest)

    def restart(self, status: Status | None, clock: BlockClock) -> None:
        """The board's samples count anew (a reset, a new rate; the TACHO frames before it fed):
        so does the tracker (a new one, if the board has a tacho)."""
        if self.tacho is not None and status is not None and not status.tacho_inputs:
            self.notes.append(Event("config", None, "the board has no tacho now: no shaft speed, no orders, "
                                    "decisions on the configured f_r"))
        self.tacho = None
        self.waiting = Pending()
        self._prev_t0 = self._fed_t0 = self._silent_since = None
        self._gaps.clear()
        self._silences.clear()
        self.ensure(status, clock)

    def check_silent(self, clock: BlockClock, t0: np.ndarray) -> list[Event]:
        """A ``tacho_lost`` event, once, when a data block (of those starting at ``t0``) starts
        ``SILENT_S`` or more after the end of the TACHO frame before it (fed or waiting; or the
        time base's start, before any): the board announces a tacho but sends none, none of them
        lost (a link loss stops the data too).  The tracker cannot tell: no frame, no timeout.
        Judged on the frames alone, so however the stream was read; when frames come again, the
        tracker's own ``tacho_lost`` of the silence is not told twice (:meth:`feed`)."""
        if self.tacho is None or self._silent_since is not None or not len(t0) or clock.t0_first is None:
            return []
        L, silent = clock.block_len, round(SILENT_S * clock.fs)
        fed = clock.t0_first - L if self._fed_t0 is None else max(clock.t0_first - L, self._fed_t0)
        if int(t0.max()) - fed - L < silent:       # every block within the wait of the newest fed
            return []
        waiting = self._waiting_t0()
        tachos = np.concatenate(([fed], np.sort(waiting[waiting > fed])))
        data = np.sort(t0[t0 > fed])
        prev = tachos[np.searchsorted(tachos, data, side="right") - 1]     # the newest TACHO at or before
        hit = np.flatnonzero(data - prev - L >= silent)
        if not hit.size:
            return []
        since = self._silent_since = int(prev[hit[0]]) + L
        inp = self.cfg.tacho.input
        others = (f" (TACHO frames come on input {', '.join(map(str, sorted(self.other_inputs)))}: see tacho.input)"
                  if self.other_inputs else "")
        return [Event("tacho_lost", None, f"no TACHO frame of input {inp} for {SILENT_S:g} s of board time while "
                      f"the board sends data: no shaft speed since sample {since}{others}",
                      clock.stamp_ns(since + silent))]

    def _waiting_t0(self) -> np.ndarray:
        """The t0 of the waiting TACHO frames, in their order."""
        parts = [p.cols.t0_unwrapped if type(p) is FrameBatch else np.array([f.t0_unwrapped for f in p], dtype=np.int64)
                 for p in self.waiting.parts]
        return np.concatenate(parts) if parts else np.empty(0, dtype=np.int64)

    def changes_tacho(self, status: Status) -> bool:
        """Whether ``status`` announces no tacho, or other pulses per revolution than the tracker
        counts with (the configured ``tacho.ppr`` overrides the board's), while there is one."""
        return self.tacho is not None and (
            not status.tacho_inputs or (self.cfg.tacho.ppr or status.tacho_ppr) != self.tacho.ppr)

    def ensure(self, status: Status | None, clock: BlockClock) -> bool:
        """Create the tracker once the board has said it has a tacho; True when there is one."""
        if self.tacho is None and status is not None and status.tacho_inputs > 0:
            from cmsensord.dsp.tacho import TachoTracker

            t = self.cfg.tacho
            ppr = t.ppr or status.tacho_ppr
            if not 1 <= ppr <= 255:
                if ppr != self._bad_ppr:
                    self._bad_ppr = ppr
                    self.notes.append(Event("decode_error", None, f"STATUS announces a tacho with {ppr} pulses "
                                            "per revolution: no shaft speed (set tacho.ppr)"))
                return False
            h = max(1, round(t.smoothing_revs * ppr))
            m = min(64, max(2, round(t.causal_revs * ppr)))
            self.tacho = TachoTracker(clock.fs, ppr, block_len=clock.block_len, half_window=h,
                                      timeout_s=t.timeout_s, causal_window=m)
        return self.tacho is not None

    def tracker(self) -> TachoTracker:
        """The tracker; only called once :meth:`ensure` has returned True."""
        assert self.tacho is not None, "no tacho tracker before ensure()"
        return self.tacho

    def feed(self, clock: BlockClock, before: int | None = None) -> list[Event]:
        """The waiting TACHO frames -> the tracker; its events (and bad payloads).  With
        ``before``: only those in front of the first whose t0 is at or after it (the rest wait)."""
        waiting = self.waiting.joined()
        self.waiting = Pending()
        events: list[Event] = []
        if before is not None:
            waiting = self._in_front_of(waiting, before)
            if not len(waiting):
                return events
        frames: Sequence[Frame]
        if type(waiting) is FrameBatch and len(waiting) > _FEW_FRAMES:
            frames, dropped, t0s = self._in_time_order_columns(waiting)
            payloads = frames.payloads()
        else:
            frames, dropped, t0s = self._in_time_order(list(waiting))
            payloads = [f.payload for f in frames]
        for t in dropped:
            events.append(Event("decode_error", None, f"TACHO frame at t0 {t} not after the newest one in board "
                                "time: dropped (the tacho needs time order, one frame a block)", clock.stamp_ns(t)))
        tracker = self.tracker()                # the smoothed speed: fitted when asked for
        limit = clock.block_len * 256           # an edge is inside its block (docs/PROTOCOL.md, TACHO)
        if len(payloads) <= FEW_TACHO:          # a live call's few: on Python ints
            counts, offsets, bad = decode_tacho_lists(payloads)
            sent = counts
            if offsets and max(offsets) >= limit:
                c, o = _inside(np.array(counts), np.array(offsets, dtype=np.int64), limit, t0s, clock, events)
                counts, offsets = c.tolist(), o.tolist()
            if max(counts, default=0) > 1 and _repeats(counts, offsets):
                c, o = _distinct(np.array(counts), np.array(offsets, dtype=np.int64), t0s, clock, events)
                counts, offsets = c.tolist(), o.tolist()
            fed = tracker.feed_few(t0s, counts, offsets)
            broken = [t for t, a, b in zip(t0s, sent, counts) if b < a] if events else []
        else:
            counts_a, offsets_a, bad = decode_tacho_many(payloads)
            sent_a = counts_a
            if offsets_a.size and int(offsets_a.max()) >= limit:
                counts_a, offsets_a = _inside(counts_a, offsets_a.astype(np.int64), limit, t0s, clock, events)
            if counts_a.size and int(counts_a.max()) > 1:
                counts_a, offsets_a = _distinct(counts_a, offsets_a, t0s, clock, events)
            fed = tracker.feed_flat(np.array(t0s, dtype=np.int64), counts_a, offsets_a)
            broken = np.asarray(t0s)[counts_a < sent_a].tolist() if events else []
        for i, message in bad:
            events.append(Event("decode_error", None, f"bad TACHO payload at byte {frames[i].offset}: {message}",
                                clock.stamp_ns(t0s[i])))
        self._note_gaps(t0s, clock.block_len, round(SILENT_S * clock.fs))
        self._note_broken(broken, clock.block_len)
        told = self._silent_since is not None and t0s[-1] >= self._silent_since    # frames again after it
        if told:
            self._silent_since = None
        for ev in fed:
            if ev.kind == "tacho_missed_pulse" and self._in_gap(ev.sample, clock.block_len):
                self.missed_in_lost_frames += int(ev.count)
                continue
            if told and ev.kind == "tacho_lost":  # the silence, told by check_silent
                continue
            events.append(Event(ev.kind, None, ev.message, clock.stamp_ns(int(ev.sample)),
                                {"count": int(ev.count)}))
        return events

    def waits_before(self, t0: int) -> bool:
        """Whether the first waiting TACHO frame starts before board sample ``t0``."""
        if not self.waiting.parts:
            return False
        first = self.waiting.parts[0]
        return int(first.cols.t0_unwrapped[0] if type(first) is FrameBatch else first[0].t0_unwrapped) < t0

    def _in_front_of(self, frames: Sequence[Frame], before: int) -> Sequence[Frame]:
        """The frames in front of the first whose t0 is at or after ``before``; the rest wait."""
        if type(frames) is FrameBatch:
            late = (frames.cols.t0_unwrapped >= before).nonzero()[0]
            k = int(late[0]) if late.size else len(frames)
        else:
            k = next((i for i, f in enumerate(frames) if f.t0_unwrapped >= before), len(frames))
        self.waiting.extend(frames[k:])
        return frames[:k]

    def _in_time_order(self, frames: list[Frame]) -> tuple[list[Frame], list[int], list[int]]:
        """The frames after the newest t0 fed so far, the t0 of those that did not step on
        (dropped: one back, or a block's frame sent again under its t0), and the t0 of those
        kept.  On Python ints: a live call brings about ten frames, in time order and after those
        fed (then all of them are kept, at once)."""
        fed = self._fed_t0
        ts = [f.t0_unwrapped for f in frames]
        if ts and (fed is None or ts[0] > fed) and all(map(lt, ts, ts[1:])):
            self._fed_t0 = ts[-1]
            return frames, [], ts
        kept: list[Frame] = []
        t0s: list[int] = []
        dropped: list[int] = []
        newest = before = None                      # the newest t0 before each (kept or not)
        for f in frames:
            t = f.t0_unwrapped
            before = (t - 1 if fed is None else fed) if newest is None else \
                (newest if fed is None else max(newest, fed))
            if t > before:
                kept.append(f)
                t0s.append(t)
            else:
                dropped.append(t)
            newest = t if newest is None else max(newest, t)
        if newest is not None and before is not None:
            self._fed_t0 = max(before, frames[-1].t0_unwrapped)
        return kept, dropped, t0s

    def _in_time_order_columns(self, frames: FrameBatch) -> tuple[FrameBatch, list[int], list[int]]:
        """:meth:`_in_time_order` of a batch, on its t0 column (a replay's reads bring hundreds
        of frames): frame i is kept when its t0 is after the newest one before it (and
        the newest fed so far); the same frames, t0 lists and ``_fed_t0``."""
        t0 = frames.cols.t0_unwrapped
        fed = self._fed_t0
        before = np.empty_like(t0)
        before[0] = t0[0] - 1 if fed is None else fed
        np.maximum.accumulate(t0[:-1], out=before[1:])
        if fed is not None:
            np.maximum(before, fed, out=before)
        keep = t0 > before
        self._fed_t0 = max(int(before[-1]), int(t0[-1]))
        if keep.all():
            return frames, [], t0.tolist()
        kept = np.flatnonzero(keep)
        return frames.take(kept), t0[~keep].tolist(), t0[kept].tolist()

    def _note_gaps(self, t0: list[int], L: int, silent: int | None = None) -> None:
        """Gaps between consecutive TACHO frames (one per block): lost frames, or a silence of the
        tacho when ``silent`` samples or more."""
        if not t0:
            return
        prev = t0[0] if self._prev_t0 is None else self._prev_t0
        for t in t0:
            if t - prev > L:
                self._gaps.append((prev + L, t))
                if silent is not None and t - prev - L >= silent:
                    self._silences.append((prev + L, t))
            prev = t
        self._prev_t0 = t0[-1]

    def _note_broken(self, t0: list[int], L: int) -> None:
        """The blocks of TACHO frames whose edges were dropped as bad input: gaps as lost frames
        are (the pulses the tracker misses in them are no encoder's), a run of them one gap."""
        for t in t0:
            if self._gaps and self._gaps[-1][0] <= t <= self._gaps[-1][1] + L:      # a block apart: one run
                self._gaps[-1] = (self._gaps[-1][0], max(self._gaps[-1][1], t + L))
            else:
                self._gaps.append((t, t + L))

    def uncovered(self, samples: np.ndarray) -> np.ndarray:
        """Which board ``samples`` (ascending) no TACHO frame covers: after the newest, or in a
        silence, a gap of at least ``SILENT_S`` between two (of the last ``LOST_GAPS``): the
        tacho has not told what the shaft did there.  What waited there longer than the wait for
        the speed went on before the next frame came, uncovered; the rest after it, in the gap:
        either way no speed, however the stream was read.  A shorter gap (frames lost on the link)
        keeps the tracker's speed."""
        out = samples >= self.tracker().covered_until
        lo, hi = samples[0], samples[-1]
        for a, b in self._silences:
            if a <= hi and b > lo:
                out |= (samples >= a) & (samples < b)
        return out

    def _in_gap(self, sample: float, L: int) -> bool:
        """True when ``sample`` is in (or within a block of) a gap of lost TACHO frames."""
        return any(a - L <= sample < b + L for a, b in self._gaps)

    def final_slot(self, clock: BlockClock) -> int:
        """The first observation slot whose speed is not final yet (none before the slots
        are anchored)."""
        if clock.slot0_t0 is None:
            return 0
        return int((self.tracker().final_until - clock.slot_t0(0)) // clock.block_len)

    def period_f_r(self, clock: BlockClock, cfg_f_r: np.ndarray, end_slot: int, period: int) -> np.ndarray:
        """Mean tacho speed [Hz] over the decision period ending at ``end_slot``, per channel
        (the configured ``cfg_f_r`` where the tacho has no valid speed)."""
        if clock.slot0_t0 is None:
            return cfg_f_r
        slots = np.arange(end_slot - period, end_slot)
        hz, _, ok = self.tracker().evaluate(clock.slot_t0(slots))
        if ok.mean() < 0.5:
            return cfg_f_r
        return np.full(len(cfg_f_r), float(np.mean(hz[ok])))


def _repeats(counts: list[int], offsets: list[int]) -> bool:
    """Whether a frame (``counts`` edges each, their ``offsets`` frame after frame) has at least
    half of its edges at the offset of another edge of it (:func:`_distinct` drops it)."""
    pos = 0
    for n in counts:
        if n > 1 and 2 * (n - len(set(offsets[pos:pos + n]))) >= n:
            return True
        pos += n
    return False


def _distinct(counts: np.ndarray, offsets: np.ndarray, t0s: list[int], clock: BlockClock,
              events: list[Event]) -> tuple[np.ndarray, np.ndarray]:
    """The edges of the frames (``counts`` edges each, their ``offsets`` frame after frame) but
    those of a frame with at least half of its edges at the offset of another edge of it: per
    frame and flat; each such frame dropped whole, with a ``decode_error`` event at its t0 (a
    timer capture gives one rising edge an instant: the frame is broken or hostile, and its
    edges would be read as a pulse a block).  An edge here and there at the offset of another
    (the tracker ignores it) keeps its frame."""
    frame = np.repeat(np.arange(len(counts)), counts)
    order = np.lexsort((offsets, frame))
    f, o = frame[order], offsets[order]
    same = (f[1:] == f[:-1]) & (o[1:] == o[:-1])
    repeats = np.bincount(f[1:][same], minlength=len(counts))
    drop = np.flatnonzero((repeats > 0) & (2 * repeats >= counts))
    if not drop.size:
        return counts, offsets
    for i in drop.tolist():
        events.append(Event("decode_error", None, f"TACHO frame at t0 {t0s[i]}: {int(repeats[i])} of its "
                            f"{int(counts[i])} edges at the offset of another (one rising edge an instant): dropped",
                            clock.stamp_ns(t0s[i])))
    keep = np.ones(len(counts), dtype=bool)
    keep[drop] = False
    return np.where(keep, counts, 0), offsets[keep[frame]]


def _inside(counts: np.ndarray, offsets: np.ndarray, limit: int, t0s: list[int], clock: BlockClock,
            events: list[Event]) -> tuple[np.ndarray, np.ndarray]:
    """The edges inside their frame's block (offsets below ``limit``, 1/256 sample), per frame
    (``counts``) and flat (``offsets``); a ``decode_error`` event, at its t0, for each frame with
    an edge outside it (a hostile or broken frame: it would place the speed anywhere in time)."""
    frame = np.repeat(np.arange(len(counts)), counts)
    out = offsets >= limit
    for i in np.unique(frame[out]).tolist():
        n = int(np.count_nonzero(out[frame == i]))
        events.append(Event("decode_error", None, f"TACHO frame at t0 {t0s[i]}: {n} edge(s) outside its block "
                            f"(offsets of {limit // 256} samples or more) dropped", clock.stamp_ns(t0s[i])))
    return counts - np.bincount(frame[out], minlength=len(counts)), offsets[~out]
