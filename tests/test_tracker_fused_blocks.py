"""`OrderTracker.process_blocks` (what the order chain calls: the filter, the envelope and the
block statistics of a call in one kernel pass, `forward_blocks`, when no sample is missing)
against the blocks of `process` (forward, envelope and block_stats one after the other), bit
for bit, call by call, with the state carried between calls: calls of every length around
the output block (shorter than the part of a block left, ending mid-block, several blocks),
missing samples in some calls (those go the long way; the calls after them the short one
again), speeds below min_rpm and above the tracker's Nyquist (invalid blocks, NaN
statistics), 1-3 channels, 1-4 components, table and exact gains, a speed function."""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.dsp.order_tracker import BlockStats, OrderTracker, TrackedComponent, have_kernel

pytestmark = pytest.mark.skipif(not have_kernel(), reason="the compiled tracker kernel is not built")

FIELDS = ("start", "t_in", "rpm", "rms", "amplitude", "valid", "missing")


def assert_same_blocks(got: BlockStats, want: BlockStats, where: str) -> None:
    for name in FIELDS:
        a, b = getattr(got, name), getattr(want, name)
        assert a.shape == b.shape and a.dtype == b.dtype, (where, name, a.shape, b.shape)
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), (where, name)


def assert_same_state(got: OrderTracker, want: OrderTracker, where: str) -> None:
    a, b = got.state, want.state
    assert (a.n_in, a.n_track, a.skip) == (b.n_in, b.n_track, b.skip), where
    assert np.array_equal(a.z, b.z) and np.array_equal(a.zi, b.zi), where
    assert np.array_equal(a.rpm_line, b.rpm_line, equal_nan=True), where
    assert sorted(a.pend) == sorted(b.pend), where
    for key in a.pend:
        assert np.array_equal(a.pend[key], b.pend[key]), (where, key)


