"""BlockClock.drift by hand, on a made-up wall clock: what the live loop's looks at the board's
clock find (tests/test_link_silence.py and test_stream_time.py run the daemon itself)."""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.monitor.clock import CATCH_UP, BlockClock

S = 1_000_000_000
WALL0 = 1_700_000_000 * S


def board(blocks_per_look: int, looks: int, clock: BlockClock, wall_s: float, found: list,
          max_drift_s: float = 2.0) -> float:
    """``looks`` looks 0.1 s apart from ``wall_s`` on, ``blocks_per_look`` blocks of 250 samples
    (fs 25000: 100 a second) before each; a drift (by more than ``max_drift_s``) found is rebased
    as the live loop does and kept in ``found`` as (wall s, offset s, rate).  Returns the wall
    clock after the last look."""
    for _ in range(looks):
        wall_s += 0.1
        t0 = clock.slot_t0(clock.next_slot) if clock.slot0_t0 is not None else 0
        clock.anchor(t0, WALL0 + round(wall_s * S))
        clock.place(np.arange(t0, t0 + 250 * blocks_per_look, 250, dtype=np.int64))
        clock.advance(blocks_per_look)
        now = WALL0 + round(wall_s * S)
        drift = clock.drift(now, max_drift_s)
        if drift is not None:
            found.append((round(wall_s, 1), *drift))
            clock.rebase(now, *drift)
    return wall_s


def test_a_board_at_twice_real_time_is_re_anchored_once_and_left_to_catch_up():
    """A board at 2x: one drift, ahead, at 5 s (the rate measured over 5 s); its stamps then run
    10 % slower than the board and come back to the wall clock, and no look starts another
    segment while they do (not another every 5 s, 4.65 s, 4.20 s, ... 2.83 s ahead)."""
    clock, found = BlockClock(), []
    board(20, 350, clock, 0.0, found)
    [(at, offset, rate)] = found
    assert 5.0 <= at <= 5.2 and 4.9 < offset < 5.3 and 50000 <= rate <= 51000   # the first look's blocks too
    assert clock.stamp_fs == round(rate * 1.1)


def test_a_backlog_after_a_silence_is_no_drift_and_the_board_time_goes_on():
    """A board in real time for 6 s, then a silence of 12 s (no look), then what it kept, in 2 s
    (the 12 s and the 2 s its clock ran on meanwhile), then real time: no drift, and the newest
    stamp is the wall clock again (guards against behind by 11.3 s at 9.3 kHz, the backlog stamped
    at that rate, then ahead, and on)."""
    clock, found = BlockClock(), []
    wall = board(10, 60, clock, 0.0, found)
    wall = board(70, 20, clock, wall + 12.0, found)     # 12 s of silence, then 7x real time
    wall = board(10, 100, clock, wall, found)
    assert found == []
    assert abs(clock.last_stamp_ns - (WALL0 + round(wall * S))) < 0.2 * S


def _fast_board(fast: float, seconds: float) -> tuple[BlockClock, list, list[int], float, list[int]]:
    """A board ``fast`` times real time (its crystal fast) looked at every 0.1 s for ``seconds``,
    whole blocks before each look (on average 10 ``fast`` of them): the clock, the drifts found,
    the newest stamp at each look less the wall clock then (ns), the wall clock at the end, and
    the wall clock on the stream's time base (``on_base_ns``) at each look less the next block's
    stamp."""
    clock, found, off, base = BlockClock(), [], [], []
    wall, owed = 0.0, 0.0
    for _ in range(round(seconds * 10)):
        owed += 10 * fast
        n = int(owed)
        owed -= n
        wall = board(n, 1, clock, wall, found)
        now = WALL0 + round(wall * S)
        off.append(clock.last_stamp_ns - now)
        base.append(clock.on_base_ns(now) - clock.stamp_ns(clock.slot_t0(clock.next_slot)))
    return clock, found, off, wall, base


@pytest.mark.parametrize("fast, seconds, at", [(1.05, 150, 38.4), (1.001, 3000, 1910.1)])
def test_a_fast_crystal_is_re_anchored_once_and_its_stamps_stay_on_the_wall_clock(fast, seconds, at):
    """A board whose crystal runs fast (5 %, and 1000 ppm): one drift, ahead by 2 s; its stamps
    then run 10 % slower than its rate until they meet the wall clock, and from there on at its
    measured rate: they stay on the wall clock, with no second drift, long after the catch-up
    would have overshot (guards against the catch-up going on, a false ``behind the wall clock
    by 2.0 s`` 44 s after the first, at 81.4 s and 1954.1 s, and a jump of the stamps).  The wall
    clock on the stream's time base (what the idle loop releases events by, and the stamp of an
    event the board's frames do not time) follows the stamps from the re-anchoring through the
    catch-up, and the wall clock after it
    (guards against it staying ahead by the drift: a ``link_stalled`` or ``stop`` stamped 2 s in
    the future, events released that much early)."""
    clock, found, off, wall, base = _fast_board(fast, seconds)
    [(when, offset, rate)] = found
    assert when == at and 2.0 < offset < 2.1
    assert abs(rate / 25000 - fast) < 0.003
    assert clock.stamp_fs == rate and clock.segment == 1          # back on the measured rate
    caught = next(i for i, o in enumerate(off) if i / 10 > at and o <= 0) / 10
    assert caught - at < 2.0 / CATCH_UP * (1 + CATCH_UP) + 0.5     # 22 s after the drift
    assert max(abs(o) for o in off[round(caught * 10):]) < 0.5 * S  # on the wall clock after it
    catching = base[round(at * 10) - 1:round(caught * 10)]          # from the look that re-anchored
    assert max(abs(b) for b in catching) < 0.1 * S, (min(catching) / S, max(catching) / S)
    on_wall = [b + o for b, o in zip(base[round(caught * 10):], off[round(caught * 10):])]
    assert max(abs(w) for w in on_wall) < 0.05 * S, (min(on_wall) / S, max(on_wall) / S)


def test_a_fast_board_handled_late_at_first_is_measured_at_its_rate():
    """A board at 1.2x whose frames are read as they come (every 0.1 s) but handled first 0.8 s
    after the first came, all at once (a loaded board computer at the daemon's start),
    ``max_drift_s`` 1 (tests/test_clock_fast_crystal.py live): the first frame is stamped when
    handled (as a replay of the capture stamps it), so the stamps are ahead by that 0.8 s and the
    board's 0.2 s a second of the 5.8 s until the drift is found (1.96 s), but the rate is
    measured from the newest frame read then, when it came: one drift, at 30000 Hz, and its
    stamps catch up at 1.1 times that rate.  Guards against the rate
    measured from the first frame's handling: 34500 Hz, the catch-up's stamps of 25000 board
    samples 0.658 s apart, not 0.758."""
    clock, found = BlockClock(), []
    t0, newest = 0, None
    for look in range(1, 9):                   # read, not handled: 12 blocks a look
        t0 += 12 * 250
        newest = (t0 - 250, WALL0 + round(look * 0.1 * S))
    clock.anchor(0, WALL0 + round(0.8 * S), newest)
    clock.place(np.arange(0, t0, 250, dtype=np.int64))
    clock.advance(t0 // 250)
    board(12, 120, clock, 0.8, found, max_drift_s=1.0)
    [(at, offset, rate)] = found
    assert 5.8 <= at <= 6.0 and 1.9 < offset < 2.0 and abs(rate - 30000) < 100, found
    assert clock.stamp_fs == round(rate * (1 + CATCH_UP))
