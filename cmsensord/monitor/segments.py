"""Time segments of the stream: board resets, a board clock drifting off the wall clock,
and frames of the mode the board is not in.

A frame whose t0 steps back by a block or more, or forward by more than ``MAX_GAP_S``, means
the board restarted its clock (a reset, a replug of a rebooted board; one a few samples behind
the frame before it is no restart: :func:`~cmsensord.monitor.clock.is_reset`): a new segment
starts (:meth:`~cmsensord.monitor.clock.BlockClock.new_segment`), stamped from the
wall clock at the reset and never before the newest stamp, with a ``time_base``
event; the seq gap in front of that frame is not a loss (the board restarted its
seq too).  Live, a board clock off the wall clock by more than ``link.max_drift_s``
starts a new segment at the board's measured rate, with a ``time_base`` event (a silent
link is no drift: the rate is measured from the frames after it on); a step of
the wall clock itself (an NTP sync) re-anchors the stamps to it at once, with one
``time_base`` event, and a step back finishes the log file, so each file keeps its
messages in time order (:meth:`Segments.check_wall`).

RAW frames in an RMS stream (STATUS says RMS mode), or RMS frames in a RAW one,
are ignored: each run of them is counted in one ``decode_error`` event when it ends.

A break in the link in front of a frame, a seq gap or frames the receiver dropped as
repeats (:mod:`cmsensord.frame_repeats`), is a ``frames_lost`` or ``frames_repeated``
event (:meth:`Segments.gaps`).  A seq gap counts its frames mod 65536 (docs/PROTOCOL.md
rule 3), and the u16 seq wraps every 65536 frames: 131 s of RAW 4 channels and a tacho.
An outage longer than that hides whole wraps, which the t0 gap shows: the frames the board
sends in it (STATUS: blocks a second times frames a block, and a STATUS a second) less the
seq gap, in whole wraps, are lost too (an extension of rule 3).  A seq gap larger than the
frames the board sends over the t0 gap (the seq stepping back while t0 goes on, a seq field
off) is no loss t0 could hold: it is a ``decode_error`` event naming the seqs and the t0 step,
and no frame is counted lost for it.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Iterator, Sequence
from operator import attrgetter, sub
from typing import NamedTuple

import numpy as np

from cmsensord.frame_repeats import REPEATS_SHIFT, repeats_before
from cmsensord.monitor.channels import ChannelSetup
from cmsensord.monitor.clock import MAX_GAP_S, QUIET_S, BlockClock, WallSteps
from cmsensord.monitor.events import EventLog
from cmsensord.protocol import Frame, FrameType

#: STATUS mode -> the data frame type the board does not send in it
_OTHER = {1: FrameType.RAW, 2: FrameType.RMS}
#: ... and their codes as plain ints, for numpy (comparing an array with an IntEnum looks up
#: dunders on the enum class, a Python call each)
_OTHER_CODE = {mode: int(t) for mode, t in _OTHER.items()}
_STATUS_CODE = int(FrameType.STATUS)
_NAME = {FrameType.RAW: "RAW", FrameType.RMS: "RMS"}
#: batches at least this long are checked in one pass (:meth:`Segments.runs`)
SCAN_MIN = 32
#: a field of every frame of a batch, in one C-level pass
_TYPE, _T0, _LOST, _FLAGS = (attrgetter(name) for name in ("type", "t0_unwrapped", "lost_before", "flags"))
#: flags above this: the receiver dropped repeats in front of the frame
WIRE_FLAGS = (1 << REPEATS_SHIFT) - 1
#: a STATUS payload's mode, fs and block_len (docs/PROTOCOL.md: after u16 firmware version, u8 C)
_MODE_FS_BLOCK = struct.Struct("<2xB1xIH")
#: after a frame that does not pass, this many frames are checked one by one before the next pass
SCAN_RETRY = 8


class FrameColumns(NamedTuple):
    """What :meth:`Segments.check` reads of each frame of a batch, as arrays."""

    code: np.ndarray    # the type code; -1 for a type that is not a FrameType (a frame built by hand)
    t0: np.ndarray      # t0_unwrapped
    lost: np.ndarray    # a break in the link in front of it (a seq gap, repeats dropped)
    frames: Sequence[Frame]     # the batch (a STATUS frame's payload is read from it)


def frame_columns(frames: Sequence[Frame]) -> FrameColumns:
    """The columns of a batch: read from a :class:`~cmsensord.protocol.FrameBatch` as they are,
    else one C-level pass (``map``) per field."""
    cols = getattr(frames, "columns", None)
    if cols is not None:
        code, t0, lost = cols()
        return FrameColumns(code, t0, lost, frames)
    n = len(frames)
    types = list(map(_TYPE, frames))
    if set(map(type, types)) <= {FrameType}:
        code = np.fromiter(types, dtype=np.int64, count=n)
    else:                               # a frame built by hand with a type that is no FrameType
        code = np.fromiter((t if type(t) is FrameType else -1 for t in types), dtype=np.int64, count=n)
    t0 = np.fromiter(map(_T0, frames), dtype=np.int64, count=n)
    lost = np.fromiter(map(_LOST, frames), dtype=np.int64, count=n) != 0
    lost |= np.fromiter(map(_FLAGS, frames), dtype=np.int64, count=n) > WIRE_FLAGS
    return FrameColumns(code, t0, lost, frames)


def _names(payload: bytes, mode: int, fs: int, block_len: int) -> bool:
    """True when a STATUS payload names board mode ``mode``, rate ``fs`` and block length
    ``block_len`` (what :meth:`Segments.check` reads): taken or refused, it changes none."""
    return len(payload) >= _MODE_FS_BLOCK.size and _MODE_FS_BLOCK.unpack_from(payload) == (mode, fs, block_len)


class Segments:
    """Resets, drift and frames of the other mode for one Processor (see module docstring).

    ``flush``: processes what waits before a reset (the last, maybe incomplete RAW block).
    """

    def __init__(self, clock: BlockClock, setup: ChannelSetup, log: EventLog,
                 clock_ns: Callable[[], int], flush: Callable[[], None]):
        self.clock, self.setup, self.log = clock, setup, log
        self.clock_ns, self.flush = clock_ns, flush
        self.last_t0: int | None = None     # t0_unwrapped of the newest frame taken
        self.previous_t0 = 0                # before the frame that :meth:`check` found a reset
        self.ignored = 0                    # frames of the other mode in the current run
        self.ignored_type: FrameType | None = None
        self.ignored_total = 0
        self.hit = False                    # the last frame checked needs :meth:`start`
        self.seq_restarts = 0               # frames the link counted lost in seq gaps at resets
        self.seq_wraps = 0                  # frames lost in whole seq wraps the t0 gaps show
        self.seq_off = 0                    # frames the link counted lost in seq gaps t0 cannot hold
        self.repeats_told = 0               # repeats the frames after them carried (frames_repeated events)
        self.before_t0: int | None = None   # t0_unwrapped of the frame before the one checked
        self._marked: tuple | None = None   # (cols, mode, fs, bad, status) of :meth:`_marks`
        self.wall = WallSteps()

    def check(self, f: Frame) -> bool:
        """True when ``f`` is a board reset or a frame of the other mode: call :meth:`start`
        (:meth:`pending` says so until the next check)."""
        self.hit = self._check(f)
        return self.hit

    def passes(self, frames: Sequence[Frame]) -> bool:
        """True when every one of ``frames`` (a live call's, at least one) passes :meth:`check`
        with no seq gap in front of it and none is a STATUS frame (which may change the mode or
        fs the check reads): :meth:`check`'s effects are applied for them, in a few C-level
        passes.  False (nothing applied): the caller checks them (:meth:`check`, :meth:`runs`)."""
        st = self.setup.status
        types = set(map(_TYPE, frames))
        if FrameType.STATUS in types or (st is not None and _OTHER.get(st.mode) in types) \
                or any(map(_LOST, frames)) or max(map(_FLAGS, frames)) > WIRE_FLAGS:
            return False
        t = list(map(_T0, frames))
        last = self.last_t0
        steps = list(map(sub, t, [t[0] if last is None else last, *t[:-1]]))   # from the frame before
        if min(steps) <= -self.clock.block_len or max(steps) > MAX_GAP_S * self.clock.fs:   # is_reset
            return False
        if self.ignored:
            self._report()
        self.last_t0 = t[-1]
        self.hit = False
        return True

    def runs(self, frames: Sequence[Frame]) -> Iterator[tuple[int, int, np.ndarray | None]]:
        """The frames in order as runs ``frames[a:b]``: with their type codes when every one is
        known to pass :meth:`check` with no seq gap in front of it (:meth:`check`'s effects
        applied: the caller takes them as they are), with None for one frame the caller is to
        :meth:`check`.  A long batch is checked in one pass up to its first frame that does not
        pass or its first STATUS frame that may change the mode or fs the check reads (one that
        names the mode and fs in force cannot), then on from there, lazily: each pass sees the
        state the frames before it left."""
        n = len(frames)
        if n < SCAN_MIN:
            for k in range(n):
                yield k, k + 1, None
            return
        cols = frame_columns(frames)
        k, wait = 0, 0
        while k < n:
            p = 0
            if wait:
                wait -= 1
            else:
                p = self._passing(cols, k)
                wait = 0 if p else SCAN_RETRY
            if p:
                yield k, k + p, cols.code[k:k + p]
                k += p
            else:
                yield k, k + 1, None
                k += 1

    def _passing(self, cols: FrameColumns, start: int) -> int:
        """How many frames from ``start`` pass :meth:`check` with no seq gap, up to and
        including the first STATUS frame that may change the mode or fs; applies :meth:`check`'s
        effects for them.

        The frames that fail against the frame before them and the STATUS frames of the batch
        are found once per batch, mode and rate (:meth:`_marks`); only the frame at ``start``
        is checked against :attr:`last_t0` here."""
        st = self.setup.status
        mode = st.mode if st is not None else None
        other = _OTHER_CODE.get(mode) if mode is not None else None
        bad, status = self._marks(cols, mode)
        code, t, lost, _ = cols
        t_s, last = int(t[start]), self.last_t0
        if lost[start] or code[start] < 0 or (other is not None and code[start] == other) \
                or (last is not None and self.clock.is_reset(t_s, last)):
            return 0
        j = int(bad.searchsorted(start + 1))
        end = int(bad[j]) if j < bad.size else t.size
        j = int(status.searchsorted(start))
        if j < status.size and status[j] < end:
            end = int(status[j]) + 1
        k = end - start
        if self.ignored:
            self._report()
        self.last_t0 = int(t[end - 1])
        self.hit = False
        return k

    def _marks(self, cols: FrameColumns, mode: int | None) -> tuple[np.ndarray, np.ndarray]:
        """(indices of the frames of ``cols`` that fail :meth:`check` against the frame before
        them or are of the other mode than ``mode`` or follow a seq gap, indices of its STATUS
        frames that may change the mode or the fs), kept while the batch, the mode and the
        rate stay."""
        fs, block_len = self.clock.fs, self.clock.block_len
        m = self._marked
        if m is not None and m[0] is cols and m[1] == mode and m[2] == (fs, block_len):
            return m[3], m[4]
        other = _OTHER_CODE.get(mode) if mode is not None else None
        code, t, lost, frames = cols
        prev = np.empty_like(t)
        prev[:1] = t[:1]
        prev[1:] = t[:-1]
        bad = lost | (code < 0) | (t <= prev - block_len) | (t - prev > MAX_GAP_S * fs)   # is_reset
        if other is not None:
            bad |= code == other
        status = (code == _STATUS_CODE).nonzero()[0]
        if mode is not None and status.size:    # one naming the mode, fs and block in force changes none
            status = np.array([i for i in status.tolist() if not _names(frames[i].payload, mode, fs, block_len)],
                              dtype=np.int64)
        marks = bad.nonzero()[0], status
        self._marked = (cols, mode, (fs, block_len), *marks)
        return marks

    def pending(self, f: Frame) -> bool:
        """True when the last :meth:`check` (of ``f``) found a reset or the other mode."""
        return self.hit

    def _check(self, f: Frame) -> bool:
        st = self.setup.status
        if st is not None and f.type is _OTHER.get(st.mode):
            return True
        if self.ignored:
            self._report()
        t, last = f.t0_unwrapped, self.last_t0
        self.last_t0, self.before_t0 = t, last
        if last is not None and self.clock.is_reset(t, last):
            self.previous_t0 = last
            return True
        return False

    def start(self, f: Frame) -> bool:
        """After :meth:`check` said so (and the frames before ``f`` are processed): True when
        ``f`` is to be skipped (the other mode); else ``f`` starts a new segment."""
        st = self.setup.status
        if st is not None and f.type is _OTHER.get(st.mode):
            self.ignored += 1
            self.ignored_type = f.type
            return True
        self.flush()
        self.log.flush(summaries=False)     # the old segment's events before the new one's
        stamp = self.clock.new_segment(f.t0_unwrapped, self.clock_ns())
        lost = (f"; the seq gap of {f.lost_before} in front of it is not a loss (seq restarted)"
                if f.lost_before else "")
        self.seq_restarts += f.lost_before
        # the t0 fields as the board sent them (the unwrapped index wraps at 2^32 with them)
        self.log.emit("time_base", None, f"board clock restarted (t0 {f.t0} after "
                   f"{self.previous_t0 & 0xFFFFFFFF}): time segment {self.clock.segment} starts at the wall "
                   f"clock{lost}", stamp, details={"segment": self.clock.segment, "reason": "reset"})
        return False

    def gaps(self, f: Frame, stamp: int | None) -> int:
        """The break in the link in front of ``f`` as events: the repeats the receiver dropped, and
        its seq gap unless it starts a new segment (``stamp`` None, the gap is no loss); the frames lost."""
        n = repeats_before(f.flags)
        if n:
            self.repeats_told += n
            self.log.emit("frames_repeated", None, f"{n} frame(s) received again before seq {f.seq} (the "
                          "same frames as already received): dropped", stamp, count=n)
        if stamp is None or not f.lost_before:
            return 0
        room = self._room(f)
        if room is not None and f.lost_before > room:
            self.seq_off += f.lost_before
            step = f.t0_unwrapped - (self.before_t0 or 0)
            again = ", or a frame sent again with new content" if f.lost_before >= 0x8000 else ""
            self.log.emit("decode_error", None, f"seq {f.seq} after seq {(f.seq - f.lost_before - 1) & 0xFFFF} "
                          f"while t0 went on {step} sample(s) ({step / self.clock.fs:.2f} s): the seq did not go "
                          f"on with t0 (a seq glitch{again}); not counted as {f.lost_before} frame(s) lost", stamp)
            return 0
        wraps = self._wraps(f)
        lost = f.lost_before + wraps * 65536
        self.seq_wraps += wraps * 65536
        said = "seq gap" if not wraps else (f"seq gap of {f.lost_before} and {wraps} whole wrap(s) of the seq: t0 "
                                            f"jumped {(f.t0_unwrapped - (self.before_t0 or 0)) / self.clock.fs:.1f} s")
        self.log.emit("frames_lost", None, f"{lost} frame(s) lost before seq {f.seq} ({said})", stamp, count=lost)
        return lost

    def _room(self, f: Frame) -> int | None:
        """The most frames the board (by its STATUS) sends between the frame before ``f`` and
        ``f``, with a frame of slack: the seq gaps t0 can hold (None without a STATUS)."""
        st = self.setup.status
        if st is None or self.before_t0 is None or st.fs <= 0 or st.block_len <= 0:
            return None
        per_block = (1 if st.mode == 1 else st.n_channels) + st.tacho_inputs
        step = max(0, f.t0_unwrapped - self.before_t0)
        return math.ceil((step / st.block_len + 1) * per_block + step / st.fs) + 1

    def _wraps(self, f: Frame) -> int:
        """The whole wraps of the u16 seq in the gap in front of ``f``: the frames the board sends
        (by its STATUS) over the t0 gap, less the seq gap, in whole 65536s (0 without a STATUS)."""
        st = self.setup.status
        if st is None or self.before_t0 is None or st.fs <= 0 or st.block_len <= 0:
            return 0
        per_block = (1 if st.mode == 1 else st.n_channels) + st.tacho_inputs
        sent = (f.t0_unwrapped - self.before_t0) / st.block_len * per_block \
            + (f.t0_unwrapped - self.before_t0) / st.fs
        return max(0, round((sent - f.lost_before) / 65536))

    def link(self, counters: dict) -> dict:
        """The link's ``counters``; a seq gap in front of a board reset is no loss (the board
        restarted its seq), nor is one t0 cannot hold (:meth:`_room`), so ``frames_lost`` leaves
        them out, and adds the whole seq wraps the t0 gaps show (:meth:`_wraps`)."""
        if "frames_lost" in counters:
            counters = {**counters, "frames_lost": counters["frames_lost"] - self.seq_restarts - self.seq_off
                        + self.seq_wraps}
        return counters

    def check_wall(self, now_ns: int, max_drift_s: float, hand_over: Callable[[], None],
                   quiet_s: float = QUIET_S, *, idle: bool = False) -> None:
        """Live, the wall clock now ``now_ns``: a step of it since the last look re-anchors the
        time base (:meth:`stepped`); else a board clock off it by more than ``max_drift_s`` (0:
        not checked) and not on its way back to it starts a new segment at its measured rate
        (:meth:`drifted`); a look more than ``quiet_s`` (``link.stall_s``) after the one before
        follows a silent link, and the rate is measured from it on (:meth:`BlockClock.drift`).
        ``hand_over`` first writes what waits, stamped in the segment it came in.  ``idle`` (no
        frames came: the board gone): the step only (:meth:`check_step`)."""
        if self.check_step(now_ns, hand_over) or idle:
            return
        drift = self.clock.drift(now_ns, max_drift_s, quiet_s) if max_drift_s else None
        if drift is not None:
            hand_over()
            self.drifted(now_ns, *drift)

    def check_step(self, now_ns: int, hand_over: Callable[[], None]) -> bool:
        """Live, the wall clock now ``now_ns``: True when it stepped since the last look, the time
        base then re-anchored (:meth:`stepped`, ``hand_over`` first).  Also while no frames come
        (the board gone): the board's drift is looked at only after frames (:meth:`check_wall`).
        Before the first frame, nothing (the stamps are the wall clock's then)."""
        step = self.wall.step(now_ns) if self.clock.anchor_ns is not None else None
        if step is None:
            return False
        hand_over()
        self.stepped(now_ns, step)
        return True

    def stepped(self, now_ns: int, step_ns: int) -> None:
        """The wall clock stepped by ``step_ns``: the next slot is stamped ``now_ns``
        (:meth:`BlockClock.restep`: what waits to be written moves with the time base); a step
        back first writes the events waiting and finishes the log file."""
        if step_ns < 0:
            self.log.went_back()
            rotate = getattr(self.log.sink, "rotate", None)
            if rotate is not None:
                rotate()
        stamp = self.clock.restep(now_ns)
        self.log.emit("time_base", None, f"the system clock stepped {step_ns / 1e9:+.1f} s (NTP?); "
                      f"re-anchored: time segment {self.clock.segment} stamped from the new wall clock",
                      stamp, details={"segment": self.clock.segment, "reason": "wall_step",
                                      "step_s": round(step_ns / 1e9, 3)})

    def drifted(self, now_ns: int, offset_s: float, rate: int) -> None:
        """Live: the board's stamps are ``offset_s`` off the wall clock ``now_ns`` (positive:
        ahead) and its clock runs at ``rate`` ticks per wall second: a new segment."""
        fs = self.clock.fs
        stamp = self.clock.rebase(now_ns, offset_s, rate)
        self.log.emit("time_base", None, f"board clock {'ahead of' if offset_s > 0 else 'behind'} "
                        f"the wall clock by {abs(offset_s):.1f} s (it runs at {rate} Hz for fs "
                        f"{fs} Hz): time segment {self.clock.segment} re-anchored to the wall clock",
                        stamp, details={"segment": self.clock.segment, "reason": "drift",
                                        "offset_s": round(offset_s, 3), "rate_hz": rate})

    def finish(self, counters: dict | None = None) -> None:
        """End of the stream: a run of frames of the other mode, or of another channel count, is
        reported, and the repeats after the last frame (the link's ``counters`` count them; no
        frame after them carried them)."""
        if self.ignored:
            self._report()
        n = (counters or {}).get("frames_repeated", 0) - self.repeats_told
        if n > 0:
            self.repeats_told += n
            self.log.emit("frames_repeated", None, f"{n} frame(s) received again at the end of the stream (the "
                          "same frames as already received): dropped", count=n)
        self.setup.end_odd_run()
        self.setup.end_disagreeing()

    def _report(self) -> None:
        st = self.setup.status
        mode = {1: "RMS", 2: "RAW"}.get(st.mode, "?") if st is not None else "?"
        kind = _NAME.get(self.ignored_type, "?") if self.ignored_type is not None else "?"
        self.ignored_total += self.ignored
        self.log.emit("decode_error", None, f"{self.ignored} {kind} frame(s) ignored: the board "
                        f"is in {mode} mode (STATUS)", count=self.ignored)
        self.ignored = 0
