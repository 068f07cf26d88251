"""The serial reader's wait between reads (cmsensord/read_pace.py): a board at 25 kHz sending
a 10-ms block (250 samples, 600 bytes) at every block's end, read as it comes."""

from __future__ import annotations

import pytest

from cmsensord.read_pace import FAR_HOLD_S, FAR_PROBE_S, MAX_HOLD_S, ReadPace


def paced(seconds: float, bytes_per_block: int = 600) -> tuple[ReadPace, float]:
    pace = ReadPace()
    t = 0.0
    for k in range(int(seconds * 100)):
        t = 0.01 * (k + 1)
        pace.arrived(t, bytes_per_block, 250 * k)
    return pace, t


def test_no_wait_before_the_rates_are_measured():
    pace, now = paced(0.5)
    assert pace.hold(now, None) == 0.0 and pace.hold(now, 250 * 60) == 0.0


def test_waits_until_shortly_before_the_block_to_wake_at_is_due():
    pace, now = paced(3.0)                      # newest frame: t0 = 250 x 299, arrived at 3.0 s
    assert pace.rate == pytest.approx(25000.0)
    due = (250 * 305 - 250 * 299) / 25000.0     # 6 blocks later: 60 ms
    assert pace.hold(now, 250 * 305) == pytest.approx(due - pace.margin_s)
    assert pace.hold(now, 250 * 299) == 0.0     # that block is in: the loop names the next soon
    assert pace.hold(now, 250 * 312) == MAX_HOLD_S     # 130 ms off: the last 0.1 s as above


def test_a_decision_further_off_is_held_for_in_one_hold_as_a_late_block():
    """RMS mode wakes at its 1-s decisions: the reader holds for one as for a late block, until
    just after it is due (FAR_HOLD_S at most), so the decision's bytes and its block are one
    read; a block not in by then is read at once (the read waits for it).  While no read has
    waited for its bytes in the last FAR_PROBE_S, the next read is at once (a probe), however
    far off the block is, and the hold follows it."""
    pace, now = paced(3.0, bytes_per_block=40)  # 4 channels' RMS frame per 10 ms
    cap = pace.buffer_bytes / pace.byte_rate
    assert cap > FAR_HOLD_S
    assert pace.hold(now, 250 * 700) == FAR_HOLD_S                              # 4.01 s off
    assert pace.hold(now, 250 * 340) == pytest.approx(0.41 - pace.margin_s)    # 0.41 s off
    assert pace.hold(now, 250 * 318) == MAX_HOLD_S                              # 0.19 s: as a block
    assert pace.hold(now, 250 * 396) == pytest.approx(0.97 - pace.margin_s)    # 0.97 s: one hold
    t = now + 0.97 - pace.margin_s              # the block came late: the read had the backlog
    pace.arrived(t, 96 * 40, 250 * 395, exact=False)
    assert pace.hold(t, 250 * 396) < 0.005      # held for as a late block: it is due now
    t = now + FAR_PROBE_S + 0.003               # a decision's block read as planned, not waited for
    pace.arrived(t, 100 * 40, 250 * (299 + round(FAR_PROBE_S * 100)), exact=False)
    far = 250 * (299 + round((FAR_PROBE_S + 1.0) * 100))                      # the next, 1 s on
    assert pace.hold(t, far) == 0.0             # no read has waited since 3.0 s: the probe
    pace.arrived(t + 0.01, 40, 250 * (300 + round(FAR_PROBE_S * 100)))        # the probe waited
    assert pace.hold(t + 0.01, far) == pytest.approx(0.99 - pace.margin_s, abs=0.001)
    fast, now = paced(3.0)                      # RAW: the buffer fills in 0.27 s, sooner than that
    assert fast.hold(now, 250 * 400) == pytest.approx(fast.buffer_bytes / fast.byte_rate)


def test_a_far_block_in_is_followed_by_a_hold_for_the_next_one_period_on():
    """Decisions named a period apart (twice the same distance): with the one named in, the
    reader holds for the next right away (as far off as the period), not waiting for the loop
    to name it; without that period known, it waits for the naming (hold 0: named_wait)."""
    pace, now = paced(3.0, bytes_per_block=40)
    assert pace.hold(now, 250 * 400) == FAR_HOLD_S      # 1.01 s off, and just after it: capped
    assert pace.hold(now, 250 * 500) == FAR_HOLD_S
    one, _ = paced(3.0, bytes_per_block=40)
    one.hold(now, 250 * 600)
    for p in (pace, one):
        p.hold(now, 250 * 600)
        p.arrived(now + 2.5, 250 * 40, 250 * 549)                   # a probe: a read that waited
        p.arrived(now + 3.015, 51 * 40, 250 * 600, exact=False)     # that block is in, read
    assert pace.hold(now + 3.015, 250 * 600) == pytest.approx(1.01 - 0.015 - pace.margin_s, abs=0.002)
    assert one.hold(now + 3.015, 250 * 600) == 0.0 and one.named_wait(now + 3.015, 250 * 600) > 0


