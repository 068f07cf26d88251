"""The AKF bank's flags-only path (`AkfBank.outliers`, the kernel's `flags`) and the kernel's
filters in pairs: the same flags, state and bits as the plain path (`process`, the numpy loop)."""

import numpy as np
import pytest

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
