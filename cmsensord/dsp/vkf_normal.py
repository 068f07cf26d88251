"""The normal equations of the second-generation batch Vold-Kalman filter (Tůma, eqs. 12-15):
built in banded form, factorised (banded Cholesky), solved and refined.

:func:`cmsensord.dsp.vkf_batch.vkf2` owns the problem and its docstring the derivation; this
module owns the linear algebra: the block-banded normal matrix of the data equation (15) and
the structural equation (14) (:func:`_vkf2_normal_matrix`), its product with a vector from the
structure (:func:`_apply_normal`), the iterative refinement that keeps narrow 2-pole filters
accurate (:func:`_vkf2_refine`), and the ridge extension for records the paper's system
cannot be solved for in double precision (:func:`ridge_solve`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded

__all__ = ["solve", "ridge_solve"]

_REFINE_TOL = 1e-10      # stop refining when max|Δz| <= tol max|z|
_REFINE_MAX = 50         # ... or after this many steps, accepting the result when
_REFINE_ACCEPT = 1e-7    # the estimated error left is below this (relative)
_RIDGE_MAX = 1e-3        # largest ridge μ (a steady envelope's bias μ/(1/2 + μ) <= 0.2 %)


def solve(g: np.ndarray, rhs: np.ndarray, rk: np.ndarray, s: int, mu: float
                ) -> tuple[np.ndarray, int]:
    """The banded Cholesky solution z (N, 2K) of the normal equations (plus the ridge μ I
    when μ > 0), refined; and the refinement steps.  LinAlgError when it fails."""
    N, P = rhs.shape
    cb = cholesky_banded(_vkf2_normal_matrix(g, rk, s, mu), overwrite_ab=True, check_finite=False)
    z = cho_solve_banded((cb, False), rhs.reshape(-1), check_finite=False).reshape(N, P)
    return z, _vkf2_refine(z, cb, rhs, g, rk, s, mu)


def ridge_solve(g: np.ndarray, rhs: np.ndarray, rk: np.ndarray, s: int) -> tuple[float, np.ndarray, int]:
    """(μ, z, refinements) of the smallest ridge μ = 10^j ε λ_max (j = 0, 2, 4, ...) whose banded
    Cholesky factor exists; λ_max = K + 2^{2s} max r²/2 bounds the normal matrix's eigenvalues,
    so μ lifts the smallest ones above the rounding of the factorisation.  LinAlgError when μ
    would exceed _RIDGE_MAX against the data's weight of 1/2 per sample and unknown: the
    bandwidth is then too narrow for double precision at this sample rate."""
    P = rhs.shape[1]
    lam_max = P / 2 + 2.0 ** (2 * s) * float(np.max(rk)) ** 2 / 2.0
    mu = np.finfo(float).eps * lam_max
    while mu <= _RIDGE_MAX:
        try:
            return mu, *solve(g, rhs, rk, s, mu)
        except np.linalg.LinAlgError:
            mu *= 100.0
    raise np.linalg.LinAlgError(
        f"vkf2: r up to {float(np.max(rk)):.3g} is too large for double precision (the "
        f"bandwidth is too narrow for the sample rate): widen the bandwidth")


def _difference_gram_bands(n: int, s: int) -> list[np.ndarray]:
    """Bands lag = 0..s of DᵀD, D the (n-s) x n s-th difference of eq. (14).

    Row i of D has the coefficients d_j = (-1)^{s-j} binom(s, j) at columns
    i + j, j = 0..s ([-1, 1] for s = 1, [1, -2, 1] for s = 2).
    """
    d = np.array([1.0])
    for _ in range(s):
        d = np.convolve(d, [-1.0, 1.0])
    bands = []
    for lag in range(s + 1):
        b = np.zeros(n - lag)
        for j in range(s + 1 - lag):
            b[j:j + n - s] += d[j] * d[j + lag]   # entry (i+j, i+j+lag) of row i
        bands.append(b)
    return bands


def _vkf2_normal_matrix(g: np.ndarray, rk: np.ndarray, s: int, mu: float = 0.0) -> np.ndarray:
    """The normal matrix of :func:`vkf2` in upper banded storage, ab[u + i - j, j] = M[i, j].

    g (2K, N): the data equation's coefficients per sample; the unknowns are ordered
    sample by sample, (u_1, v_1, ..., u_K, v_K); half-bandwidth u = 2K s.  Fortran order so
    LAPACK (pbtrf) factorises it in place without a copy.
    """
    P, N = g.shape
    K = P // 2
    u = P * s                  # half-bandwidth of the normal matrix
    ab = np.zeros((u + 1, P * N), order="F")
    ab[u] = mu                 # the ridge μ I (0: the paper's normal matrix)
    for p in range(P):         # Σ_n g gᵀ, the 2K x 2K block of every sample
        for q in range(p, P):
            ab[u + p - q, q::P] += g[p] * g[q]
    # structural equation (14) on u_k and on v_k: (r_k²/2) DᵀD, unknowns P apart
    for lag, band in enumerate(_difference_gram_bands(N, s)):
        for k in range(K):
            w = 0.5 * rk[k] * rk[k]
            for m in (2 * k, 2 * k + 1):
                ab[u - P * lag, P * lag + m::P] += w * band
    return ab


def _vkf2_refine(z: np.ndarray, cb: np.ndarray, rhs: np.ndarray, g: np.ndarray, rk: np.ndarray,
                 s: int, mu: float = 0.0) -> int:
    """Iterative refinement of the solution z (N, 2K) of :func:`vkf2`, in place; returns the steps.

    The normal matrix has eigenvalues from ~1 (smooth envelopes, fixed by the data) to
    ~2^{2s} r²/2, so the Cholesky solution of the smooth part carries a relative error
    ~ r² ε (2 poles, 0.25 Hz at 2 kHz: r = 4e6, 0.8 % in RMS).  The residual is recomputed
    from the structure (g and the differences of eq. 14, exact for smooth envelopes) and
    corrected with the same factor ``cb`` until the correction is below _REFINE_TOL.  Raises
    LinAlgError when it does not converge.

    With the ridge ``mu`` > 0, ``cb`` factors M + μI and the residual is that of M + μI.
    """
    N, P = z.shape
    w = np.repeat(0.5 * rk * rk, 2)          # weight of u_k and v_k
    refinements, step = 0, math.inf
    zmax = max(float(np.abs(z).max()), np.finfo(float).tiny)
    while refinements < _REFINE_MAX:
        refinements += 1
        res = rhs - _apply_normal(z, g, w, s) - mu * z
        dz = cho_solve_banded((cb, False), res.reshape(-1), check_finite=False)
        z += dz.reshape(N, P)
        prev, step = step, float(np.abs(dz).max()) / zmax
        if step <= _REFINE_TOL:
            break
    else:  # no break: _REFINE_MAX steps
        # slow but converging (rate < 1): the error left is about step·rate/(1-rate)
        rate = step / prev
        if not (rate < 1.0 and step * rate / (1.0 - rate) <= _REFINE_ACCEPT):
            raise np.linalg.LinAlgError(
                f"vkf2: iterative refinement did not converge (last correction "
                f"{step:.1e} relative, ratio {rate:.2f}); r = {rk.tolist()} is too large "
                "for double precision: widen the bandwidth")
    return refinements


def _apply_normal(z: np.ndarray, g: np.ndarray, w: np.ndarray, s: int) -> np.ndarray:
    """M z for the vkf2 normal matrix, from its structure: z (N, 2K), g (2K, N).

    M z = g(n) (g(n)ᵀ z(n)) + w Dᵀ D z, D the s-th difference along n, whose
    adjoint is (-1)^s times the s-th difference of the zero-padded sequence.
    """
    h = np.einsum("pn,np->n", g, z)                      # data equation, g(n)ᵀ z(n)
    out = (g * h).T
    dz = np.diff(z, n=s, axis=0) * w                     # structural equation (14)
    out += (-1.0) ** s * np.diff(np.pad(dz, ((s, s), (0, 0))), n=s, axis=0)
    return out
