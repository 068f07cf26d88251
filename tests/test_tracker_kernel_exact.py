"""The order tracker's compiled loops against plain references, bit for bit: the anti-alias
cascade (its state in registers for cascades of up to 8 sections, the general loop beyond)
against the direct form II transposed written out per sample in Python floats, the gain
table's interpolation in the kernel against its numpy lookup, and the peak amplitudes of the
state pairs against recursions.envelope."""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.dsp.order_tracker import OrderTracker, TrackedComponent, have_kernel
from cmsensord.dsp.order_tracker.gain_table import GainTable
from cmsensord.dsp.order_tracker.recursions import envelope

pytestmark = pytest.mark.skipif(not have_kernel(), reason="the compiled tracker kernel is not built")


def sosfilt_reference(sos, x, zi, skip, D):
    """scipy.signal.sosfilt's arithmetic, one sample, channel and section at a time (Python
    floats are IEEE doubles: the same roundings), every D-th output from ``skip`` on."""
    T, C = x.shape
    z = zi.copy()
    out = []
    for n in range(T):
        row = []
        for ch in range(C):
            v = float(x[n, ch])
            for s, (b0, b1, b2, _, a1, a2) in enumerate(sos.tolist()):
                new = b0 * v + z[s, 0, ch]
                z[s, 0, ch] = b1 * v - a1 * new + z[s, 1, ch]
                z[s, 1, ch] = b2 * v - a2 * new
                v = new
            row.append(v)
        if n >= skip and (n - skip) % D == 0:
            out.append(row)
    return np.array(out).reshape(-1, C), z


@pytest.mark.parametrize("S", [1, 2, 3, 4, 5, 8, 9, 11])
@pytest.mark.parametrize("C", [1, 3])
def test_the_kernels_cascade_equals_the_per_sample_reference(S, C):
    from cmsensord.dsp import _trackerkernel

    rng = np.random.default_rng(S * 10 + C)
    sos = np.empty((S, 6))
    sos[:, :3] = rng.uniform(-1, 1, (S, 3))
    sos[:, 3] = 1.0
    sos[:, 4:] = rng.uniform(-0.4, 0.4, (S, 2))          # stable sections
    x = rng.standard_normal((500, C))
    zi = rng.standard_normal((S, 2, C))
    for skip, D in ((0, 1), (3, 7), (499, 5), (600, 4)):
        want, z_want = sosfilt_reference(sos, x, zi, skip, D)
        out = np.full((len(want), C), np.nan)
        z = zi.copy()
        _trackerkernel.sosfilt(sos, x, z, out, skip, D)
        assert np.array_equal(out, want) and np.array_equal(z, z_want), (skip, D)


@pytest.mark.parametrize("lag", [None, 0.05])
def test_the_kernels_table_lookup_equals_the_numpy_one(lag):
    """Random speeds over the whole grid, below it and at its top (the last interval, f
    clipped to 1): k, S and P are the numpy lookup's, bit for bit."""
    comps = [TrackedComponent(f"{k}x", order=float(k), bandwidth_pct=5.0) for k in (1, 2, 3)]
    tr = OrderTracker(comps, fs_in=25000.0, max_rpm=3600.0, smoother_lag_s=lag, backend="c")
    t = tr.table
    assert t is not None and t._lerp is not None
    plain = GainTable(t.grid, tr.K, lag is not None, tr._steady_state, kernel=False)
    assert plain._lerp is None
    rng = np.random.default_rng(1)
    speed = np.concatenate([rng.uniform(100.0, 4200.0, 3000), [300.0, 3960.0, 5000.0, 250.0]])
    got, want = t.lookup(speed), plain.lookup(speed)
    for a, b in zip(got, want):
        if b is None:
            assert a is None
        else:
            assert a.shape == b.shape and a.flags.c_contiguous and np.array_equal(a, b)
    assert got[2] is None or got[2].shape == (len(speed), 6, 6)


def test_the_kernels_lookup_at_grid_coordinates_equals_the_numpy_one(monkeypatch):
    """Once the table holds the rows, the kernel's lookup at grid coordinates (index, fraction
    and rows in one pass, ``lerp_at``) gives the numpy lookup's k and S, bit for bit; a speed
    whose rows are not there yet goes the way that fills them (lerp_at says so, writing
    nothing), also when it comes among speeds whose rows are."""
    from cmsensord.dsp import _trackerkernel

    comps = [TrackedComponent(f"{k}x", order=float(k), bandwidth_pct=5.0) for k in (1, 2, 4)]
    tr = OrderTracker(comps, fs_in=25000.0, max_rpm=3600.0, backend="c")
    t = tr.table
    assert t is not None and t._lerp_at is not None
    plain = GainTable(t.grid, tr.K, False, tr._steady_state, kernel=False)
    answers = []
    lerp_at = t._lerp_at

    def spy(*args):
        answers.append(lerp_at(*args))
        return answers[-1]

    monkeypatch.setattr(t, "_lerp_at", spy)
    rng = np.random.default_rng(2)
    low = rng.uniform(250.0, 1500.0, 2000)
    t.lookup(low)                                               # fills the rows of these speeds
    assert answers == [False]
    for speed in (low, np.concatenate([low[::-7], [300.0, 299.0, 250.0]]), low[:0]):
        got, want = t.lookup(speed), plain.lookup(speed)
        assert answers[-1] is True and got[2] is None and want[2] is None
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    high = np.concatenate([low[:50], [3900.0]])                 # a row not there yet
    got, want = t.lookup(high), plain.lookup(high)
    assert answers[-1] is False
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    k, S = np.empty((1, 6)), np.empty(1)
    for bad in (np.nan, -1.0):                                  # not a grid coordinate: numpy's way
        assert _trackerkernel.lerp_at(t.kS, t.dkS, np.array([bad]), t.have.view(np.uint8), 64, k, S,
                                      7, 6) is False