def test_without_a_block_to_wake_at_it_waits_the_idle_hold_but_never_fills_the_buffer():
    pace, now = paced(3.0)
    assert pace.hold(now, None) == pace.idle_hold_s
    fast, now = paced(3.0, bytes_per_block=20000)        # 2 MB/s: 16 kB in 8 ms
    assert fast.hold(now, None) == pytest.approx(fast.buffer_bytes / 2e6)
    assert fast.hold(now, 250 * 305) == pytest.approx(fast.buffer_bytes / 2e6)


def test_a_board_clock_going_back_starts_the_measurement_over():
    pace, now = paced(3.0)
    pace.arrived(now + 0.01, 600, 0)
    assert pace.rate is None and pace.hold(now + 0.01, 250) == 0.0


def test_behind_a_backlog_it_reads_again_at_once():
    """The newest frame read came 40 ms after it was due (a read took only part of what waits):
    no wait, whatever the block to wake at; in time again, the wait is back."""
    pace, now = paced(3.0)
    late = now + 0.05                           # t0 250 x 300 was due at ~3.01 s
    pace.arrived(late, 600, 250 * 300)
    assert pace.hold(late, 250 * 310) == 0.0 and pace.hold(late, None) == 0.0
    assert pace.named_wait(late, 250 * 300) == 0.0
    pace.arrived(late + 0.001, 3000, 250 * 304)  # the rest of the backlog: due at ~3.05 s
    assert pace.hold(late + 0.001, 250 * 310) > 0.0


def test_with_the_block_to_wake_at_in_it_waits_for_the_loop_to_name_the_next():
    pace, now = paced(3.0)
    assert pace.named_wait(now, 250 * 299) == MAX_HOLD_S      # in: wait (at most MAX_HOLD_S)
    assert pace.named_wait(now, 250 * 305) == 0.0             # to come: hold() says how long
    assert pace.named_wait(now, None) == 0.0


def test_one_early_arrival_does_not_make_every_later_block_look_late():
    """A loaded machine: the blocks come ~25 ms after their time, one of them once on time.
    Seconds later the blocks are on time again by the arrivals of the last second (``recent_s``),
    and the reader holds for the block to wake at instead of reading every block as it comes."""
    pace = ReadPace()
    for k in range(500):                        # 5 s of blocks, block 200 on time, the rest 25 ms late
        t = 0.01 * (k + 1) + (0.0 if k == 200 else 0.025)
        pace.arrived(t, 600, 250 * k)
    assert pace.late_s < pace.behind_s
    assert pace.hold(t, 250 * 505) == pytest.approx(0.06 - pace.margin_s, abs=0.002)   # 6 blocks on


def test_reads_that_found_their_bytes_waiting_do_not_move_the_due_time_and_a_probe_measures_it():
    """At 1x the reader holds until 2 ms after the block to wake at is due and reads it with the
    backlog (one read per /orders block): such a read found its bytes waiting, so its time is
    no arrival (taken as one, the due time would move 2 ms later at every read).  Every
    ``probe_s`` without a read that waited, the hold ends 5 ms before the block is due, and the
    block is read as it comes: its arrival keeps the due time measured."""
    holds, probes = one_read_per_block(0.5)
    assert max(holds) <= 0.002 + 1e-6                       # never later than 2 ms after: no drift
    assert sum(e >= 0 for e in holds) >= 0.75 * len(holds)  # mostly one read per /orders block
    assert min(holds) == pytest.approx(-0.005, abs=1e-6)
    assert 300 / 6 <= probes <= 300 / 4                     # one every probe_s = 5 /orders blocks


def one_read_per_block(probe_s: float) -> tuple[list[float], int]:
    """30 s of /orders blocks (ten blocks each) read as the reader does: (when each hold ended,
    from its block's due time; how many were probes)."""
    pace, now = paced(3.0)                      # blocks on time: block k comes at 0.01 (k + 1)
    pace.probe_s = probe_s
    holds, probes = [], 0
    k = 299
    for _ in range(300):                        # 30 s of /orders blocks, ten blocks each
        wake = 250 * (k + 10)
        hold = pace.hold(now, wake)
        due = 0.01 * (k + 11)
        holds.append(now + hold - due)
        if now + hold < due:                    # a probe: the backlog, then the block as it comes
            probes += 1
            pace.arrived(now + hold, 5400, 250 * (k + 9), exact=False)
            now = due
            pace.arrived(now, 600, wake, exact=True)
        else:                                   # the block was in: one read, found waiting
            now += hold
            pace.arrived(now, 6000, wake, exact=False)
        k += 10
    return holds, probes
    assert 300 / 6 <= probes <= 300 / 4                      # one probe every probe_s = 5 /orders blocks


def test_a_fast_stream_reads_the_backlog_before_the_block_so_the_port_buffer_never_fills():
    """RAW 4 channels send ~2.1 kB a block: between the newest read and the block to wake at
    more than half the buffer would wait, so the hold ends 5 ms before that block is due (the
    backlog, then the block as it comes), not after it."""
    pace, now = paced(3.0, bytes_per_block=2100)
    due = (250 * 305 - 250 * 299) / 25000.0     # 6 blocks on: 12.6 kB, over half of 16 kB
    assert pace.hold(now, 250 * 305) == pytest.approx(due - pace.probe_margin_s)
    assert pace.hold(now, 250 * 302) == pytest.approx(0.03 - pace.margin_s)   # 6.3 kB: after it
