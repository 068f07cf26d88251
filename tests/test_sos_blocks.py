"""The numpy anti-alias cascade (cmsensord/dsp/order_tracker/sos_blocks.py) is scipy.signal's
sosfilt to rounding, however the input is cut into calls: the plain reference is scipy's
sample-by-sample recursion."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from cmsensord.dsp.order_tracker.antialias import cheb2ord, cheby2_sos
from cmsensord.dsp.order_tracker.sos_blocks import BLOCK, MAX_BLOCKS, SosBlocks


def antialias(fs: float = 25000.0, f_hi: float = 240.0, D: int = 20) -> np.ndarray:
    order, fc = cheb2ord(f_hi, fs / D - f_hi, 0.001, 80.0, fs)
    return cheby2_sos(order, 80.0, fc, fs)


@pytest.mark.parametrize("C", [1, 3])
def test_blocks_equal_scipy_sosfilt_with_a_carried_state(C):
    sos = antialias()
    rng = np.random.default_rng(C)
    x = rng.standard_normal((BLOCK * MAX_BLOCKS * 2 + 37, C)) * 3.0
    zi = rng.standard_normal((sos.shape[0], 2, C)) * 0.1
    want, zf = signal.sosfilt(sos, x, axis=0, zi=zi)
    got, zg = SosBlocks(sos)(x, zi)
    scale = np.abs(want).max()
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(zg, zf, rtol=0, atol=1e-13 * scale)


@pytest.mark.parametrize("cuts", [(1,), (63, 64, 65), (5, 700, 4200, 4201), tuple(range(0, 9000, 997))])
def test_any_cut_into_calls_gives_one_pass(cuts):
    sos = antialias()
    x = np.random.default_rng(7).standard_normal((9000, 2))
    want, zf = signal.sosfilt(sos, x, axis=0, zi=np.zeros((sos.shape[0], 2, 2)))
    f = SosBlocks(sos)
    z = np.zeros((sos.shape[0], 2, 2))
    parts = []
    for a, b in zip((0, *cuts), (*cuts, len(x))):
        y, z = f(x[a:b], z)
        parts.append(y)
    np.testing.assert_allclose(np.concatenate(parts), want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(z, zf, rtol=0, atol=1e-14)
    assert parts[0].shape == (cuts[0], 2)
