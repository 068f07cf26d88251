"""Model matrices and the steady-state gain design of the tracker.

F(n) of eq. (13), the process and measurement noise of eq. (25) with a
weighting factor per component, and the steady-state Riccati solution by a
doubling algorithm (the tracker's gain table, the bandwidth mapping).  See
docs/order_tracker.md (§1 Model, §3, §4 Gains).
"""

from __future__ import annotations

import numpy as np


def f_matrices(c: np.ndarray) -> np.ndarray:
    """F(n) of eq. (13) for coefficients c (..., K) = 2cos(ω ΔT): (..., 2K, 2K)."""
    K = c.shape[-1]
    d = 2 * K
    F = np.zeros(c.shape[:-1] + (d * d,))
    step = 2 * d + 2                      # from the block of pair i to that of pair i + 1
    F[..., 1::step] = 1.0                 # (2i, 2i+1): strided slices of the flat matrix,
    F[..., d::step] = -1.0                # (2i+1, 2i)   not fancy indexing
    F[..., d + 1::step] = c               # (2i+1, 2i+1)
    return F.reshape(c.shape[:-1] + (d, d))


def q_diag(rk: np.ndarray, q1: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample process-noise diagonal (..., 2K) and Q2 (...) from r_k (..., K).

    Q1 = q1 blockdiag((r̄/r_k)² I_2), Q2 = r̄² q1, r̄ = r_1 (eq. 25 generalised).
    """
    rbar = rk[..., :1]
    q1k = q1 * (rbar / rk) ** 2
    return np.repeat(q1k, 2, axis=-1), q1 * rbar[..., 0] ** 2


def riccati_doubling(c: np.ndarray, qdiag: np.ndarray, q2: np.ndarray, n_double: int) -> np.ndarray:
    """P(n|n-1) after 2^n_double constant-model steps from P = 0, batched: (G, 2K, 2K).

    Structure-preserving doubling for the filter Riccati equation
    P = F P Fᵀ - F P hᵀ (h P hᵀ + Q2)⁻¹ h P Fᵀ + Q1, written as the control form
    with A = Fᵀ, G = hᵀh/Q2, H = Q1::

        W = I + G_j H_j
        A_{j+1} = A_j W⁻¹ A_j
        G_{j+1} = G_j + A_j W⁻¹ G_j A_jᵀ
        H_{j+1} = H_j + A_jᵀ H_j W⁻¹ A_j

    H_j is P after 2^j prediction steps.  Each model of the batch stops on its
    own once converged (H changes by at most 1e-15 of its largest element), so
    its result does not depend on the others in the batch (a gain table or r
    grid filled piecewise equals one filled at once); the stopped ones leave
    the batch.  W⁻¹A and W⁻¹G come from one solve.
    """
    F = f_matrices(c)
    G, d = F.shape[0], F.shape[-1]
    h = np.zeros(d)
    h[1::2] = 1.0
    A = np.swapaxes(F, -1, -2).copy()
    Gm = np.outer(h, h)[None, :, :] / q2[:, None, None]
    H = np.zeros((G, d, d))
    H[:, np.arange(d), np.arange(d)] = qdiag
    out = np.empty((G, d, d))
    act = np.arange(G)
    eye = np.eye(d)
    for j in range(n_double):
        W = eye + Gm @ H
        X = np.linalg.solve(W, np.concatenate([A, Gm], axis=-1))
        WA, WG = X[..., :d], X[..., d:]
        At = np.swapaxes(A, -1, -2)
        Hn = H + At @ H @ WA
        Gm = Gm + A @ WG @ At
        A = A @ WA
        Hn = 0.5 * (Hn + np.swapaxes(Hn, -1, -2))
        Gm = 0.5 * (Gm + np.swapaxes(Gm, -1, -2))
        done = (np.max(np.abs(Hn - H), axis=(1, 2))
                <= 1e-15 * np.max(np.abs(Hn), axis=(1, 2)))
        H = Hn
        if j == n_double - 1 or done.all():
            out[act] = H
            break
        if done.any():
            out[act[done]] = H[done]
            keep = ~done
            act, A, Gm, H = act[keep], A[keep], Gm[keep], H[keep]
    return out