def signal(T: int, C: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Orders of a shaft speeding up through the valid range and beyond (invalid blocks at
    both ends), noise, one channel louder than the others."""
    rng = np.random.default_rng(seed)
    rpm = np.linspace(200.0, 4200.0, T) + rng.normal(0.0, 5.0, T)
    phase = np.cumsum(rpm / 60.0) / 5000.0 * 2 * np.pi
    y = np.stack([(ch + 1) * np.sin(phase * (ch + 1)) + 0.3 * np.sin(2 * phase + ch)
                  + 0.1 * rng.standard_normal(T) for ch in range(C)], axis=1)
    return y, rpm


def cuts(T: int, rng: np.random.Generator, per_block: int) -> list[int]:
    """Call lengths: tiny, around a block, several blocks; then whole blocks."""
    sizes = [1, 7, per_block - 1, per_block, per_block + 1, 3 * per_block + 11, 2 * per_block]
    sizes += list(rng.integers(1, 4 * per_block, 30))
    out, at = [], 0
    for n in sizes + [per_block] * T:
        if at >= T:
            break
        out.append(min(int(n), T - at))
        at += out[-1]
    return out


@pytest.mark.parametrize("gains", ["table", "exact"])
@pytest.mark.parametrize("C,K", [(1, 4), (1, 1), (2, 3), (3, 2)])
def test_process_blocks_equals_the_blocks_of_process(gains, C, K):
    comps = [TrackedComponent(f"{k}x", order=float(k)) for k in range(1, K + 1)]
    if K >= 3:
        comps[-1] = TrackedComponent("47 Hz", freq_hz=47.0)
    kw = dict(fs_in=5000.0, max_rpm=3600.0, n_channels=C, gains=gains, backend="c", output_rate_hz=20.0)
    ref, fused = OrderTracker(comps, **kw), OrderTracker(comps, **kw)
    calls = []
    kernel = fused._fused_kernel
    assert kernel is not None and ref.decimate > 1
    fused._fused_kernel = lambda *a: calls.append(1) or kernel(*a)
    T = 40_000
    y, rpm = signal(T, C, 10 * C + K)
    rng = np.random.default_rng(C + K)
    per_block = fused.block * fused.decimate
    at = 0
    n_blocks = 0
    for i, n in enumerate(cuts(T, rng, per_block)):
        yy = y[at:at + n].copy()
        if i in (12, 13) and n > 3:                  # missing samples in some calls: the long way
            yy[n // 3, i % C if gains == "table" else slice(None)] = np.nan   # exact: all channels
        want = ref.process(yy, rpm[at:at + n])
        got, smoothed = fused.process_blocks(yy, rpm[at:at + n])
        assert smoothed is None and want.smoothed_blocks is None
        assert_same_blocks(got, want.blocks, f"call {i} at {at}")
        assert_same_state(fused, ref, f"call {i} at {at}")
        n_blocks += len(got.start)
        at += n
    assert at == T and n_blocks > 100
    assert len(calls) > 40                          # the kernel pass ran in most calls
    assert not fused.state.pend or len(fused.state.pend["rpm"]) < fused.block


def test_process_blocks_with_a_speed_function_and_the_smoother():
    """With a speed function (what the order chain passes) the same as process with it; with
    the smoother the call goes through process (its smoothed blocks too)."""
    comps = [TrackedComponent("1x", order=1.0), TrackedComponent("2x", order=2.0)]
    y, rpm = signal(30_000, 2, 3)
    for lag in (None, 0.05):
        kw = dict(fs_in=5000.0, max_rpm=3600.0, n_channels=2, backend="c", smoother_lag_s=lag)
        ref, fused = OrderTracker(comps, **kw), OrderTracker(comps, **kw)
        for a in range(0, 30_000, 2_300):
            b = min(a + 2_300, 30_000)
            want = ref.process(y[a:b], lambda i, a=a: rpm[a + i])
            got, smoothed = fused.process_blocks(y[a:b], lambda i, a=a: rpm[a + i])
            assert_same_blocks(got, want.blocks, f"lag {lag} at {a}")
            if lag is None:
                assert smoothed is None
            else:
                assert smoothed is not None and want.smoothed_blocks is not None
                assert_same_blocks(smoothed, want.smoothed_blocks, f"smoothed at {a}")
            assert_same_state(fused, ref, f"lag {lag} at {a}")


def test_the_numpy_backend_takes_the_long_way():
    """Without the kernel (backend numpy) process_blocks is process's blocks."""
    comps = [TrackedComponent("1x", order=1.0), TrackedComponent("3x", order=3.0)]
    y, rpm = signal(12_000, 1, 5)
    kw = dict(fs_in=5000.0, max_rpm=3600.0, n_channels=1, backend="numpy")
    ref, other = OrderTracker(comps, **kw), OrderTracker(comps, **kw)
    assert other._fused_kernel is None
    for a in range(0, 12_000, 1_700):
        want = ref.process(y[a:a + 1_700], rpm[a:a + 1_700])
        got, _ = other.process_blocks(y[a:a + 1_700], rpm[a:a + 1_700])
        assert_same_blocks(got, want.blocks, f"at {a}")


def test_the_kernel_checks_its_buffers():
    from cmsensord.dsp import _trackerkernel

    K, C, B = 2, 1, 5
    y, c, k = np.zeros((10, C)), np.zeros((10, K)), np.zeros((10, 2 * K))
    z, rpm = np.zeros((C, 2 * K)), np.zeros(10)
    out = [np.empty((2, C, K)), np.empty((2, C, K)), np.empty(2), np.empty(2, dtype=np.uint8),
           np.empty((0, C, K)), np.empty((0, C, K))]
    none = np.empty((0, C, K))
    _trackerkernel.forward_blocks(y, c, k, z, rpm, K, B, 0, none, none, 300.0, 2.0, 100.0, *out)
    with pytest.raises(ValueError, match="rpm"):
        _trackerkernel.forward_blocks(y, c, k, z, rpm[:9], K, B, 0, none, none, 300.0, 2.0, 100.0, *out)
    with pytest.raises(ValueError, match="cw"):
        _trackerkernel.forward_blocks(y, c, k, z, np.zeros(13), K, B, 3, none, none, 300.0, 2.0, 100.0,
                                      out[0], out[1], out[2], out[3], np.empty((3, C, K)), np.empty((3, C, K)))
    with pytest.raises(ValueError, match="tw"):
        _trackerkernel.forward_blocks(y, c, k, z, np.zeros(12), K, B, 2, np.zeros((2, C, K)), np.zeros((2, C, K)),
                                      300.0, 2.0, 100.0, *out)


@pytest.mark.parametrize("K", [1, 3, 5])
def test_the_kernels_model_speed_and_omega_equal_numpys(K):
    """``Omegas.scaled`` (the model speed and omega / fs of every tracker call) in the kernel and
    in numpy: the same bits, with speeds negative, below min_rpm, at it, huge, NaN and infinite,
    orders and fixed frequencies mixed."""
    from cmsensord.dsp.order_tracker import components

    comps = [TrackedComponent(f"c{k}", order=0.37 + 1.3 * k) if k % 2 == 0 else
             TrackedComponent(f"c{k}", freq_hz=47.0 + 11.1 * k) for k in range(K)]
    om = components.Omegas(comps)
    rng = np.random.default_rng(K)
    rpm = np.concatenate([rng.uniform(-4000.0, 4000.0, 500), [0.0, -0.0, 300.0, 299.99, 1e300, -1e300,
                                                              np.nan, np.inf, -np.inf, 5e-324]])
    calls = []
    kernel = components._model_omega
    assert kernel is not None
    components._model_omega = lambda *a: calls.append(1) or kernel(*a)
    try:
        for fs in (1250.0, 2000.0 / 3.0):
            got = om.scaled(rpm, 300.0, fs)
            want = om.scaled(rpm, 300.0, fs, kernel=False)
            for a, b in zip(got, want):
                assert a.shape == b.shape and np.array_equal(a, b)
            assert np.array_equal(want[0], components.model_speed(rpm, 300.0))
    finally:
        components._model_omega = kernel
    assert len(calls) == 2
