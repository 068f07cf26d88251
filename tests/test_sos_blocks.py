"""The numpy anti-alias cascade (cmsensord/dsp/order_tracker/sos_blocks.py) is scipy.signal's
sosfilt (the plain sample-by-sample recursion) to rounding, and bit for bit the same however
the input is cut into calls."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from cmsensord.dsp.order_tracker.antialias import cheb2ord, cheby2_sos
from cmsensord.dsp.order_tracker.sos_blocks import BLOCK, SosBlocks

#: how close the block form comes to the per-sample recursion, in units of the output's largest
#: magnitude: the block products sum in another order than the recursion (and in the order the
#: CPU's BLAS kernel picks: 1e-14 held on one machine, 1.6e-14 was measured on an AMD EPYC), so
#: a few hundred ulps of the scale; a wrong coefficient or a lost state is off by orders more
ROUNDING = 256 * np.finfo(float).eps


def antialias(fs: float = 25000.0, f_hi: float = 240.0, D: int = 20) -> np.ndarray:
    order, fc = cheb2ord(f_hi, fs / D - f_hi, 0.001, 80.0, fs)
    return cheby2_sos(order, 80.0, fc, fs)


@pytest.mark.parametrize("C", [1, 3])
def test_blocks_equal_scipy_sosfilt_with_a_carried_state(C):
    sos = antialias()
    rng = np.random.default_rng(C)
    x = rng.standard_normal((BLOCK * 150, C)) * 3.0
    zi = rng.standard_normal((sos.shape[0], 2, C)) * 0.1
    want, zf = signal.sosfilt(sos, x, axis=0, zi=zi)
    got, zg, part = SosBlocks(sos)(x, zi)
    scale = np.abs(want).max()
    assert part.shape == (0, C)
    np.testing.assert_allclose(got, want, rtol=0, atol=ROUNDING * scale)
    np.testing.assert_allclose(zg, zf, rtol=0, atol=ROUNDING * scale)
    got2, _, part = SosBlocks(sos)(x[:1000], zi)        # a partial block at the end
    np.testing.assert_allclose(got2, want[:1000], rtol=0, atol=ROUNDING * scale)
    assert len(part) == 1000 % BLOCK


@pytest.mark.parametrize("cuts", [(1,), (63, 64, 65), (5, 700, 4200, 4201), tuple(range(0, 9000, 997))])
def test_any_cut_into_calls_gives_one_pass_bit_for_bit(cuts):
    sos = antialias()
    x = np.random.default_rng(7).standard_normal((9000, 2))
    zi = np.zeros((sos.shape[0], 2, 2))
    f = SosBlocks(sos)
    want, zf, part_f = f(x, zi)
    z, part, parts = zi, None, []
    for a, b in zip((0, *cuts), (*cuts, len(x))):
        y, z, part = f(x[a:b], z, part)
        parts.append(y)
    assert parts[0].shape == (cuts[0], 2)
    np.testing.assert_array_equal(np.concatenate(parts), want)
    np.testing.assert_array_equal(z, zf)
    np.testing.assert_array_equal(part, part_f)


def plain_df2t(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """The cascade sample by sample, in direct form II transposed (the kernel's recursion)."""
    z = zi.copy()
    y = np.empty_like(x)
    for n in range(len(x)):
        v = x[n].copy()
        for s, (b0, b1, b2, _, a1, a2) in enumerate(sos):
            out = b0 * v + z[s, 0]
            z[s, 0] = b1 * v - a1 * out + z[s, 1]
            z[s, 1] = b2 * v - a2 * out
            v = out
        y[n] = v
    return y


@pytest.mark.parametrize("D", [3, 20])
def test_decimated_blocks_equal_the_plain_recursion_and_any_cut(D):
    """With D > 1 only every D-th output (from the stream's first sample) is formed: those of
    the plain per-sample recursion to rounding, and the same bits however the input is cut."""
    sos = antialias(D=D)
    x = np.random.default_rng(D).standard_normal((3000, 2)) * 2.0
    zi = np.zeros((sos.shape[0], 2, 2))
    want = plain_df2t(sos, x, zi)[::D]
    f = SosBlocks(sos, D)
    assert f.M % D == 0
    got, zf, part = f(x, zi)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * np.abs(want).max())
    z, part, parts = zi, None, []
    for a, b in zip((0, 1, 7, f.M - 1, f.M, 2 * f.M + 5), (1, 7, f.M - 1, f.M, 2 * f.M + 5, len(x))):
        y, z, part = f(x[a:b], z, part)
        parts.append(y)
    np.testing.assert_array_equal(np.concatenate(parts), got)
    np.testing.assert_array_equal(z, zf)