def test_omegas_in_one_operation_equal_omega():
    from cmsensord.dsp.order_tracker.components import Omegas, omega

    rng = np.random.default_rng(3)
    speed = np.concatenate([rng.uniform(300.0, 4000.0, 500), [300.0, 1e-3, 1e9]])
    for comps in ([TrackedComponent(f"{k}x", order=k) for k in (1.0, 2.0, 3.7, 4.0)],
                  [TrackedComponent("1x", order=1.0), TrackedComponent("mains", freq_hz=50.0),
                   TrackedComponent("bpfo", order=3.58)]):
        assert np.array_equal(Omegas(comps)(speed), omega(comps, speed))


def test_the_kernels_lookup_refuses_rows_outside_the_table():
    from cmsensord.dsp import _trackerkernel

    tab, dtab = np.zeros((4, 3)), np.zeros((3, 3))
    a, b = np.empty((2, 2)), np.empty(2)
    for bad in ([0, 3], [-1, 0]):
        with pytest.raises(ValueError, match="outside"):
            _trackerkernel.lerp_rows(tab, dtab, np.array(bad, dtype=np.int64), np.zeros(2), a, b, 3, 2)
    with pytest.raises(ValueError, match="expected"):
        _trackerkernel.lerp_rows(tab, dtab, np.zeros(3, dtype=np.int64), np.zeros(2), a, b, 3, 2)


@pytest.mark.parametrize("C,K", [(1, 1), (1, 4), (3, 2)])
def test_the_kernels_envelope_equals_the_numpy_one(C, K):
    """Random states and coefficients, c near +-2 (1 - c^2/4 at the 1e-300 floor), zeros,
    NaN and inf: the same numbers, bit for bit (NaN where numpy gives NaN)."""
    from cmsensord.dsp import _trackerkernel

    rng = np.random.default_rng(C * 7 + K)
    N = 500
    xs = rng.standard_normal((N, C, 2 * K)) * rng.choice([1e-3, 1.0, 1e3], (N, C, 2 * K))
    c = rng.uniform(-2.0, 2.0, (N, K))
    c[:20] = 2.0
    c[20:40] = -2.0
    c[40:60] = 2.0 - 1e-17
    xs[60:70] = 0.0
    xs[70, 0, 0] = np.nan
    xs[71, 0, 1] = np.inf
    c[72, 0] = np.nan
    with np.errstate(invalid="ignore"):                   # inf - inf: NaN, as in the kernel
        want = envelope(xs, c)
    got = np.empty((N, C, K))
    _trackerkernel.envelope(xs, c, got, K)
    assert np.array_equal(got, want, equal_nan=True)
    assert np.isnan(want).any()
    with pytest.raises(ValueError, match="expected"):
        _trackerkernel.envelope(xs[:, :, :-1].copy(), c, got, K)


@pytest.mark.parametrize("fs,f_hi", [(25000.0, 240.0), (25000.0, 1000.0), (2000.0, 80.0)])
def test_the_impulse_response_from_the_kernel_equals_the_python_loop(monkeypatch, fs, f_hi):
    """missing_window_of reads the anti-alias filter's impulse response: from the kernel's
    cascade, the Python loop's numbers bit for bit, so the same window W."""
    from cmsensord.dsp.order_tracker import antialias

    order, fc = antialias.cheb2ord(f_hi, fs / 10 - f_hi, 0.001, 80.0, fs)
    sos = antialias.cheby2_sos(order, 80.0, fc, fs)
    fast = antialias._sos_impulse(sos)
    w_fast = antialias.missing_window_of(sos)
    monkeypatch.setattr(antialias, "_trackerkernel", None)
    assert np.array_equal(fast, antialias._sos_impulse(sos)) and len(fast) > 500
    assert antialias.missing_window_of(sos) == w_fast


@pytest.mark.parametrize("C", [1, 2, 3])
@pytest.mark.parametrize("K", [1, 2, 4])
def test_the_kernels_block_statistics_equal_the_numpy_ones(C, K):
    """Random blocks of every length around numpy's 8 accumulators and the live 125 samples,
    speeds below min_rpm, above the tracker's Nyquist and NaN (invalid blocks, NaN statistics):
    rms, amplitude, mean speed and validity are numpy's, bit for bit, and the kernel runs."""
    comps = [TrackedComponent(f"{k}x", order=float(k)) for k in range(1, K + 1)]
    tr = OrderTracker(comps, fs_in=25000.0, max_rpm=3600.0, n_channels=C, backend="c")
    calls = []
    kernel = tr._stats_kernel
    assert kernel is not None
    tr._stats_kernel = lambda *a: calls.append(1) or kernel(*a)
    rng = np.random.default_rng(10 * C + K)
    for E in (1, 2, 5):
        for B in (1, 3, 7, 8, 9, 17, 125, 200):
            wave = rng.standard_normal((E, B, C, K)) * 10.0 ** rng.uniform(-3, 3)
            env = np.abs(rng.standard_normal((E, B, C, K)))
            rpm = rng.uniform(200.0, 4000.0, (E, B))
            rpm[0, rng.integers(B)] = [np.nan, 100.0, 1e5, -1500.0][rng.integers(4)]
            got = tr._block_stats(np.arange(E) * B, wave, env, rpm, None)
            want = tr._block_stats_numpy(wave, env, rpm)
            for a, b in zip((got.rms, got.amplitude, got.rpm, got.valid), want):
                assert a.shape == b.shape and a.dtype == b.dtype
                assert np.array_equal(a, b, equal_nan=True)
    assert len(calls) == 3 * 8
