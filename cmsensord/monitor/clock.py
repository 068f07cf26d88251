"""The board's block clock: anchoring, unwrapped t0 -> slots and stamps, gaps, re-anchoring.

Timestamps come from the ADC clock (docs/PROTOCOL.md rule 4):
t = anchor + (t0_unwrapped - t0_first) / fs, the anchor being the wall clock
when the first frame of the segment was received (fs: the board's, or its rate
measured live).  Observations sit on slots of one block:
slot = (t0_unwrapped - slot0_t0) / block_len, slot 0 being the first
observation.  A slot with no frame is a *missing observation*, but at most
``MAX_FILL_S`` seconds (and ``MAX_FILL_SLOTS`` slots) of them per gap: a longer
gap forward, a duplicate or a step backwards re-anchors the slots instead of
inventing missing observations for the whole gap; a duplicate (a stuck t0) is
stamped one block after the newest stamp.

Stamps are made in *segments*.  A step back of a block or more, or forward by more than
``MAX_GAP_S``, is a board reset (t0 restarted or reloaded: :func:`is_reset`): a new segment starts,
anchored to the wall clock at the reset but never before the end of the newest slot
(:meth:`BlockClock.new_segment`), so stamps never go backwards.  Live, the
board's clock is compared with the wall clock (:meth:`BlockClock.drift`); one
running fast or slow by more than ``link.max_drift_s`` starts a new segment whose
stamps follow the board's measured rate (ahead: slower until they meet the wall clock, then
at the rate, :meth:`BlockClock.rebase`).  A silent link is no slow board: the wall time
without frames is no board time, and the frames after it may be a backlog (a buffer on the
way, a board that kept what it could not send), old when they come in.  So the board's rate
is measured from the first look after a silence on, and stamps behind the wall clock that
run faster than it (or ahead and slower) are on their way back to it, not drifting; the
frames after the silence are stamped where their t0 puts them in the segment, which for a
board whose clock kept running is the wall clock.

Live, the wall clock itself may step (an NTP sync after a boot with a stale clock, a
board without an RTC battery): :class:`WallSteps` tells a step from the wall clock's
advance against the monotonic clock's, which does not step, and
:meth:`BlockClock.restep` re-anchors the time base to the new wall clock at once, at the
board's rate, backwards too (the one case where stamps go back): a step is not a board
running fast or slow, and the rate measured over an interval holding it would be wrong.
Whatever is not written yet moves with the time base, as if the wall clock had always been
the new one: the slots already processed are stamped shifted by the re-anchoring's *shift*
(the new stamp of the next slot less its old one), and each part of the chain that holds
stamps (:attr:`BlockClock.steps`) is told the shift.
Replay never looks at the wall clock after its anchor, so it never re-anchors for a step.
"""

from __future__ import annotations

import bisect
import time
from collections.abc import Callable
from typing import overload

import numpy as np

DEFAULT_FS = 25000
DEFAULT_BLOCK_LEN = 250
#: a jump of the block clock larger than this (or backwards) is a board reset: a new segment
MAX_GAP_S = 600.0
#: most missing observations one gap inserts: a longer gap re-anchors the slots
MAX_FILL_S = 10.0
MAX_FILL_SLOTS = 1000
#: live: least wall time over which the board's rate is measured
DRIFT_MIN_WALL_S = 5.0
#: live: a look at the board's clock this long (s) after the one before follows a silence of the
#: link (the live loop passes ``link.stall_s``): the rate is measured from there on
QUIET_S = 2.0
#: a board ahead of the wall clock is stamped this much slower than its rate until caught up
CATCH_UP = 0.1
#: live: a wall clock advancing this much more or less than the monotonic clock between two
#: looks has stepped (an NTP sync)
STEP_S = 1.0
#: time bases (epochs) kept to stamp slots already processed (a decision released late)
MAX_EPOCHS = 4096


