"""The order tracker's start (a replay's fixed cost): with the table's gains it
solves no bandwidth -> r at construction, and its first fill only at the grid points around
its speeds (min_rpm, where the speed is not known yet, and the running speed, none between);
once the speed moves to another segment the table's whole range comes in one batch.  The
outputs are those of a tracker whose r grid was computed over the whole range up front,
bit for bit."""

from __future__ import annotations

import numpy as np

import cmsensord.dsp.order_tracker.bandwidth as bandwidth
from cmsensord.dsp.order_tracker import OrderTracker, TrackedComponent


def comps(pct: float) -> list[TrackedComponent]:
    """Components no other test uses (the r grid is cached per component and rate)."""
    return [TrackedComponent(f"{k}x", order=float(k), bandwidth_pct=pct) for k in (1, 2, 3, 4)]


def computed(cs) -> int:
    """Grid points of r computed so far for these components."""
    return sum(int(np.isfinite(lr).sum()) for (c, _), lr in bandwidth._R_CACHE.items() if c in cs)


def test_the_r_grid_is_solved_where_the_table_needs_it_with_the_same_outputs():
    kw = {"fs_in": 25000.0, "max_rpm": 3600.0, "smoother_lag_s": 0.05}
    late = comps(5.0123)
    tr = OrderTracker(late, **kw)
    assert computed(late) == 0                          # nothing solved at construction
    rng = np.random.default_rng(2)
    y = rng.standard_normal(60000)
    steady = np.full(30000, 1720.0)
    steady[:5000] = 0.0                                 # no speed yet: the model runs at min_rpm
    first = tr.process(y[:30000], steady)
    at_one_speed = computed(late)
    assert 0 < at_one_speed <= 4 * 16                   # a few grid points around 300 and 1720 rpm
    ramp = np.linspace(1720.0, 3500.0, 30000)
    second = tr.process(y[30000:], ramp)
    assert computed(late) >= 4 * 60                     # then the whole 300-3960 rpm range

    same = comps(5.0125)
    a = OrderTracker(same, **kw)
    outs_a = [a.process(y[:30000], steady), a.process(y[30000:], ramp)]
    bandwidth._R_CACHE.update({k: np.full_like(v, np.nan) for k, v in bandwidth._R_CACHE.items() if k[0] in same})
    b = OrderTracker(same, **kw)
    assert b.table is not None
    bandwidth.component_r(same, b.table.grid.speeds(np.arange(b.table.grid.n)), b.fs_track)   # one batch
    outs_b = [b.process(y[:30000], steady), b.process(y[30000:], ramp)]
    for oa, ob in zip(outs_a, outs_b):
        for attr in ("waveform", "smoothed_waveform"):
            assert np.array_equal(getattr(oa, attr), getattr(ob, attr))
        for f in ("rms", "amplitude"):
            assert np.array_equal(getattr(oa.blocks, f), getattr(ob.blocks, f), equal_nan=True)
    assert a.table is not None and a.table.P is not None and b.table.P is not None
    assert np.array_equal(a.table.kS, b.table.kS) and np.array_equal(a.table.P, b.table.P)
    assert first.blocks.rms.shape[0] > 0 and second.blocks.rms.shape[0] > 0
