"""The reorder window: log times never go back in a file, in-order streams pass straight through."""

from __future__ import annotations

import random

from cmsensord.sinks.reorder import ReorderWindow

S = 1_000_000_000


def _push_all(window: ReorderWindow, stamps):
    out = []
    for k, stamp in enumerate(stamps):
        out += window.push(stamp, 1, str(k).encode())
    return out + window.drain()


def test_a_stream_in_order_passes_straight_through():
    w = ReorderWindow()
    for k in range(100):
        assert w.push(k * S // 100, 1, b"x") == [(k * S // 100, k * S // 100, 1, b"x")]
        assert len(w) == 0                     # nothing held: crash safety as without the window
    assert w.horizon_ns == 0 and w.clamped == 0


def test_late_messages_within_the_horizon_are_written_in_order_with_their_own_stamps():
    w = ReorderWindow(horizon_ns=6 * S)        # as after expect_lag: the order chain has started
    rng = random.Random(3)
    stamps = [k * S // 10 - rng.randrange(0, 6 * S) for k in range(60, 400)]
    out = _push_all(w, stamps)
    log_times = [lt for lt, _, _, _ in out]
    assert log_times == sorted(log_times) == sorted(stamps)
    assert all(lt == pt for lt, pt, _, _ in out) and w.clamped == 0


def test_a_message_later_than_the_window_is_clamped_never_lost():
    w = ReorderWindow(max_s=1.0)
    out = _push_all(w, [10 * S, 11 * S, 12 * S, 5 * S, 13 * S])
    assert [lt for lt, _, _, _ in out] == sorted(lt for lt, _, _, _ in out)
    assert len(out) == 5 and w.clamped == 1
    (lt, pt, _, data), = [o for o in out if o[1] == 5 * S]
    assert data == b"3" and lt > pt                    # the newest log time written, its own publish time
    assert w.horizon_ns == 1 * S                       # learnt, up to max_s


def test_memory_is_bounded():
    w = ReorderWindow(horizon_ns=10 * S, max_held=50)
    for k in range(1000):
        w.push(10**12 + k, 1, b"x")                  # all within the horizon: held, but at most 50
        assert len(w) <= 50
