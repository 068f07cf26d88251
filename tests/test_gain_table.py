"""The order tracker's gain table: bounded memory, its speed grid, its interpolation error.

The table holds the steady-state gains on a geometric speed grid (gain_table.py);
these tests hold its memory at 16 orders on a full run-up, the shape of the grid,
and the interpolation error against the steady state solved at the very speed.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from cmsensord.dsp.order_tracker import OrderTracker, TrackedComponent
from cmsensord.dsp.order_tracker.gain_table import BUDGET_BYTES, choose_grid

ORDERS16 = [TrackedComponent(f"{k}x", order=float(k), bandwidth_pct=5.0) for k in range(1, 17)]


def _runup(fs: float, seconds: float, lo: float, hi: float):
    t = np.arange(round(fs * seconds)) / fs
    rpm = lo + (hi - lo) * t / seconds
    y = np.sin(2 * np.pi * np.cumsum(rpm / 60.0) / fs) + 0.3 * np.sin(4 * np.pi * np.cumsum(rpm / 60.0) / fs)
    return y, rpm


@pytest.mark.parametrize("lag", [None, 0.1])
def test_table_memory_at_16_orders_on_a_full_run_up_is_at_most_20_mb(lag):
    """16 orders at 25 kHz (D = 5), the daemon's 300-3960 rpm table, a run-up from
    below min_rpm to above 1.1 max_rpm: every segment of the table is filled, and it
    holds <= 20 MB (62 MB with all 3662 speeds, P and its differences always); what
    the tracker keeps after the run (table + state, traced by tracemalloc) too.
    Without the smoother P is not kept at all: <= 1 MB."""
    y, rpm = _runup(25000.0, 2.0, 200.0, 4100.0)
    tracemalloc.start()
    try:
        tr = OrderTracker(ORDERS16, fs_in=25000.0, max_rpm=3600.0, smoother_lag_s=lag)
        for i in range(0, len(y), 5000):
            tr.process(y[i:i + 5000, None], rpm[i:i + 5000])
        held, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    table = tr.table
    assert table is not None and tr.decimate == 5 and tr.K == 16
    assert table.have.all()                                  # the whole grid was visited
    assert table.filled_bytes == table.nbytes
    assert table.nbytes <= (20e6 if lag else 1e6), table.nbytes
    assert (table.P is None) == (lag is None)
    assert held <= table.nbytes + 5e6, (held, table.nbytes)  # nothing big kept beside it


def test_grid_is_geometric_with_todays_step_at_min_rpm():
    """Default grid: step min_rpm/300 at min_rpm (1 rpm at 300 rpm, the old uniform
    step), growing with the speed; it covers [min_rpm, 1.1 max_rpm]; a coordinate
    maps each grid speed back to its index."""
    tr = OrderTracker(ORDERS16[:4], fs_in=25000.0, max_rpm=3600.0)
    g = tr.table.grid
    s = g.speeds(np.arange(g.n))
    assert s[0] == 300.0 and s[-2] < 3960.0 <= s[-1]
    assert np.diff(s)[0] == pytest.approx(1.0, rel=1e-9)
    np.testing.assert_allclose(np.diff(s) / s[:-1], 1.0 / 300.0, rtol=1e-9)
    assert g.n == 777                                        # 3662 with the old 1-rpm grid
    np.testing.assert_allclose(g.coord(s), np.arange(g.n), rtol=0, atol=1e-9)


def test_crossing_of_a_fixed_frequency_keeps_a_1_rpm_step():
    """A fixed-frequency component that an order crosses (47 Hz = order 1 at 2820 rpm):
    steps of at most 1 rpm; without a crossing in range the grid stays geometric."""
    comps = [TrackedComponent("1x", order=1.0, r=50.0), TrackedComponent("47 Hz", freq_hz=47.0, r=50.0)]
    cross = OrderTracker(comps, fs_in=2000.0, max_rpm=7000.0, decimate=1).table.grid
    assert np.diff(cross.speeds(np.arange(cross.n))).max() <= 1.0 + 1e-9
    none = OrderTracker(comps, fs_in=2000.0, max_rpm=2000.0, decimate=1).table.grid   # 47 Hz > 2200 rpm
    assert not none.linear and none.n < 700


def test_grid_coarsens_to_fit_the_budget():
    """Too many points for the budget: the cap on the step doubles, then the relative step
    grows; the grid still spans the range and the table fits."""
    per_point = 200_000
    g = choose_grid(300.0, 3960.0, None, 1.0, per_point)
    assert g.n * per_point <= BUDGET_BYTES and g.n >= 16
    s = g.speeds(np.arange(g.n))
    assert s[0] == 300.0 and s[-1] >= 3960.0 - 1e-6 and s[-2] < 3960.0


def test_interpolated_gains_against_the_steady_state_at_that_speed():
    """Midway between grid points (the worst place), on the daemon's default 4 orders
    at 1250 Hz: k and P within 1e-4 of their largest element of the steady state
    solved at that speed (measured: 2.5e-5 and 1.7e-5; the old 1-rpm grid 2.7e-5)."""
    tr = OrderTracker(ORDERS16[:4], fs_in=25000.0, max_rpm=3600.0, smoother_lag_s=0.1)
    g = tr.table.grid
    mid = g.speeds(np.arange(g.n - 1) + 0.5)
    k, S, P = tr.table.lookup(mid)
    kS, Pt = tr._steady_state(mid)
    assert np.abs(k - kS[:, :-1]).max() / np.abs(kS[:, :-1]).max() <= 1e-4
    assert (np.abs(P - Pt).max(axis=(1, 2)) / np.abs(Pt).max(axis=(1, 2))).max() <= 1e-4
    np.testing.assert_allclose(S, kS[:, -1], rtol=1e-4)
    assert np.abs(k - kS[:, :-1]).max() > 0                  # they are interpolated, not solved


def test_a_long_call_is_tracked_in_bounded_pieces():
    """A 1.2-s call at 16 orders with the smoother (6050 tracker samples; the smoother's P
    alone is 8 kB a sample): the memory the call allocates at its peak stays <= 50 MB
    (151 MB when the call was tracked in one piece), and its outputs are those of the
    same input in 0.1-s calls."""
    y, rpm = _runup(25000.0, 2.5, 900.0, 1300.0)
    n = 30250
    a = OrderTracker(ORDERS16, fs_in=25000.0, max_rpm=3600.0, smoother_lag_s=0.1)
    a.process(y[:n, None], rpm[:n])                          # the table for these speeds
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        out = a.process(y[n:2 * n, None], rpm[n:2 * n])
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert peak <= 50e6, peak
    b = OrderTracker(ORDERS16, fs_in=25000.0, max_rpm=3600.0, smoother_lag_s=0.1)
    parts = [b.process(y[i:i + 2500, None], rpm[i:i + 2500]) for i in range(0, 2 * n, 2500)]
    wave = np.concatenate([p.waveform for p in parts])
    swave = np.concatenate([p.smoothed_waveform for p in parts])
    sidx = np.concatenate([p.smoothed_index for p in parts])
    assert len(out.waveform) == 6050 and len(out.blocks.rms) >= 10 and len(out.smoothed_index) >= 5000
    np.testing.assert_array_equal(out.waveform, wave[out.index])            # index: from the start
    np.testing.assert_array_equal(out.smoothed_waveform, swave[out.smoothed_index - sidx[0]])


def test_a_tracker_with_its_table_is_freed_without_the_cycle_collector():
    """The table holds its tracker's solver weakly: a tracker no longer used goes at once, its
    table (up to 16 MB) with it, not at the cycle collector's next full pass."""
    import gc
    import weakref

    gc.disable()
    try:
        tr = OrderTracker([TrackedComponent("1x", order=1.0), TrackedComponent("2x", order=2.0)], fs_in=25000.0,
                          max_rpm=3000.0)
        assert tr.table is not None
        tr.process(np.random.default_rng(0).standard_normal((5000, 1)), np.full(5000, 1720.0))
        gone = weakref.ref(tr)
        table = weakref.ref(tr.table)
        del tr
        assert gone() is None and table() is None
    finally:
        gc.enable()
