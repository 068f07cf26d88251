"""The tacho's closed-form weighted quadratic fit (cmsensord/dsp/tacho/smoothing.py: cheap
enough for a 100-ms live call) against numpy.linalg.solve of the normal equations, on random
windows like those of the smoothing and the causal speed; and its Python float path (few rows,
one live call) against its numpy path (many rows, replay), bit for bit, so that any split of
the frames still gives the same knots and segments."""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.dsp.tacho import smoothing
from cmsensord.dsp.tacho.smoothing import solve_normal_rows, weighted_quadratic

_HANKEL = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4]])


def solve_reference(x: np.ndarray, y: np.ndarray, wgt: np.ndarray, npts: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The reference weighted quadratic: normal equations by numpy.linalg.solve; and the moments."""
    x2 = x * x
    wx, wx2 = wgt * x, wgt * x2
    mom = np.stack([wgt, wx, wx2, wx2 * x, wx2 * x2, wgt * y, wx * y, wx2 * y], axis=1).sum(axis=2)
    A = mom[:, _HANKEL]
    b = mom[:, 5:].copy()
    lin = npts < 3
    A[lin, 2, :] = 0.0
    A[lin, :, 2] = 0.0
    A[lin, 2, 2] = 1.0
    b[lin, 2] = 0.0
    one = npts < 2
    A[one] = np.eye(3)
    b[one] = 0.0
    return np.linalg.solve(A, b[..., None])[..., 0], mom


def random_windows(rng: np.random.Generator, rows: int, width: int, centred: bool
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Edge windows as _fit (centred) or _flush_segments (one-sided) build them: x scaled to
    [-1, 1], pulse counts with jitter, tricube-like weights, 1 .. width points."""
    npts = rng.integers(1, width + 1, rows)
    use = np.arange(width)[None, :] < npts[:, None]
    t = np.cumsum(rng.uniform(0.3, 3.0, (rows, width)), axis=1)
    ref = np.take_along_axis(t, (npts[:, None] // 2) if centred else np.zeros((rows, 1), int), axis=1)
    dx = np.where(use, t - ref, 0.0)
    S = np.abs(dx).max(axis=1)
    S = np.where(S > 0, S, 1.0)
    x = dx / S[:, None]
    n = np.arange(width)[None, :] - (npts[:, None] // 2 if centred else 0)
    y = np.where(use, n + rng.normal(0, 0.05, (rows, width)), 0.0)
    wgt = use * rng.uniform(0.02, 1.0, width)[None, :]
    return x, y, wgt, npts


@pytest.mark.parametrize("width,centred", [(3, True), (9, True), (17, True), (16, False), (64, False)])
def test_closed_form_equals_numpy_solve(width: int, centred: bool) -> None:
    rng = np.random.default_rng(width)
    for _ in range(100):
        x, y, wgt, npts = random_windows(rng, int(rng.integers(1, 40)), width, centred)
        want, _ = solve_reference(x, y, wgt, npts)
        got = weighted_quadratic(x, y, wgt, npts)
        scale = np.abs(want).max(axis=1, keepdims=True)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-11 * scale.max())
        assert np.all(got[npts < 3, 2] == 0.0)                  # two points: a straight line
        assert np.all(got[npts < 2] == 0.0)                     # one point: no speed


def test_python_float_path_equals_numpy_path_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    rows = 3 * smoothing._SCALAR_ROWS
    for width, centred in ((9, True), (16, False)):
        for _ in range(50):
            x, y, wgt, npts = random_windows(rng, rows, width, centred)
            _, mom = solve_reference(x, y, wgt, npts)
            whole = weighted_quadratic(x, y, wgt, npts)            # numpy path
            assert np.array_equal(whole, solve_normal_rows(mom, npts))
            for a in range(0, rows, smoothing._SCALAR_ROWS):       # Python float path, by rows
                b = a + smoothing._SCALAR_ROWS
                part = weighted_quadratic(x[a:b], y[a:b], wgt[a:b], npts[a:b])
                assert np.array_equal(part, whole[a:b])
