"""The numpy AKF bank's steady runs (every channel started and observed, one window for all)
give the bits of the step-by-step loop, its plain reference, and of the C kernel."""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.dsp import akf
from cmsensord.dsp.akf import AkfBank, ScalarAKF, bank_r, have_kernel

FIELDS = ("x_prior", "x_hat", "Y", "Q", "outlier")
STATE = ("x", "P", "Q", "res2", "dx2", "pos", "fill", "started")


def gappy_stream(rng: np.random.Generator, T: int, C: int) -> tuple[np.ndarray, np.ndarray]:
    """Observations with runs of every length between gaps: single missing samples, whole-step
    gaps, a late channel, runs of 1, 2, ... samples and long ones, spikes (outliers)."""
    y = rng.normal(1.0, 0.1, (T, C)) + 2.0 * (rng.random((T, C)) < 0.05)
    valid = np.ones((T, C), dtype=bool)
    valid[:7, C - 1] = False                                  # a channel that starts late
    k = 20
    for run in (1, 2, 3, 5, 9, 10, 11, 30, 1, 1, 60):
        valid[k, rng.integers(C)] = False                     # one channel misses a sample
        k += 1 + run
        valid[k:k + 2] = False                                # every channel misses two
        k += 2 + run
    valid[k:k + 200][rng.random((min(200, T - k), C)) < 0.3] = False   # scattered gaps
    return y, valid


def step_by_step(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make the numpy bank run every step through the masked loop (no steady runs)."""
    def steps(bank, y, out, k0, k1):
        rings = akf._Rings(bank)
        valid = np.ones(y.shape, dtype=bool)
        for k in range(k0, k1):
            akf._step(bank, rings, y, valid, out, k, True, True)
    monkeypatch.setattr(akf, "_run_steady", steps)


def run(R, y, valid, window, scaling, cuts, backend="numpy"):
    bank = AkfBank(R, window=window, z_c=2.8, scaling=scaling, backend=backend)
    edges = [0, *cuts, len(y)]
    parts = [bank.process(y[a:b], valid[a:b]) for a, b in zip(edges[:-1], edges[1:])]
    return {f: np.concatenate([getattr(p, f) for p in parts]) for f in FIELDS}, bank.state


@pytest.mark.parametrize("window", [1, 3, 10, 50])
@pytest.mark.parametrize("scaling", [True, False])
def test_steady_runs_give_the_bits_of_the_step_loop(monkeypatch, window, scaling):
    rng = np.random.default_rng(window)
    y, valid = gappy_stream(rng, 900, 3)
    R = np.stack([bank_r(4e-3, 0.13, 10), bank_r(1e-3, 0.5, 10), bank_r(4e-3, 0.13, 10)])
    cuts = sorted(rng.choice(np.arange(1, 900), 6, replace=False).tolist()) + [899]
    fast, fast_state = run(R, y, valid, window, scaling, cuts)
    whole, _ = run(R, y, valid, window, scaling, [])
    with monkeypatch.context() as m:
        step_by_step(m)
        plain, plain_state = run(R, y, valid, window, scaling, cuts[:2])
    for f in FIELDS:
        assert np.array_equal(fast[f], plain[f], equal_nan=True), f
        assert np.array_equal(fast[f], whole[f], equal_nan=True), f
    for f in STATE:
        assert np.array_equal(getattr(fast_state, f), getattr(plain_state, f)), f
    assert fast["outlier"].sum() > 100                        # outliers were compared too
    assert np.isnan(fast["x_hat"][:7, 2]).all() and not np.isnan(fast["x_hat"][7:]).any()


@pytest.mark.skipif(not have_kernel(), reason="the compiled kernel is not built")
@pytest.mark.parametrize("window", [1, 10, 50])
def test_steady_runs_give_the_bits_of_the_c_kernel(window):
    rng = np.random.default_rng(11)
    y, valid = gappy_stream(rng, 900, 2)
    R = np.stack([bank_r(4e-3, 0.13, 10)] * 2)
    a, _ = run(R, y, valid, window, True, [100, 450], backend="numpy")
    b, _ = run(R, y, valid, window, True, [100, 450], backend="c")
    for f in FIELDS:
        assert np.array_equal(a[f], b[f], equal_nan=True), f


def test_steady_runs_equal_the_scalar_reference():
    """A uniform window (the steady runs' case) against ScalarAKF, the equations one to one."""
    rng = np.random.default_rng(5)
    y, valid = gappy_stream(rng, 700, 2)
    R = np.stack([bank_r(4e-3, 0.13, 6), bank_r(1e-3, 0.5, 6)])
    got, _ = run(R, y, valid, 10, True, [250])
    for c in range(2):
        for i in range(6):
            f = ScalarAKF(R[c, i], window=10, z_c=2.8)
            ref = [f.step(float(y[k, c]) if valid[k, c] else None) for k in range(len(y))]
            np.testing.assert_allclose(got["x_hat"][:, c, i], [r["x_hat"] for r in ref],
                                       rtol=0, atol=1e-12, equal_nan=True)
            np.testing.assert_allclose(got["Q"][:, c, i], [r["Q"] for r in ref],
                                       rtol=1e-12, atol=1e-15, equal_nan=True)
            assert np.array_equal(got["outlier"][:, c, i], [r["outlier"] for r in ref])
    assert got["outlier"].sum() > 30