def is_reset(t0_unwrapped: int, last_t0: int, fs: int, block_len: int) -> bool:
    """True when a frame at ``t0_unwrapped`` after one at ``last_t0`` means the board restarted its
    clock (at ``fs`` samples a second, blocks of ``block_len``): a step back of a block or more, or
    forward by more than ``MAX_GAP_S``.  A frame's t0 is the first sample of its block, shared by the
    frames of that block (docs/PROTOCOL.md), so one less than a block behind the frame before it is
    a t0 off by a few samples (a RAW and a TACHO frame of one block that disagree), not a clock
    that started again."""
    return t0_unwrapped <= last_t0 - block_len or t0_unwrapped - last_t0 > MAX_GAP_S * fs


class BlockClock:
    """Slots and wall-clock stamps of the board's blocks (see module docstring)."""

    def __init__(self) -> None:
        self.fs = DEFAULT_FS
        self.block_len = DEFAULT_BLOCK_LEN
        self.anchor_ns: int | None = None      # wall clock at the first frame
        self.t0_first: int | None = None       # t0_unwrapped of the first frame
        self.slot0_t0: int | None = None       # t0_unwrapped of slot 0
        self.next_slot = 0                     # next observation slot expected
        self._rate_slot, self._adc_before = 0, 0.0   # the slot the rate took over at; ADC seconds before it
        self.last_stamp_ns = 0                 # stamp of the newest observation slot
        self.floor_ns = 0                      # no later stamp is before this (the end of the newest slot)
        self.stamp_fs = DEFAULT_FS             # board ticks per second of stamps (fs, or measured)
        self.rate = 0                          # the board's measured ticks per wall second (0: fs)
        self.segment = 0                       # segments started after the first
        self.seg_stamp_ns = 0                  # the first stamp of the current segment
        self.base_wall_ns = 0                  # a wall clock and its stamp: the stream's time base
        self.base_stamp_ns = 0                 # (:meth:`on_base_ns`) from there on
        self.win_wall_ns = 0                   # wall clock and t0 where the rate is measured from
        self.win_t0 = 0                        # (the segment's start, or the first look after a silence)
        self.looked_ns = 0                     # wall clock at the last look (:meth:`drift`)
        self.catching_up = False               # stamps slower than the board's rate, ahead of the wall clock
        self.rate_s = 0.0                      # wall seconds the measured rate was measured over
        #: (first slot, anchor_ns, t0_first, slot0_t0, block_len, stamp_fs) of each time base
        self._epochs: list[tuple[int, int, int, int, int, int]] = []
        #: called with the shift [ns] of the stamps at each :meth:`restep` (a step of the wall clock)
        self.steps: list[Callable[[int], None]] = []

    def anchor(self, t0_unwrapped: int, wall_ns: int, newest: tuple[int, int] | None = None) -> None:
        """The first frame: its t0 is ``wall_ns``, the wall clock when it is handled (live as in a
        replay of the capture, so their stamps agree).  Live, ``newest`` is (t0_unwrapped, wall
        clock ns) of the newest frame read, when it was read (one at most ``MAX_FILL_S`` after
        the first, and not after ``wall_ns``): the board's rate is measured from that frame
        (:meth:`drift`), not from the first one's handling.  The first reads' backlog, handled
        late on a loaded machine, would otherwise shorten the wall time of the measurement by
        the delay and give a rate too fast by it over ``DRIFT_MIN_WALL_S`` (34,700 Hz for a board
        at 30,000 Hz handled 0.8 s late), and the catch-up's stamps a step too short."""
        if self.anchor_ns is not None:
            return
        self.anchor_ns = self.seg_stamp_ns = wall_ns
        self.base_wall_ns = self.base_stamp_ns = wall_ns
        self.t0_first = t0_unwrapped
        self.win_t0, self.win_wall_ns = t0_unwrapped, wall_ns
        if newest is not None and newest[1] <= wall_ns and 0 <= newest[0] - t0_unwrapped <= MAX_FILL_S * self.fs:
            self.win_t0, self.win_wall_ns = newest

    def is_reset(self, t0_unwrapped: int, last_t0: int) -> bool:
        """:func:`is_reset` at this clock's fs and block length."""
        return is_reset(t0_unwrapped, last_t0, self.fs, self.block_len)

    def new_segment(self, t0_unwrapped: int, wall_ns: int, stamp_fs: int | None = None) -> int:
        """A new segment: the block at ``t0_unwrapped`` takes the next slot and is stamped
        ``wall_ns``, but never earlier than the end of the newest slot (``floor_ns``).  Its stamps run
        at ``stamp_fs`` board ticks per second (default fs).  Returns its stamp."""
        self.anchor_ns = self.floor_ns = self.seg_stamp_ns = max(wall_ns, self.floor_ns)
        self.t0_first = t0_unwrapped
        self.win_wall_ns, self.win_t0 = wall_ns, t0_unwrapped
        self.base_wall_ns, self.base_stamp_ns = wall_ns, self.anchor_ns
        self.stamp_fs = stamp_fs or self.fs
        self.catching_up = False
        self.segment += 1
        if self.slot0_t0 is not None:
            self.slot0_t0 = t0_unwrapped - self.next_slot * self.block_len
        return self.anchor_ns

    def wall_stamp_ns(self, wall_ns: int) -> int:
        """The wall clock ``wall_ns`` on the stream's time base (:meth:`on_base_ns`: the stamps of a
        board in step with the wall clock), never before the end of the newest slot; ``wall_ns``
        itself before the first frame."""
        return wall_ns if self.anchor_ns is None else max(self.floor_ns, self.on_base_ns(wall_ns))

    def on_base_ns(self, wall_ns: int) -> int:
        """The wall clock ``wall_ns`` on the stream's time base, whatever the stamps processed (a
        board sent faster than real time runs ahead of it): as far from the current segment's
        first stamp as it is from the wall clock at the segment's start; while a segment catches
        up with the wall clock (:meth:`rebase`), that far times the stamps' slowing; once it has,
        as far from the stamp it met the wall clock at."""
        since = wall_ns - self.base_wall_ns
        if self.catching_up and self.rate:
            since = since * self.rate // self.stamp_fs
        return self.base_stamp_ns + since

    def drift(self, wall_ns: int, max_drift_s: float = 2.0,
              quiet_s: float = QUIET_S) -> tuple[float, int] | None:
        """Live, looked at after frames came: (offset s, measured board ticks per wall second)
        when the newest stamp is more than ``max_drift_s`` off the wall clock ``wall_ns``
        (positive: the board is ahead) and not on its way back to it, the rate measured over at
        least ``DRIFT_MIN_WALL_S``; else None.  On its way back: behind, the stamps (at
        ``stamp_fs``) run faster than the wall clock, or ahead, slower (a backlog coming in
        after a silence; a segment catching up).  A look more than ``quiet_s`` after the one
        before (the link was silent, or the loop behind) measures the rate from here on: the
        wall time without frames is no board time."""
        if not self.last_stamp_ns or self.slot0_t0 is None:
            return None
        looked, self.looked_ns = self.looked_ns, wall_ns
        if looked and wall_ns - looked > quiet_s * 1e9:
            self.win_wall_ns, self.win_t0 = wall_ns, self.slot_t0(self.next_slot)
            return None
        if self.catching_up and self.last_stamp_ns <= wall_ns:
            self._caught_up(wall_ns)
        offset = (self.last_stamp_ns - wall_ns) / 1e9
        wall_s = (wall_ns - self.win_wall_ns) / 1e9
        if abs(offset) <= max_drift_s or wall_s < DRIFT_MIN_WALL_S:
            return None
        ticks = self.slot_t0(self.next_slot) - self.win_t0
        if ticks <= 0:
            return None
        rate = max(1, round(ticks / wall_s))
        if rate > self.stamp_fs if offset < 0 else rate < self.stamp_fs:
            return None                         # on its way back to the wall clock
        self.rate_s = wall_s
        return offset, rate

    def rebase(self, wall_ns: int, offset_s: float, rate: int) -> int:
        """A new segment after a drift of ``offset_s`` (see :meth:`drift`): stamps from the
        wall clock at the next slot, at the measured ``rate``.  While the board is ahead they run
        slower by ``CATCH_UP``, so they never go back yet meet the wall clock; the first look
        that finds them there (:meth:`drift`) puts them back on ``rate`` from the next slot on,
        without a jump, so they stay with the wall clock instead of falling behind it."""
        stamp_fs = round(rate * (1 + CATCH_UP)) if offset_s > 0 else rate
        self.rate = rate
        stamp = self.new_segment(self.slot_t0(self.next_slot), wall_ns, stamp_fs)
        self.catching_up = offset_s > 0
        return stamp

    def _caught_up(self, wall_ns: int) -> None:
        """The stamps of a segment catching up (:meth:`rebase`) have met the wall clock ``wall_ns``:
        from the next slot on they run at the board's measured rate, the next slot keeping its
        stamp (the same segment, a new time base for the slots to come).  The rate is measured
        again over the catch-up when that is longer than what the drift's rate was measured over
        (a few seconds after a start, whose first reads may bring what waited in the port)."""
        t0 = self.slot_t0(self.next_slot)
        wall_s, ticks = (wall_ns - self.win_wall_ns) / 1e9, t0 - self.win_t0
        if wall_s > self.rate_s and ticks > 0:
            self.rate, self.rate_s = max(1, round(ticks / wall_s)), wall_s
        self.anchor_ns, self.t0_first = self.stamp_ns(t0), t0
        self.base_wall_ns, self.base_stamp_ns = wall_ns, self.anchor_ns
        self.stamp_fs = self.rate or self.fs
        self.catching_up = False

    def restep(self, wall_ns: int) -> int:
        """The wall clock stepped (:class:`WallSteps`): a new segment whose next slot is stamped
        ``wall_ns``, even before the newest stamp (a step back), at the board's measured rate
        (fs when none was measured); the drift is measured from here.  The slots already processed
        and :attr:`steps` move by the shift (module docstring).  Returns its stamp."""
        was = self.floor_ns if self.slot0_t0 is None else self.stamp_ns(self.slot_t0(self.next_slot))
        self.floor_ns = min(self.floor_ns, wall_ns)
        if self.slot0_t0 is None:               # after a rate change, before its first block
            self.anchor_ns = self.floor_ns = self.seg_stamp_ns = self.win_wall_ns = wall_ns
            self.base_wall_ns = self.base_stamp_ns = wall_ns
            self.segment += 1
        else:
            self.new_segment(self.slot_t0(self.next_slot), wall_ns, self.rate or self.fs)
        shift = wall_ns - was if was else 0     # nothing stamped yet: nothing to move
        self._epochs = [(f, a + shift, t, s0, n, fs) for f, a, t, s0, n, fs in self._epochs]
        if self.last_stamp_ns:
            self.last_stamp_ns += shift
        for told in self.steps:
            told(shift)
        return wall_ns

    def set_rate(self, fs: int, block_len: int) -> bool:
        """The board's fs/block_len; True when the slots had to be re-anchored for it."""
        if fs <= 0 or block_len <= 0 or (fs, block_len) == (self.fs, self.block_len):
            return False
        moved = self.slot0_t0 is not None
        self._adc_before, self._rate_slot = self.adc_seconds, self.next_slot
        if self.next_slot:                      # stamps go on from the end of the newest slot,
            self.anchor_ns, self.t0_first = self.floor_ns, None     # from the next frame's t0
        self.slot0_t0 = None
        self.fs, self.block_len = fs, block_len
        self.stamp_fs = fs
        self.rate = 0
        self.catching_up = False
        return moved

    # ---- stamps ------------------------------------------------------------
    def stamp_ns(self, t0_unwrapped: int) -> int:
        """ADC sample index -> ns since the epoch (docs/PROTOCOL.md rule 4)."""
        assert self.anchor_ns is not None
        if self.t0_first is None:               # after a rate change, before the next block
            return self.anchor_ns
        return self.anchor_ns + (t0_unwrapped - self.t0_first) * 1_000_000_000 // self.stamp_fs

    @overload
    def slot_t0(self, slot: int) -> int: ...
    @overload
    def slot_t0(self, slot: np.ndarray) -> np.ndarray: ...

    def slot_t0(self, slot):
        """The board sample (unwrapped t0) where observation slot ``slot`` (an int, or an
        array of them) begins."""
        assert self.slot0_t0 is not None
        return self.slot0_t0 + slot * self.block_len

    def slot_stamp_ns(self, slot: int) -> int:
        """The stamp of observation slot ``slot``: a slot already processed keeps the stamp
        of the time base it was processed in (a re-anchoring since does not move it)."""
        return self._stamp(slot, 0)

    def slot_end_ns(self, slot: int) -> int:
        """The stamp of the end of slot ``slot`` (one block after its start, in its time base):
        a decision over slots up to ``slot`` is stamped so."""
        return self._stamp(slot, 1)

    def _stamp(self, slot: int, blocks: int) -> int:
        if slot >= self.next_slot or not self._epochs or slot >= self._epochs[-1][0] and self._current():
            return self.stamp_ns(self.slot_t0(slot + blocks))
        i = max(0, bisect.bisect_right(self._epochs, slot, key=lambda e: e[0]) - 1)
        return self._stamp_in(self._epochs[i][1:], slot, blocks)

    @staticmethod
    def _stamp_in(params: tuple[int, ...], slot: int, blocks: int) -> int:
        """The stamp ``blocks`` blocks after the start of ``slot`` in the time base ``params``
        (anchor_ns, t0_first, slot0_t0, block_len, stamp_fs: :meth:`_params`, an epoch's)."""
        anchor, t0_first, slot0_t0, block_len, stamp_fs = params
        return anchor + (slot0_t0 + (slot + blocks) * block_len - t0_first) * 1_000_000_000 // stamp_fs

    def _params(self) -> tuple[int, int, int, int, int]:
        assert self.anchor_ns is not None and self.t0_first is not None and self.slot0_t0 is not None
        return self.anchor_ns, self.t0_first, self.slot0_t0, self.block_len, self.stamp_fs

    def _current(self) -> bool:
        """True when the newest epoch is the current time base."""
        if self.anchor_ns is None or self.t0_first is None or self.slot0_t0 is None:
            return False
        return self._epochs[-1][1:] == self._params()

    @property
    def board_seconds(self) -> float:
        """The board's clock (t0_unwrapped / fs) at the end of the processed observations."""
        if self.slot0_t0 is None:
            return 0.0
        return (self.slot0_t0 + self.next_slot * self.block_len) / self.fs

    @property
    def adc_seconds(self) -> float:
        """ADC time covered by the observations processed so far, each stretch at its own rate."""
        return self.seconds_at(self.next_slot)

    def seconds_at(self, slot: int) -> float:
        """ADC time before ``slot`` (a slot of the current rate's stretch), each stretch at its
        own rate."""
        return self._adc_before + (slot - self._rate_slot) * self.block_len / self.fs

    # ---- slots -------------------------------------------------------------
    def begin(self, t0: int) -> None:
        """A block starting at ``t0`` comes: the first of the stream or of a new rate sets where
        the slots and the stamps count from (before it, stamps are the anchor's)."""
        if self.slot0_t0 is None:
            self.slot0_t0 = t0 - self.next_slot * self.block_len
        if self.t0_first is None:
            self.t0_first = t0

    def place(self, t0: np.ndarray) -> tuple[np.ndarray, int]:
        """Slots of the blocks starting at ``t0`` (int64, in arrival order), up to the first
        time jump or duplicate: (slots of the first n blocks, n).  n < len(t0): call
        :meth:`reanchor` with t0[n], then place the rest."""
        if len(t0):
            self.begin(int(t0[0]))
        slots = (t0 - self.slot0_t0) // self.block_len
        max_gap = max(1, min(MAX_FILL_SLOTS, int(MAX_FILL_S * self.fs / self.block_len)))
        if not len(slots):
            return slots, 0
        step = np.empty_like(slots)             # from the slot before: the newest one for the first
        step[0] = self.next_slot - 1
        step[1:] = slots[:-1]
        np.subtract(slots, step, out=step)
        bad = ((step <= 0) | (step > max_gap)).nonzero()[0]
        n = int(bad[0]) if bad.size else len(t0)
        return slots[:n], n

    def jump_words(self, t0: int) -> str:
        """What the block at ``t0`` that :meth:`place` stopped at does to the board's clock, in the
        board's own t0 fields (as sent, 32 bits) and seconds: ``board clock jumped 599.0 s ahead (t0
        15000000 after 14987750)``, the seconds past the block expected next; ``board clock did not
        advance a block (t0 500 after 500)`` for a t0 less than a block after the newest block's."""
        if self.slot0_t0 is None or not self.next_slot:
            return f"board clock jumped (t0 {t0 & 0xFFFFFFFF})"
        prev = self.slot_t0(self.next_slot - 1)
        told = f"(t0 {t0 & 0xFFFFFFFF} after {prev & 0xFFFFFFFF})"
        if t0 - prev < self.block_len:
            return f"board clock did not advance a block {told}"
        return f"board clock jumped {(t0 - prev - self.block_len) / self.fs:.1f} s ahead {told}"

    def reanchor(self, t0: int) -> None:
        """The block starting at ``t0`` takes the next slot; when ``t0`` is not after the
        newest slot's (a duplicate, a stuck t0), it is stamped one block after the newest stamp."""
        if self.slot0_t0 is not None and self.next_slot and t0 <= self.slot_t0(self.next_slot - 1):
            self.anchor_ns = self.floor_ns
            self.t0_first = t0
        self.slot0_t0 = t0 - self.next_slot * self.block_len

    def advance(self, n_slots: int) -> None:
        """``n_slots`` more observation slots are processed."""
        params = self._params()
        if not self._epochs or self._epochs[-1][1:] != params:
            self._epochs.append((self.next_slot, *params))
            if len(self._epochs) > MAX_EPOCHS:
                del self._epochs[0]
        self.next_slot += n_slots
        if n_slots <= 0:
            self.last_stamp_ns = self.slot_stamp_ns(self.next_slot - 1)
            self.floor_ns = max(self.floor_ns, self.slot_end_ns(self.next_slot - 1))
            return
        newest = self.next_slot - 1             # in the current time base, the newest epoch
        self.last_stamp_ns = self._stamp_in(params, newest, 0)
        self.floor_ns = max(self.floor_ns, self._stamp_in(params, newest, 1))


class WallSteps:
    """Steps of the wall clock: how much more (or less) it advanced between two looks than
    the monotonic clock (``mono_ns``), which does not step."""

    def __init__(self, mono_ns: Callable[[], int] = time.monotonic_ns) -> None:
        self.mono_ns = mono_ns
        self._last: tuple[int, int] | None = None

    def step(self, wall_ns: int) -> int | None:
        """The step (ns, negative: back) of the wall clock, now ``wall_ns``, since the last look,
        when more than ``STEP_S``; else None (and at the first look)."""
        mono = self.mono_ns()
        last, self._last = self._last, (wall_ns, mono)
        if last is None:
            return None
        step = (wall_ns - last[0]) - (mono - last[1])
        return step if abs(step) > STEP_S * 1e9 else None
