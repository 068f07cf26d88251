"""`OrderTracker.process_blocks` with a speed function through the live path (live.py's
`LiveCall`: the kernel's `live_in` and `live_out`) against the same tracker with the live path
turned off (the general path: `_prepare`, `_coeffs_gains`, `fused_blocks`, or `process`), bit
for bit, call by call, with the state carried: calls of a tenth of a second and of every
length around it (shorter than the delay line, ending mid-block, several blocks), a speed
through min_rpm and above the tracker's Nyquist (invalid blocks, new table segments), NaN in
some calls and the calls right after them (a missing input near), 1-3 channels, orders and a
fixed frequency (the table's linear grid: no `live_out`), the daemon's configuration.  The
speeds asked for are the same samples, each once."""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.dsp.order_tracker import OrderTracker, TrackedComponent, have_kernel
from test_tracker_fused_blocks import assert_same_blocks, assert_same_state

pytestmark = pytest.mark.skipif(not have_kernel(), reason="the compiled tracker kernel is not built")


class Speed:
    """rpm at absolute input samples, as a function of a call's samples; records what is asked."""

    def __init__(self, rpm: np.ndarray):
        self.rpm, self.asked = rpm, []

    def at(self, start: int):
        def speed(i):
            self.asked.append(start + np.asarray(i))
            return self.rpm[start + i]
        return speed


class Counted:
    """A kernel function that counts its calls and the ones it did (True)."""

    def __init__(self, f):
        self.f, self.calls, self.done = f, 0, 0

    def __call__(self, *a):
        got = self.f(*a)
        self.calls += 1
        self.done += got is True
        return got


def signal(T: int, C: int, fs: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    rpm = np.concatenate([np.linspace(250.0, 3000.0, T // 2), np.linspace(3000.0, 4100.0, T - T // 2)])
    rpm += rng.normal(0.0, 3.0, T)
    phase = np.cumsum(rpm / 60.0) / fs * 2 * np.pi
    y = np.stack([(ch + 1) * np.sin(phase * (ch + 1)) + 0.3 * np.sin(4 * phase + ch)
                  + 0.1 * rng.standard_normal(T) for ch in range(C)], axis=1)
    return y, rpm


def run_both(comps, C: int, fs: float, sizes: list[int], nan_calls: set[int], seed: int, **kw):
    live, ref = (OrderTracker(comps, fs_in=fs, max_rpm=3600.0, n_channels=C, backend="c", **kw)
                 for _ in range(2))
    assert live._live is not None
    ref._live = None
    lc = live._live
    lc._live_in, lc._live_out = Counted(lc._live_in), Counted(lc._live_out)
    T = sum(sizes)
    y, rpm = signal(T, C, fs, seed)
    sa, sb = Speed(rpm), Speed(rpm)
    at = 0
    n_blocks = 0
    for i, n in enumerate(sizes):
        yy = y[at:at + n].copy()
        if i in nan_calls:
            yy[n // 2, i % C] = np.nan
        want, ws = ref.process_blocks(yy, sb.at(at))
        got, gs = live.process_blocks(yy, sa.at(at))
        assert gs is None and ws is None
        assert_same_blocks(got, want, f"call {i} at {at}")
        assert_same_state(live, ref, f"call {i} at {at}")
        assert np.array_equal(live.state.last_miss, ref.state.last_miss)
        n_blocks += len(got.start)
        at += n
    assert len(sa.asked) == len(sb.asked)
    for a, b in zip(sa.asked, sb.asked):
        assert np.array_equal(a, b)
    asked = np.concatenate(sa.asked)
    assert (np.diff(asked) > 0).all()                   # each sample once
    return lc, n_blocks


@pytest.mark.parametrize("C", [1, 2, 3])
def test_the_live_path_equals_the_general_path(C):
    comps = [TrackedComponent(f"{k}x", order=float(k), bandwidth_pct=5.0) for k in range(1, 5)]
    rng = np.random.default_rng(C)
    sizes = [2500, 1, 7, 30, 2499, 2501, 2500, 7000, 5, 100_000]     # 100 000: more than SCRATCH
    sizes += [int(n) for n in rng.integers(1, 6000, 40)] + [2500] * 60
    nan_calls = {15, 16, 30}
    lc, n_blocks = run_both(comps, C, 25_000.0, sizes, nan_calls, seed=C, output_rate_hz=10.0)
    assert n_blocks > 100
    assert lc._live_in.done > 90                        # the live path ran in most calls
    assert lc._live_in.calls - lc._live_in.done >= 2    # and declined with a NaN
    assert lc._live_out.done > 80 and lc._live_out.calls > lc._live_out.done   # new table rows: declined


def test_a_fixed_frequency_takes_the_live_path_without_live_out():
    """A fixed frequency crossing the orders: the table's grid is linear above some speed, so
    the gains come from the table's lookup (live_out is not used); the same blocks still."""
    comps = [TrackedComponent("1x", order=1.0), TrackedComponent("2x", order=2.0),
             TrackedComponent("47 Hz", freq_hz=47.0)]
    lc, n_blocks = run_both(comps, 2, 10_000.0, [1000] * 150 + [333] * 30, {40}, seed=7, output_rate_hz=20.0)
    assert not lc._direct and lc._live_out.calls == 0
    assert lc._live_in.done > 150 and n_blocks > 100


def test_the_live_kernels_check_their_buffers():
    from cmsensord.dsp import _trackerkernel as k

    comps = [TrackedComponent("1x", order=1.0), TrackedComponent("2x", order=2.0)]
    tr = OrderTracker(comps, fs_in=5000.0, max_rpm=3600.0, n_channels=1, backend="c")
    st, om = tr.state, tr.omegas
    T, D = 400, tr.decimate
    N = (T + D - 1) // D
    args = [tr.sos, np.zeros((T, 1)), st.zi, 0, D, st.last_miss, 10**6, tr.missing_window, st.rpm_line.copy(),
            np.zeros(len(range(0, T, D))), 0, 300.0, om.orders, om.fixed, om.by_order_u8, 2 * np.pi,
            tr.fs_track, 300.0, np.empty((N, 1)), np.empty(N), np.empty(N), np.empty(N), np.empty((N, 2))]
    assert k.live_in(*args) in (True, False)
    bad = list(args)
    bad[-1] = np.empty((N - 1, 2))
    with pytest.raises(ValueError, match="w"):
        k.live_in(*bad)
    bad = list(args)
    bad[5] = np.zeros(2, dtype=np.int64)             # last_miss of another channel count
    with pytest.raises(ValueError, match="last_miss"):
        k.live_in(*bad)
    nan = list(args)
    nan[1] = np.full((T, 1), np.nan)
    zi = st.zi.copy()
    assert k.live_in(*nan) is False and np.array_equal(st.zi, zi)      # declined, nothing changed
