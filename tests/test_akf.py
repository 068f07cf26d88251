"""The AKF bank against Kim et al. 2023: the spike example, the reference, chunk splits."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cmsensord.dsp.akf import AkfBank, ScalarAKF, bank_r, have_kernel
from cmsensord.dsp.severity import AnomalyDecider

BACKENDS = ["numpy"] + (["c"] if have_kernel() else [])


def spike_input(seconds: int, seed: int) -> np.ndarray:
    """Kim et al. 2023 Fig. 4: a random signal at 100 Hz with 25 single-sample spikes per
    second (one every 4th sample).  The base is N(1, 0.05²), the spikes +2."""
    rng = np.random.default_rng(seed)
    y = 1.0 + 0.05 * rng.standard_normal(seconds * 100)
    y[::4] += 2.0
    return y


def outliers_per_second(y, *, scaling, window=10, backend="numpy"):
    bank = AkfBank(np.array([[1e-2]]), window=window, z_c=2.8, scaling=scaling, backend=backend)
    out = bank.process(y[:, None]).outlier[:, 0, 0]
    return out.reshape(-1, 100).sum(axis=1)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fig5_spikes_counted_once_each_with_scaling(seed, backend):
    """Fig. 5: R = 1e-2; the AKF counts the 25 spikes of every second after the first, exactly."""
    y = spike_input(30, seed)
    counts = outliers_per_second(y, scaling=True, backend=backend)[1:]
    assert (counts == 25).all(), counts


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fig5_without_scaling_counts_both_edges(seed):
    """Fig. 5: with S(k) = 1 each spike gives an outlier at both edges: 50 in every second after
    the first, where S(k) gives 25."""
    y = spike_input(30, seed)
    with_s = outliers_per_second(y, scaling=True)[1:]
    without = outliers_per_second(y, scaling=False)[1:]
    assert (with_s == 25).all() and (without == 50).all(), (without, with_s)


def random_stream(rng, T, C, p_missing=0.05):
    y = np.abs(rng.standard_normal((T, C))) + np.cumsum(rng.standard_normal((T, C)), axis=0) * 0.02
    y[rng.random((T, C)) < 0.01] += 3.0      # a few spikes
    valid = rng.random((T, C)) > p_missing
    return y, valid


def reference(R, y, valid, windows, z_c=2.8):
    T, C = y.shape
    n = R.shape[1]
    x_hat = np.full((T, C, n), np.nan)
    Q = np.full((T, C, n), np.nan)
    outl = np.zeros((T, C, n), dtype=np.uint8)
    for c in range(C):
        for i in range(n):
            f = ScalarAKF(R[c, i], window=windows[c], z_c=z_c)
            for k in range(T):
                r = f.step(float(y[k, c]) if valid[k, c] else None)
                x_hat[k, c, i] = r["x_hat"]
                Q[k, c, i] = r["Q"]
                outl[k, c, i] = r["outlier"]
    return x_hat, Q, outl


@pytest.mark.parametrize("backend", BACKENDS)
def test_vectorised_bank_equals_scalar_reference(backend):
    rng = np.random.default_rng(7)
    T, C, n = 1500, 3, 10
    y, valid = random_stream(rng, T, C)
    valid[:4, 2] = False                  # a channel whose first observations are missing
    R = np.stack([bank_r(4e-3, 0.13, n), bank_r(1e-3, 0.5, n), bank_r(4e-3, 0.13, n)])
    windows = [10, 4, 25]
    bank = AkfBank(R, window=windows, z_c=2.8, backend=backend)
    out = bank.process(y, valid)
    ref_x, ref_q, ref_o = reference(R, y, valid, windows)
    assert np.array_equal(np.isnan(out.x_hat), np.isnan(ref_x))
    np.testing.assert_allclose(out.x_hat, ref_x, rtol=0, atol=1e-12, equal_nan=True)
    np.testing.assert_allclose(out.Q, ref_q, rtol=1e-12, atol=1e-15, equal_nan=True)
    assert np.array_equal(out.outlier, ref_o)
    assert ref_o.sum() > 50               # the comparison covered outliers too


@pytest.mark.parametrize("backend", BACKENDS)
@settings(max_examples=25, deadline=None)
@given(split=st.integers(min_value=0, max_value=600), seed=st.integers(0, 3))
def test_two_chunks_equal_one_pass(backend, split, seed):
    rng = np.random.default_rng(seed)
    y, valid = random_stream(rng, 600, 2)
    R = np.stack([bank_r(4e-3, 0.13, 10)] * 2)
    one = AkfBank(R, window=10, z_c=2.8, backend=backend)
    a = one.process(y, valid)
    two = AkfBank(R, window=10, z_c=2.8, backend=backend)
    b1 = two.process(y[:split], valid[:split])
    b2 = two.process(y[split:], valid[split:])
    np.testing.assert_array_equal(a.x_hat, np.concatenate([b1.x_hat, b2.x_hat]))
    np.testing.assert_array_equal(a.outlier, np.concatenate([b1.outlier, b2.outlier]))
    for k in ("x", "P", "Q", "res2", "dx2", "pos", "fill"):
        np.testing.assert_array_equal(getattr(one.state, k), getattr(two.state, k))

    d1 = AnomalyDecider(2, 10, f_r=5.0, c=0.4, period=50)
    d2 = AnomalyDecider(2, 10, f_r=5.0, c=0.4, period=50)
    full = d1.update(a.outlier, valid)
    parts = d2.update(b1.outlier, valid[:split]) + d2.update(b2.outlier, valid[split:])
    assert [d.slot for d in full] == [d.slot for d in parts]
    for x, z in zip(full, parts):
        np.testing.assert_array_equal(x.cnt, z.cnt)
        np.testing.assert_array_equal(x.anomaly, z.anomaly)


@pytest.mark.parametrize("backend", BACKENDS)
def test_missing_observation_is_a_time_update_not_a_zero(backend):
    y = np.full((40, 1), 2.0)
    valid = np.ones((40, 1), bool)
    valid[20] = False
    bank = AkfBank(np.array([[0.01, 0.1]]), window=10, z_c=2.8, backend=backend)
    out = bank.process(y, valid)
    P_before = bank.state.P.copy()
    # at the missing step the estimate is the prediction and no outlier is counted
    np.testing.assert_array_equal(out.x_hat[20], out.x_prior[20])
    assert out.outlier[20].sum() == 0
    assert np.all(np.abs(out.x_hat[19:22] - 2.0) < 1e-9)     # a zero would have pulled it down
    zero = AkfBank(np.array([[0.01, 0.1]]), window=10, z_c=2.8, backend=backend)
    yz = y.copy()
    yz[20] = 0.0
    outz = zero.process(yz)
    assert np.all(np.abs(outz.x_hat[20] - 2.0) > 0.05)
    assert np.all(P_before > 0)


def test_bank_r_is_eq16():
    r = bank_r(4e-3, 0.13, 10)
    assert r[-1] == pytest.approx(0.13)
    assert r[0] == pytest.approx(4e-3 + (0.13 - 4e-3) / 10)
    np.testing.assert_allclose(np.diff(r), (0.13 - 4e-3) / 10)


def test_bad_shapes_say_expected_and_got():
    bank = AkfBank(np.array([[0.01, 0.1]] * 2), window=10, z_c=2.8)
    with pytest.raises(ValueError, match=r"expected shape \(T, 2\), got \(5, 3\)"):
        bank.process(np.zeros((5, 3)))


def test_the_compiled_kernel_is_built():
    """`pip install` builds the C kernel where a compiler exists (CI has one).

    Set CMSENSORD_NO_KERNEL_OK=1 to run the suite on a machine without a compiler.
    """
    import os

    if os.environ.get("CMSENSORD_NO_KERNEL_OK") == "1":
        pytest.skip("running without the compiled kernel by request")
    assert have_kernel(), "cmsensord.dsp._akfkernel is not built: pip install -e . with a C compiler"


@pytest.mark.skipif(not have_kernel(), reason="the compiled kernel is not built")
@pytest.mark.parametrize("window", [10, [5, 10, 7]])
@pytest.mark.parametrize("scaling", [True, False])
def test_numpy_loop_gives_the_bits_of_the_c_kernel(window, scaling):
    """The numpy loop's shortcuts (masks skipped once every channel started, at steps with
    every observation, once every ring is full) keep the arithmetic of the C kernel: the same
    bits, on input with a late-starting channel, scattered and whole-step gaps, in two calls."""
    rng = np.random.default_rng(3)
    y = rng.normal(1.0, 0.1, (1200, 3))
    y[rng.random(y.shape) < 0.2] = np.nan
    y[:50, 1] = np.nan
    y[100:130] = np.nan
    y[600:] = np.nan_to_num(y[600:], nan=1.0)          # then every observation
    R = np.stack([bank_r(4e-3, 0.13, 10)] * 3)
    banks = [AkfBank(R, window=window, z_c=2.8, scaling=scaling, backend=b) for b in ("numpy", "c")]
    for part in (y[:700], y[700:]):
        a, b = (bank.process(part) for bank in banks)
        for k in ("x_prior", "x_hat", "Y", "Q", "outlier"):
            assert np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True), k
