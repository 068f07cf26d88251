"""The knots of the tacho's smoothed speed in the compiled kernel (``_trackerkernel.knot_fit``:
the weighted quadratic over the 2h + 1 committed edges around each centre, with numpy's order
of summation, windows clipped at a run's start and end) equal the numpy path's, bit for bit: on
random edge streams with missed, spurious and duplicated pulses and stops, fed in random splits,
at half windows whose 2h + 1 edges are below, at and above the 8 accumulators of numpy's
pairwise sum and above its 128-entry blocks; the final and the provisional knots, and the
speed, angle and validity read from them (``evaluate``)."""

from __future__ import annotations

import random

import numpy as np
import pytest

from cmsensord.dsp.order_tracker import have_kernel
from cmsensord.dsp.tacho import TachoTracker, smoothing
from test_tacho_batch import L, random_edges

pytestmark = pytest.mark.skipif(not have_kernel() or smoothing._knot_fit is None,
                                reason="the compiled tracker kernel is not built")


def _tracker(kernel: bool, ppr: int, h: int | None) -> TachoTracker:
    tr = TachoTracker(25000, ppr=ppr, block_len=L, half_window=h)
    tr.smooth_kernel = kernel
    return tr


def _knots(tr: TachoTracker) -> np.ndarray:
    return tr._kbuf[:, tr._klo:tr._khi].copy()


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize(("ppr", "h"), [(1, None), (1, 1), (1, 3), (1, 4), (1, 7), (2, None), (4, 70)])
def test_the_kernels_knots_equal_the_numpy_path(seed, ppr, h):
    rnd = random.Random(100 * seed + 10 * ppr + (h or 0))
    t0, edges = random_edges(rnd, 30.0)
    cuts = sorted(rnd.sample(range(1, len(t0)), rnd.choice([5, 60, 300])))
    c_tr, np_tr = _tracker(True, ppr, h), _tracker(False, ppr, h)
    calls = []
    fit = smoothing._knot_fit
    smoothing._knot_fit = lambda *a: calls.append(1) or fit(*a)
    try:
        for a, b in zip([0, *cuts], [*cuts, len(t0)]):
            counts = [len(e) for e in edges[a:b]]
            off = np.concatenate(edges[a:b]) if b > a else np.empty(0, dtype=np.uint32)
            assert c_tr.feed_flat(t0[a:b], counts, off) == np_tr.feed_flat(t0[a:b], counts, off)
            assert c_tr.final_until == np_tr.final_until
            assert np.array_equal(_knots(c_tr), _knots(np_tr), equal_nan=True)        # bit for bit
            prov = c_tr._provisional(), np_tr._provisional()
            assert (prov[0] is None) == (prov[1] is None)
            if prov[0] is not None and prov[1] is not None:
                assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(*prov))
            end = c_tr.covered_until
            s = np.arange(max(0, end - rnd.randrange(1, 200000)), end + 30000, 7)
            got, want = c_tr.evaluate(s), np_tr.evaluate(s)
            assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(got, want))
    finally:
        smoothing._knot_fit = fit
    assert c_tr._khi - c_tr._klo > 20 and len(calls) > 5


def test_the_kernel_checks_its_arguments():
    fit = smoothing._knot_fit
    T, n = [0.0, 10.0, 20.0, 30.0], [0, 1, 2, 3]
    w = np.ones(3)
    out = np.empty((3, 2))
    fit(T, n, 0, 1, 4, w, 0.0, 1.0, out)
    assert np.array_equal(out[0], [10.0, 20.0]) and np.allclose(out[2], 0.1)
    with pytest.raises(ValueError, match="expected"):
        fit(T, n[:3], 0, 1, 4, w, 0.0, 1.0, out)             # lists of two lengths
    with pytest.raises(ValueError, match="expected"):
        fit(T, n, 0, 3, 4, w, 0.0, 1.0, out)                 # centres beyond the edges
    with pytest.raises(ValueError, match="before the kept edges"):
        fit(T[2:], n[2:], 2, 2, 4, w, 0.0, 1.0, out)         # a window before index c0
