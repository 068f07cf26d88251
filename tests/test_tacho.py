"""Tacho edges -> shaft speed and angle (cmsensord.dsp.tacho.TachoTracker), as a specification.

Edges come from the simulated board (firmware_sim), whose shaft angle is exact:
- a constant 28.66 Hz shaft (the motor of Kim et al. 2023), ppr 1 and 4: speed within 0.1 %, angle within 1e-3 rev;
- the close-orders run-up of Yeh, Pan & Le with 2 samples of edge jitter: speed within 0.5 % above 300 rpm;
- missed and spurious pulses are repaired, counted and reported, the speed unaffected beyond 0.5 %;
- any split of the frames gives the same final output (hypothesis), and final values never change;
- a dead encoder: tacho_lost after the timeout, the speed decays then is 0 and invalid, tacho_restored.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cmsensord.dsp.tacho import EXTRA, LOST, MISSED, RESTORED, TachoTracker
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario

FS = 25000
L = 250


def board_frames(board: Board, n_blocks: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """t0 and edge offsets of the TACHO frame of every block (N = 0 frames included)."""
    blk, off = board.tacho_edges(0, n_blocks)
    bounds = np.searchsorted(blk, np.arange(n_blocks + 1))
    t0 = np.arange(n_blocks, dtype=np.int64) * L
    return t0, [off[bounds[i]:bounds[i + 1]] for i in range(n_blocks)]


def track(t0, edges, ppr, splits=(), **kw):
    """Run a tracker over the frames, split before the given frame indices; returns (tracker, events)."""
    tr = TachoTracker(FS, ppr, block_len=L, **kw)
    events = []
    cuts = [0, *sorted(set(splits)), len(t0)]
    for a, b in zip(cuts[:-1], cuts[1:]):
        events += tr.update(t0[a:b], edges[a:b]).events
    return tr, events


def make_board(name, seconds, ppr, seed=0, **faults):
    sc = make_scenario(name, duration_s=seconds, seed=seed)
    return sc, Board(sc, BoardConfig(tacho=True, ppr=ppr, **faults))


# --------------------------------------------------------------------------- constant speed

@pytest.mark.parametrize("ppr", [1, 4])
def test_constant_28_66_hz_shaft_speed_and_angle(ppr):
    sc, board = make_board("healthy", 10.0, ppr)
    tr, events = track(*board_frames(board, 1000), ppr)
    assert events == []
    s = np.arange(0, 1000 * L, 7)
    s = s[s < tr.final_until]
    assert s[-1] > 9.5 * FS  # final up to ~4 revolutions before the end
    hz, turns, valid = tr.evaluate(s)
    assert valid.all()
    assert np.max(np.abs(hz - 28.66)) / 28.66 < 1e-3
    # the first edge is at t = 0, where the shaft angle is 0
    assert np.max(np.abs(turns - sc.shaft_turns(s / FS))) < 1e-3
    c = tr.counters
    assert (c.missed, c.extra, c.irregular, c.lost) == (0, 0, 0, 0)
    assert c.edges == c.pulses == int(ppr * 28.66 * 10) + 1  # pulses 0 .. floor(ppr f_r T)


# --------------------------------------------------------------------------- run-up with jitter

@pytest.mark.parametrize("ppr", [1, 4])
def test_close_orders_runup_with_jitter_within_half_a_percent(ppr):
    sc, board = make_board("close_orders", 6.0, ppr, tacho_jitter=2.0)
    clean = Board(sc, BoardConfig(tacho=True, ppr=ppr))
    # the edges really are jittered by ~2 samples
    e_j, e_c = board.tacho_pulses(0, 600)["edges"], clean.tacho_pulses(0, 600)["edges"]
    assert e_j.size == e_c.size
    assert 1.8 < np.std((e_j - e_c) / 256) < 2.2
    tr, _ = track(*board_frames(board, 600), ppr)
    s = np.arange(0, 600 * L, 3)
    s = s[s < tr.final_until]
    hz, _, valid = tr.evaluate(s)
    true = sc.shaft_hz(s / FS)
    above = true * 60 > 300
    assert valid[above].all()
    rel = np.abs(hz[above] - true[above]) / true[above]
    assert rel.max() < 5e-3
    assert np.sqrt(np.mean(rel**2)) < 1e-3


def test_runup_without_jitter_is_tracked_without_bias():
    """The local quadratic in time is exact for a constant acceleration (only the kink at 5 s shows)."""
    sc, board = make_board("close_orders", 6.0, 1)
    tr, _ = track(*board_frames(board, 600), 1)
    s = np.arange(int(0.5 * FS), int(4.8 * FS), 5)
    hz = tr.speed_at(s)
    true = sc.shaft_hz(s / FS)
    assert np.max(np.abs(hz - true) / true) < 2e-4


# --------------------------------------------------------------------------- missed and extra pulses

@pytest.mark.parametrize("ppr", [1, 4])
def test_missed_and_extra_pulse_are_repaired_counted_and_reported(ppr):
    sc, board = make_board("close_orders", 6.0, ppr, tacho_jitter=2.0,
                           tacho_missed=(60 * ppr,), tacho_extra=(90 * ppr,))
    truth = board.tacho_pulses(0, 600)
    assert truth["missed"].tolist() == [60 * ppr] and truth["extra"].sum() == 1
    tr, events = track(*board_frames(board, 600), ppr)
    assert (tr.counters.missed, tr.counters.extra, tr.counters.irregular) == (1, 1, 0)
    assert [e.kind for e in events] == [MISSED, EXTRA]
    edges = truth["edges"] / 256
    i_missed = int(np.searchsorted(truth["pulse"], 60 * ppr))  # the edge after the gap
    assert edges[i_missed - 1] < events[0].sample < edges[i_missed]
    assert events[0].count == 1
    assert events[1].sample == edges[truth["extra"]][0]
    # the speed is unaffected beyond 0.5 %, also near the repaired pulses
    _, ref_board = make_board("close_orders", 6.0, ppr, tacho_jitter=2.0)
    ref, _ = track(*board_frames(ref_board, 600), ppr)
    s = np.arange(0, 600 * L, 3)
    s = s[(s < tr.final_until) & (sc.shaft_hz(s / FS) * 60 > 300)]
    true = sc.shaft_hz(s / FS)
    hz = tr.speed_at(s)
    assert np.max(np.abs(hz - true) / true) < 5e-3
    assert np.max(np.abs(hz - ref.speed_at(s)) / true) < 5e-3
    # the pulse count is whole again: the angle after the faults matches the clean run's
    late = s[s > edges[-1] * 0.9 - 4 * FS / 50]
    assert np.max(np.abs(tr.evaluate(late)[1] - ref.evaluate(late)[1])) < 0.01


def test_random_missed_and_extra_pulses_are_all_found():
    ppr = 4
    _, board = make_board("close_orders", 6.0, ppr, tacho_jitter=2.0, tacho_missed=0.03, tacho_extra=0.03)
    truth = board.tacho_pulses(0, 600)
    tr, events = track(*board_frames(board, 600), ppr)
    assert truth["missed"].size > 10 and truth["extra"].sum() > 10
    assert tr.counters.missed == truth["missed"].size
    assert tr.counters.extra == int(truth["extra"].sum())
    assert sorted(e.sample for e in events if e.kind == EXTRA) == (truth["edges"][truth["extra"]] / 256).tolist()


# --------------------------------------------------------------------------- chunk-split invariance

def _faulty_frames():
    # jitter, random extra pulses, single missed ones and a dead stretch (pulses 100..150,
    # 0.7 s: a loss) in 5 s of run-up (250 pulses at ppr 2)
    _, board = make_board("close_orders", 5.0, 2, tacho_jitter=1.5, tacho_extra=0.02,
                           tacho_missed=(*range(30, 250, 37), *range(100, 151)))
    return board_frames(board, 500)


FRAMES = _faulty_frames()
_REF_TR, _REF_EVENTS = track(*FRAMES, 2)
_GRID = np.arange(0, 500 * L, 11)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.integers(min_value=1, max_value=499), max_size=12))
def test_any_split_of_the_frames_gives_the_same_final_output(splits):
    t0, edges = FRAMES
    tr = TachoTracker(FS, 2, block_len=L)
    events = []
    cuts = [0, *sorted(set(splits)), len(t0)]
    early = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        u = tr.update(t0[a:b], edges[a:b])
        events += u.events
        s = _GRID[_GRID < u.final_until]
        early.append((s, tr.evaluate(s)))  # final now: must never change later
    assert [(e.kind, e.sample, e.count) for e in events] == [(e.kind, e.sample, e.count) for e in _REF_EVENTS]
    assert tr.counters == _REF_TR.counters
    assert tr.final_until == _REF_TR.final_until
    s = _GRID[_GRID < tr.final_until]
    for got, want in zip(tr.evaluate(s), _REF_TR.evaluate(s)):
        assert np.array_equal(got, want)
    for s, vals in early:
        for got, want in zip(vals, _REF_TR.evaluate(s)):
            assert np.array_equal(got, want)


def test_the_split_fixture_exercises_faults_and_loss():
    c = _REF_TR.counters
    assert c.missed >= 4 and c.extra > 0 and c.lost == 1 and c.restored == 1


# --------------------------------------------------------------------------- loss and recovery

def test_dead_encoder_loses_then_restores_the_tacho():
    _, board = make_board("healthy", 6.0, 1, tacho_missed=tuple(range(100, 130)))
    q = board.tacho_pulses(0, 600)["edges"] / 256
    e99, e130, e131 = q[99], q[100], q[101]
    tr = TachoTracker(FS, 1, block_len=L)
    t0, edges = board_frames(board, 600)
    events, valid_after = [], []
    for i in range(600):  # frame by frame, as the daemon feeds them
        u = tr.update(t0[i:i + 1], edges[i:i + 1])
        events += u.events
        valid_after.append(u.valid)
    timeout = 0.5 * FS  # max(0.5 s, 3 periods of 35 ms)
    assert [(e.kind, e.sample) for e in events] == [(LOST, e99 + timeout), (RESTORED, e131)]
    assert (tr.counters.lost, tr.counters.restored, tr.counters.missed) == (1, 1, 0)
    # reported valid until the block after the timeout, invalid until the second new edge
    blk_lost = int((e99 + timeout) // L)
    assert valid_after[blk_lost - 1] and not valid_after[blk_lost + 1]
    assert not valid_after[int(e130 // L)] and valid_after[int(e131 // L) + 1]
    P = FS / 28.66
    hz, turns, valid = tr.evaluate(np.array([e99 + 0.5 * P, e99 + 2 * P, e99 + 4 * P, e99 + timeout + 1,
                                             e130 - 1, e130 + 1, e131 + 10 * P]))
    assert abs(hz[0] - 28.66) < 0.03  # held for one expected period
    assert abs(hz[1] - 28.66 / 2) < 0.03 and abs(hz[2] - 28.66 / 4) < 0.03  # then decays as 1/t
    assert valid[:3].all()
    assert hz[3] == hz[4] == 0.0 and not valid[3] and not valid[4]
    assert turns[3] == turns[4]  # held while lost
    assert valid[5] and valid[6] and abs(hz[6] - 28.66) < 0.03
    # the angle across the loss is unknown: the new run starts at the next whole pulse
    assert turns[5] == pytest.approx(np.floor(turns[4]) + 1, abs=0.01)


def test_stopped_shaft_sends_empty_frames_and_is_never_valid():
    tr = TachoTracker(FS, 1, block_len=L)
    u = tr.update(np.arange(200) * L, [np.empty(0, dtype=np.uint32)] * 200)
    assert u.events == [] and not u.valid and u.final_until == 200 * L
    hz, turns, valid = tr.evaluate(np.arange(0, 200 * L, 1000))
    assert not valid.any() and not hz.any() and not turns.any()


def test_arguments_are_checked():
    tr = TachoTracker(FS, 1)
    with pytest.raises(ValueError, match="one edge array per frame"):
        tr.update([0, 250], [np.empty(0)])
    tr.update([500], [np.empty(0)])
    with pytest.raises(ValueError, match="time order"):
        tr.update([250], [np.empty(0)])
    with pytest.raises(ValueError, match="ppr"):
        TachoTracker(FS, 0)
    with pytest.raises(ValueError, match="timeout_periods"):
        TachoTracker(FS, 1, timeout_periods=1.5)


@pytest.mark.parametrize("args, kw, message", [
    ((0.0, 1), {}, "fs must be > 0, got 0.0"),
    ((float("nan"), 1), {}, "fs must be > 0, got nan"),
    ((FS, 256), {}, "ppr must be an integer 1..255, got 256"),
    ((FS, 1.0), {}, "ppr must be an integer 1..255, got 1.0"),
    ((FS, 1), {"block_len": 0}, "block_len must be a positive integer, got 0"),
    ((FS, 1), {"half_window": 0}, "half_window must be an integer >= 1, got 0"),
    ((FS, 1), {"tol": 0.5}, "tol must be in (0, 0.5), got 0.5"),
    ((FS, 1), {"timeout_s": 2.0, "max_timeout_s": 1.0},
     "need timeout_s > 0, timeout_periods > 2 (a missed pulse is 2 periods) and max_timeout_s >= "
     "timeout_s; got 2.0, 3.0, 1.0"),
    ((FS, 1), {"history_s": 0}, "history_s must be > 0, got 0"),
    ((FS, 1), {"causal_window": 1}, "causal_window must be an integer >= 2, got 1"),
])
def test_each_setting_out_of_range_is_one_clear_error(args, kw, message):
    with pytest.raises(ValueError) as err:
        TachoTracker(*args, **kw)
    assert str(err.value) == message


def test_the_windows_default_from_ppr():
    tr = TachoTracker(FS, 2)
    assert (tr.half_window, tr.causal_window) == (8, 32)
    assert (TachoTracker(FS, 8).causal_window, TachoTracker(FS, 1, causal_window=5).causal_window) == (64, 5)


def test_history_is_bounded():
    _, board = make_board("healthy", 8.0, 1)
    t0, edges = board_frames(board, 800)
    tr = TachoTracker(FS, 1, block_len=L, history_s=2.0)
    for i in range(0, 800, 50):
        tr.update(t0[i:i + 50], edges[i:i + 50])
    hz, turns, valid = tr.evaluate(np.array([0.5 * FS, 7.0 * FS]))
    assert np.isnan(hz[0]) and np.isnan(turns[0]) and not valid[0]  # dropped
    assert abs(hz[1] - 28.66) < 1e-3 and valid[1]
    assert tr._khi - tr._klo <= 2.0 * 28.66 + 64 + 1  # history_s of knots, pruned in batches of >= 64


# --------------------------------------------------------------------------- implementation

def test_compiled_evaluate_equals_numpy():
    """evaluate() between knots in the compiled kernel: bit for bit the numpy path,
    before the first edge, inside runs, after a loss, behind the history, at NaN/inf."""
    from cmsensord.dsp.tacho import smoothing as tacho_mod

    if tacho_mod._kernel is None:
        pytest.skip("compiled kernel not built")
    t0, edges = FRAMES
    tr = TachoTracker(FS, 2, block_len=L, history_s=1.0)
    tr.update(t0[:480], edges[:480])        # a loss at 2-3 s, knots before 3.9 s pruned
    assert tr._pruned and tr.counters.lost == 1
    rng = np.random.default_rng(4)
    s = np.concatenate([rng.uniform(-5000, 500 * L, 4000), np.arange(0, 500 * L, 3.3)[::-1],
                        [np.nan, np.inf, -np.inf, 0.0]])
    s = s[:s.size // 2 * 2]
    tr.use_kernel = True
    got = tr.evaluate(s.reshape(-1, 2))
    tr.use_kernel = False
    want = tr.evaluate(s.reshape(-1, 2))
    assert got[2].any() and not got[2].all() and np.isnan(got[0]).any()   # all cases present
    for g, w in zip(got, want):
        assert g.shape == (s.size // 2, 2) and np.array_equal(g, w, equal_nan=True)


@pytest.mark.parametrize("bad", ["order", "offsets"])
def test_a_bad_frame_raises_after_the_frames_before_it(bad):
    """update() takes the frames before a bad one (as frame-by-frame feeding would),
    then raises; the tracker goes on from there."""
    t0, edges = FRAMES
    t0, edges = t0[:200].copy(), list(edges[:200])
    if bad == "order":
        t0[120] = t0[119] - 1
    else:
        edges[120] = np.array([3, 2**32], dtype=np.int64)
    tr = TachoTracker(FS, 2, block_len=L)
    with pytest.raises(ValueError, match="time order" if bad == "order" else "u32"):
        tr.update(t0, edges)
    ref = TachoTracker(FS, 2, block_len=L)
    for i in range(120):
        ref.update(t0[i:i + 1], edges[i:i + 1])
    assert tr.counters == ref.counters and tr._now == ref._now
    tr.update(t0[121:], edges[121:])
    ref.update(t0[121:], edges[121:])
    s = np.arange(0, int(ref.final_until), 7)
    for got, want in zip(tr.evaluate(s), ref.evaluate(s)):
        assert np.array_equal(got, want)


def test_a_duplicated_edge_is_ignored_and_counted_not_a_crash():
    """A board (or a corrupted but CRC-valid frame) repeating an edge time must not stop the daemon."""
    fs, hz = 25000, 28.66
    period = fs / hz
    q = [int(round(k * period * 256)) for k in range(60)]
    q.insert(30, q[29])                     # the same edge twice
    blocks = {}
    for e in q:
        b = e // (250 * 256)
        blocks.setdefault(b, []).append(e - b * 250 * 256)
    nb = max(blocks) + 1
    tr = TachoTracker(fs, 1)
    u = tr.update(np.arange(nb) * 250, [np.array(blocks.get(b, []), dtype=np.uint32) for b in range(nb)])
    assert u.counters.out_of_order == 1
    hz_est, _, ok = tr.evaluate(np.array([20 * period]))
    assert ok[0] and abs(hz_est[0] - hz) < 1e-3 * hz


# --------------------------------------------------------------------------- causal speed

@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.integers(min_value=1, max_value=499), max_size=12))
def test_causal_speed_at_a_sample_never_depends_on_later_frames(splits):
    """Asked for as soon as the frames cover a sample, the causal speed equals the one asked
    for after the whole stream (missed/extra pulses, a loss and a restart included)."""
    t0, edges = FRAMES
    tr = TachoTracker(FS, 2, block_len=L)
    cuts = [0, *sorted(set(splits)), len(t0)]
    got, done = [], 0
    for a, b in zip(cuts[:-1], cuts[1:]):
        tr.update(t0[a:b], edges[a:b])
        s = np.arange(done, tr.covered_until)
        got.append(tr.evaluate_causal(s))
        done = tr.covered_until
    hz = np.concatenate([g[0] for g in got])
    valid = np.concatenate([g[1] for g in got])
    ref_hz, ref_valid = _REF_TR.evaluate_causal(np.arange(done))
    assert done == 500 * L
    assert np.array_equal(hz, ref_hz) and np.array_equal(valid, ref_valid)


@pytest.mark.parametrize("ppr", [1, 4])
def test_causal_speed_follows_the_close_orders_runup_with_jitter_and_faults(ppr):
    sc, board = make_board("close_orders", 6.0, ppr, tacho_jitter=2.0, tacho_missed=0.02,
                           tacho_extra=0.02)
    tr, _ = track(*board_frames(board, 600), ppr)
    assert tr.counters.missed > 0 and tr.counters.extra > 0
    s = np.arange(0, tr.covered_until, 3)
    hz, valid = tr.evaluate_causal(s)
    true = sc.shaft_hz(s / FS)
    runup = (true * 60 > 800) & (s < 4.95 * FS)
    assert valid[runup].all()
    assert np.max(np.abs(hz[runup] - true[runup]) / true[runup]) < 0.005
    # the abrupt end of the run-up (constant speed from 5 s): an overshoot that dies out
    after = s > 5.6 * FS
    assert np.max(np.abs(hz[after] - true[after]) / true[after]) < 0.005
    assert np.max(np.abs(hz - true)[s > 4.95 * FS] / true[s > 4.95 * FS]) < 0.02


def test_causal_speed_of_a_dead_encoder_is_capped_then_invalid():
    _, board = make_board("healthy", 6.0, 1, tacho_missed=tuple(range(100, 130)))
    q = board.tacho_pulses(0, 600)["edges"] / 256
    e99, e130, e131 = q[99], q[100], q[101]
    tr, _ = track(*board_frames(board, 600), 1)
    P = FS / 28.66
    hz, valid = tr.evaluate_causal(np.array([e99 + 0.5 * P, e99 + 2 * P, e99 + 5 * P,
                                             e99 + 0.5 * FS + 1, e130 + 1, e131 + 1]))
    assert abs(hz[0] - 28.66) < 0.03 and abs(hz[1] - 28.66) < 0.03   # a missed pulse is no news
    assert abs(hz[2] - 28.66 * 2.5 / 5) < 0.03                         # then 2.5 pulses over the wait
    assert valid[:3].all()
    assert hz[3] == 0 and not valid[3]                                 # after the timeout
    assert hz[4] == 0 and not valid[4]                                 # one new edge: no speed yet
    assert valid[5] and hz[5] > 0


def test_causal_range_equals_causal_evaluation_bit_for_bit():
    """The order chain's segment-by-segment path equals the per-sample one, over ranges
    before the first edge, across missed/extra pulses, a loss and a restart."""
    rng = np.random.default_rng(5)
    tr = TachoTracker(FS, 2, block_len=L)
    t0, edges = FRAMES
    tr.update(t0, edges)
    ranges = [(0, 500), (0, 500 * L), (499 * L, 500 * L + 300)]
    ranges += [tuple(sorted(rng.integers(0, 500 * L, 2))) for _ in range(40)]
    for a, b in ranges:
        hz, valid = tr.causal_range(a, b)
        ref_hz, ref_valid = tr.evaluate_causal(np.arange(a, b))
        assert np.array_equal(hz, ref_hz, equal_nan=True) and np.array_equal(valid, ref_valid), (a, b)
    assert tr.causal_range(10, 10)[0].size == 0
