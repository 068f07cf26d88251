"""The tracker's numpy forward recursion (recursions.forward_numpy, the fallback without a
compiled kernel) equals the plain per-sample Kalman filter and gives the same bits
however the stream is cut at its chunk boundaries."""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.dsp.order_tracker.design import f_matrices, q_diag, riccati_doubling
from cmsensord.dsp.order_tracker.recursions import CHUNK, forward_numpy


def steady_gains(c: np.ndarray, r: float = 30.0) -> np.ndarray:
    """The steady-state gains k (T, 2K) at coefficients c (T, K): a stable filter."""
    qd, q2 = q_diag(np.full(c.shape, r), 1.0)
    P = riccati_doubling(c, qd, q2, 30)
    ph = P[:, :, 1::2].sum(axis=2)
    return ph / (ph[:, 1::2].sum(axis=1) + q2)[:, None]


def plain_forward(y, c, k, z0):
    """X̂ (T+1, C, 2K), e (T, C), x̂ (T, C, 2K): e = y - h X̂, x̂ = X̂ + k e, X̂' = F x̂."""
    F = f_matrices(c)
    z = z0.copy()
    zp, e, xf = [], [], []
    for n in range(len(y)):
        zp.append(z)
        en = y[n] - z[:, 1::2].sum(axis=1)
        x = z + k[n][None, :] * en[:, None]
        e.append(en)
        xf.append(x)
        z = x @ F[n].T
    zp.append(z)
    return np.array(zp), np.array(e), np.array(xf)


@pytest.fixture(scope="module")
def case():
    rng = np.random.default_rng(3)
    T, K, C = 10 * CHUNK + 13, 3, 2
    theta = np.linspace(0.2, 0.5, T)[:, None] * np.array([1.0, 2.0, 2.1])[None, :]
    c = 2.0 * np.cos(theta)
    t = np.arange(T)[:, None]
    y = np.sin(theta * t).sum(axis=1)[:, None] + 0.3 * rng.standard_normal((T, C))
    return y, c, steady_gains(c), 0.1 * rng.standard_normal((C, 2 * K))


def test_forward_equals_the_plain_per_sample_filter(case):
    y, c, k, z0 = case
    got = forward_numpy(y, c, k, z0)
    want = plain_forward(y, c, k, z0)
    for g, w in zip(got, want):
        assert g.shape == w.shape
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-12 * np.abs(w).max())
    assert np.abs(want[2]).max() > 0.5                 # the comparison is not of zeros


@pytest.mark.parametrize("cuts", [(CHUNK,), (CHUNK - 1, 3 * CHUNK), (2 * CHUNK + 5, 2 * CHUNK + 6, 7 * CHUNK)])
def test_forward_cut_at_chunk_starts_gives_one_pass_bit_for_bit(case, cuts):
    """As the tracker calls it: each call starts at the chunk start before its first new
    sample, from the predicted state there (the chunk cut by the last call runs again)."""
    y, c, k, z0 = case
    zp1, e1, x1 = forward_numpy(y, c, k, z0)
    zp, e, xf = [], [], []
    start, z = 0, z0                                   # start: the chunk boundary of this call
    for a, b in zip((0, *cuts), (*cuts, len(y))):
        zpc, ec, xc = forward_numpy(y[start:b], c[start:b], k[start:b], z)
        zp.append(zpc[a - start:b - start])
        e.append(ec[a - start:])
        xf.append(xc[a - start:])
        nxt = b // CHUNK * CHUNK
        z = zpc[nxt - start]
        start = nxt
    np.testing.assert_array_equal(np.concatenate(zp), zp1[:-1])
    np.testing.assert_array_equal(np.concatenate(e), e1)
    np.testing.assert_array_equal(np.concatenate(xf), x1)
