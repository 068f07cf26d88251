"""The AKF bank's flags-only path (`AkfBank.outliers`, the kernel's `flags`) and the kernel's
filters in pairs: the same flags, state and bits as the plain path (`process`, the numpy loop)."""

import numpy as np
import pytest

from cmsensord.dsp import akf
from cmsensord.dsp.akf import AkfBank, bank_r, have_kernel

BACKENDS = ["numpy"] + (["c"] if have_kernel() else [])


def _gappy(T: int, C: int, seed: int) -> np.ndarray:
    """Observations with a late-starting channel, scattered and whole-step gaps, outliers."""
    rng = np.random.default_rng(seed)
    y = rng.normal(1.0, 0.1, (T, C))
    y[rng.random(y.shape) < 0.01] *= 4.0              # outliers to flag
    y[rng.random(y.shape) < 0.15] = np.nan
    y[:40, 1 % C] = np.nan
    y[90:120] = np.nan
    y[T // 2:] = np.nan_to_num(y[T // 2:], nan=1.0)
    return y


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("n", [1, 3, 10])
@pytest.mark.parametrize("window", [10, [5, 10, 7]])
@pytest.mark.parametrize("scaling", [True, False])
def test_outliers_give_the_flags_and_state_of_process(backend, n, window, scaling):
    """outliers() flags what process() flags, and leaves the bank in the same state, call
    after call (odd n: the kernel's last filter outside its pairs)."""
    y = _gappy(900, 3, seed=n)
    R = np.stack([bank_r(4e-3, 0.13, n)] * 3)
    plain, flags = (AkfBank(R, window=window, z_c=2.8, scaling=scaling, backend=backend) for _ in "ab")
    hits = 0
    for part in (y[:1], y[1:300], y[300:301], y[301:]):
        ref = plain.process(part)
        outlier, valid = flags.outliers(part)
        assert outlier.dtype == np.uint8 and outlier.shape == ref.outlier.shape
        assert np.array_equal(outlier, ref.outlier)
        assert np.array_equal(valid, ref.valid)
        hits += int(outlier.sum())
        for k, v in plain.state.__dict__.items():
            assert np.array_equal(v, getattr(flags.state, k)), k
    assert hits > 0                                   # the test sees flags, not only zeros


@pytest.mark.skipif(not have_kernel(), reason="the compiled kernel is not built")
@pytest.mark.parametrize("n", [1, 2, 3, 5, 10])
def test_the_kernel_gives_the_bits_of_the_numpy_loop_for_any_number_of_filters(n):
    """The kernel runs a channel's filters two at a time (and an odd one alone): every output
    has the numpy loop's bits, whatever n."""
    y = _gappy(700, 2, seed=10 + n)
    R = np.stack([bank_r(4e-3, 0.13, n), bank_r(1e-3, 0.2, n)])
    banks = [AkfBank(R, window=[10, 6], z_c=[2.8, 2.2], backend=b) for b in ("numpy", "c")]
    for part in (y[:350], y[350:]):
        a, b = (bank.process(part) for bank in banks)
        for k in ("x_prior", "x_hat", "Y", "Q", "outlier"):
            assert np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True), k
        assert int(a.outlier.sum()) > 0


def test_outliers_of_no_observations():
    bank = AkfBank(np.stack([bank_r(4e-3, 0.13, 4)] * 2), window=10, z_c=2.8)
    outlier, valid = bank.outliers(np.empty((0, 2)))
    assert outlier.shape == (0, 2, 4) and valid.shape == (0, 2)
    with pytest.raises(ValueError, match=r"expected shape \(T, 2\)"):
        bank.outliers(np.zeros((5, 3)))


@pytest.mark.skipif(not have_kernel(), reason="the compiled kernel is not built")
@pytest.mark.parametrize("z_c", [2.8, 1.0, 3.0000000000000004, 1e-90, 1e90])
def test_the_outlier_test_at_its_threshold_flags_as_the_division_does(z_c):
    """The kernel decides |z| > z_c from the squares where they are clearly apart and by the
    division otherwise: observations whose z lies within a few ulps of z_c, and far from it,
    on tiny and huge scales, are flagged as the numpy loop's division flags them."""
    rng = np.random.default_rng(7)
    n, C = 4, 2
    R = np.stack([bank_r(4e-3, 0.13, n)] * C)
    template = AkfBank(R, window=3, z_c=z_c, backend="numpy")
    template.process(rng.normal(1.0, 0.1, (5, C)))             # started, rings in use
    s = template.state
    flagged = cases = 0
    for scale in (1e-120, 1e-3, 1.0, 1e100):
        for _ in range(60):
            x0 = float(rng.choice([0.0, rng.normal(1.0, 0.2)])) * scale   # 0: y - x0 is the innovation exactly
            P, Q = float(rng.uniform(0.01, 1)) * scale ** 2, float(rng.uniform(0.001, 0.1)) * scale ** 2
            Rs = R * scale ** 2
            Yv = P + Q + Rs[0, 0]                              # filter 1's Y, as the kernel forms it
            for k in rng.integers(-40, 40, 6).tolist() + [0, 1, -1]:
                innov = z_c * np.sqrt(Yv) * (1.0 + k * 2.0 ** -52) * rng.choice([-1.0, 1.0])
                y = np.full((1, C), x0 + innov)
                out = []
                for backend in ("numpy", "c"):
                    bank = AkfBank(Rs, window=3, z_c=z_c, backend=backend)
                    bank.state = s.copy()
                    bank.state.x[:] = x0
                    bank.state.P[:] = P
                    bank.state.Q[:] = Q
                    bank.state.res2 *= scale ** 2
                    bank.state.dx2 *= scale ** 2
                    with np.errstate(over="ignore", invalid="ignore"):     # squares past 1e308: inf
                        out.append(bank.outliers(y)[0])
                assert np.array_equal(out[0], out[1]), (scale, k)
                flagged += int(out[0][0, 0, 0])
                cases += 1
    assert 0 < flagged < cases                                 # both sides of the threshold seen


@pytest.mark.skipif(not have_kernel(), reason="the compiled kernel is not built")
def test_a_kernel_built_before_the_flags_entry_serves_outliers_through_process(monkeypatch):
    """An installed kernel without ``flags`` (built from older sources): outliers() takes
    process()'s flags, the same."""
    y = _gappy(400, 3, seed=3)
    R = np.stack([bank_r(4e-3, 0.13, 10)] * 3)
    want = AkfBank(R, window=10, z_c=2.8).outliers(y)[0]
    monkeypatch.setattr(akf, "_flags", None)
    got = AkfBank(R, window=10, z_c=2.8).outliers(y)[0]
    assert np.array_equal(got, want) and want.sum() > 0
