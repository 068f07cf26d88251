"""BlockClock.drift by hand, on a made-up wall clock: what the live loop's looks at the board's
clock find (tests/test_link_silence.py and test_stream_time.py run the daemon itself)."""

from __future__ import annotations

import numpy as np

from cmsensord.monitor.clock import BlockClock

S = 1_000_000_000
WALL0 = 1_700_000_000 * S


def board(blocks_per_look: int, looks: int, clock: BlockClock, wall_s: float, found: list) -> float:
    """``looks`` looks 0.1 s apart from ``wall_s`` on, ``blocks_per_look`` blocks of 250 samples
    (fs 25000: 100 a second) before each; a drift found is rebased as the live loop does and kept
    in ``found`` as (wall s, offset s, rate).  Returns the wall clock after the last look."""
    for _ in range(looks):
        wall_s += 0.1
        t0 = clock.slot_t0(clock.next_slot) if clock.slot0_t0 is not None else 0
        clock.anchor(t0, WALL0 + round(wall_s * S))
        clock.place(np.arange(t0, t0 + 250 * blocks_per_look, 250, dtype=np.int64))
        clock.advance(blocks_per_look)
        now = WALL0 + round(wall_s * S)
        drift = clock.drift(now)
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
