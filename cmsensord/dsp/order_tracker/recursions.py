"""The tracker's recursions in numpy, without a numpy call per sample.

The linear time-varying recursions of the forward filter (chunk starts from the
chunk maps, :func:`_chunk_starts`, then the chunks run side by side) and of the
fixed-lag smoother (modified Bryson-Frazier form, a two-level chunked scan,
:func:`_scan`); the exact Riccati gains loop over samples (for tests).  Also
the envelope of the tracked components.  The compiled kernel
(``cmsensord.dsp._trackerkernel``) runs the same loops in C.  See
docs/order_tracker.md (§4 Smoother, §5, §7).
"""

from __future__ import annotations

import math

import numpy as np

from cmsensord.dsp.order_tracker.design import f_matrices


def _scan(A: np.ndarray, b: np.ndarray, u0: np.ndarray, m: int | None = None) -> np.ndarray:
    """u(t+1) = A[t] u(t) + b[t] for t = 0..T-1, without a numpy call per step.

    A: (..., T, d, d), b: (..., T, d, C), u0: (..., d, C) -> u(0..T): (..., T+1, d, C).
    Two levels: the T steps are cut into J chunks of m ≈ sqrt(T); all chunks run
    their m steps at once from a zero state, also accumulating their transition
    matrix Φ (M = [Φ | z]); then the J chunk starts s_j are joined in sequence,
    and every state is u = Φ(j, i) s_j + z(j, i) in one batched product.
    (A pairwise composition of the chunk maps, or re-running the chunks from
    their starts, measured slower here.)  ``m`` fixes the chunk length (the
    forward filter uses chunks aligned to absolute sample indices, see
    :meth:`OrderTracker._filter`); by default m = ceil(sqrt(T)).
    """
    T, d = A.shape[-3], A.shape[-1]
    C = b.shape[-1]
    batch = A.shape[:-3]
    if m is None:
        m = max(1, math.ceil(math.sqrt(T)))
    J = -(-T // m)
    pad = J * m - T
    if pad:
        eye = np.broadcast_to(np.eye(d), batch + (pad, d, d))
        A = np.concatenate([A, eye], axis=-3)
        b = np.concatenate([b, np.zeros(batch + (pad, d, C))], axis=-3)
    A = A.reshape(batch + (J, m, d, d))
    b = b.reshape(batch + (J, m, d, C))
    M = np.zeros(batch + (J, d, d + C))
    M[..., :, :d] = np.eye(d)
    store = np.empty(batch + (J, m, d, d + C))
    for i in range(m):
        store[..., i, :, :] = M
        M = A[..., i, :, :] @ M
        M[..., d:] += b[..., i, :, :]
    s = np.empty(batch + (J + 1, d, C))
    s[..., 0, :, :] = u0
    for j in range(J):
        s[..., j + 1, :, :] = M[..., j, :, :d] @ s[..., j, :, :] + M[..., j, :, d:]
    u = store[..., :d] @ s[..., :J, None, :, :] + store[..., d:]
    u = u.reshape(batch + (J * m, d, C))[..., :T, :, :]
    return np.concatenate([u, s[..., J:, :, :]], axis=-3)


def _fk(c: np.ndarray, k: np.ndarray) -> np.ndarray:
    """F(n) k(n) for c (T, K), k (T, 2K), using the block structure of F."""
    out = np.empty_like(k)
    out[:, 0::2] = k[:, 1::2]
    out[:, 1::2] = -k[:, 0::2] + c * k[:, 1::2]
    return out


def _a_matrices(c: np.ndarray, k: np.ndarray, fk: np.ndarray | None = None) -> np.ndarray:
    """A(n) = F(n)(I - k(n) h) = F(n) - (F(n) k(n)) h: (T, 2K, 2K) (``fk``: F(n) k(n) if
    the caller has it)."""
    F = f_matrices(c)
    F[:, :, 1::2] -= (_fk(c, k) if fk is None else fk)[:, :, None]
    return F


CHUNK = 32       # chunk length of the forward scan (numpy path)


def _chunk_starts(A: np.ndarray, b: np.ndarray, u0: np.ndarray, m: int) -> np.ndarray:
    """The states at t = 0, m, 2m, .. <= T of u(t+1) = A(t) u(t) + b(t): A (T, d, d),
    b (T, d, C), u0 (d, C) -> (T // m + 1, d, C).

    The maps [Φ | z] of the whole chunks of m steps come from m batched products (all
    chunks at once, from Φ = I, z = 0); then the starts are joined in sequence,
    s(j+1) = Φ(j) s(j) + z(j).  Each chunk's map is a product of the same shape per
    chunk, so it is the same bits whatever else is computed beside it."""
    T, d = A.shape[0], A.shape[1]
    C = b.shape[-1]
    J = T // m
    s = np.empty((J + 1, d, C))
    s[0] = u0
    if J == 0:
        return s
    Ab = A[:J * m].reshape(J, m, d, d)
    bb = b[:J * m].reshape(J, m, d, C)
    M = np.concatenate([Ab[:, 0], bb[:, 0]], axis=-1)         # after the first step
    for t in range(1, m):
        M = Ab[:, t] @ M
        M[..., d:] += bb[:, t]
    rows = list(s)                                            # views, made once
    for Phi, z, cur, nxt in zip(M[:, :, :d], M[:, :, d:], rows, rows[1:]):
        np.add(Phi @ cur, z, out=nxt)
    return s


def forward_numpy(y, c, k, z0):
    """Filter a block that starts at a chunk boundary: y (T, C), c (T, K), k (T, 2K),
    z0 (C, 2K) the predicted state at its start.

    Returns predicted states (T+1, C, 2K) (the last one after the block),
    innovations (T, C), filtered states (T, C, 2K).

    Chunks of CHUNK samples: their start states from the chunk maps
    (:func:`_chunk_starts`), then every chunk runs its samples at once from its start,
    e = y - h X̂, x̂ = X̂ + k e, X̂' = F x̂ (F pair by pair: x1' = x2, x2' = c x2 - x1),
    a few elementwise operations per sample step for all chunks together.
    """
    T, K = c.shape
    C = y.shape[1]
    d = 2 * K
    m = CHUNK
    fk = _fk(c, k)
    w = T // m * m                                            # the whole chunks' maps
    s = _chunk_starts(_a_matrices(c[:w], k[:w], fk[:w]), fk[:w, :, None] * y[:w, None, :], z0.T, m)
    J = -(-T // m)
    pad = J * m - T
    if pad:
        y = np.concatenate([y, np.zeros((pad, C))])
        c = np.concatenate([c, np.zeros((pad, K))])
        k = np.concatenate([k, np.zeros((pad, d))])
    yb = y.reshape(J, m, C)
    cb = c.reshape(J, m, 1, K)
    kb = k.reshape(J, m, 1, d)
    zp = np.empty((J, m, C, d))
    e = np.empty((J, m, C))
    xf = np.empty((J, m, C, d))
    u = np.ascontiguousarray(np.swapaxes(s[:J], 1, 2))           # (J, C, d)
    for t in range(m):
        zp[:, t] = u
        et = yb[:, t] - u[..., 1::2].sum(axis=-1)
        e[:, t] = et
        v = u + kb[:, t] * et[..., None]
        xf[:, t] = v
        u = np.empty_like(v)
        u[..., 0::2] = v[..., 1::2]
        u[..., 1::2] = cb[:, t] * v[..., 1::2] - v[..., 0::2]
    zp = zp.reshape(J * m, C, d)
    # the state after the block: at a chunk boundary the joined start of the next chunk
    # (what a longer call would start that chunk from), else the last step's
    end = np.swapaxes(s[J:], 1, 2) if not pad else zp[T:T + 1]
    return (np.concatenate([zp[:T], end]), e.reshape(J * m, C)[:T],
            xf.reshape(J * m, C, d)[:T])


def backward_numpy(c, k, S, P, zp, e, starts, W, nout):
    """MBF fixed-lag smoothing of E windows [s, s+W) (all inside the given arrays).

    Returns smoothed states of the first ``nout`` samples of each window: (E, nout, C, 2K).
    """
    E = len(starts)
    idx = np.asarray(starts)[:, None] + np.arange(W)[None, :]           # (E, W)
    ridx = idx[:, ::-1]                                                 # backwards in time
    A = _a_matrices(c, k)                                               # (T, 2K, 2K)
    At = np.swapaxes(A, 1, 2)[ridx]                                     # (E, W, 2K, 2K)
    d = A.shape[1]
    C = e.shape[1]
    g = np.zeros((e.shape[0], d, C))
    g[:, 1::2, :] = (e / S[:, None])[:, None, :]
    # λ(n) = Aᵀ(n) λ(n+1) + g(n): step t maps λ(end-t) to λ(end-t-1); the first
    # step multiplies λ(end) = 0, so its matrix is irrelevant
    u = _scan(At, g[ridx], np.zeros((E, d, C)))                         # (E, W+1, d, C)
    lam = u[:, ::-1][:, :nout]                                          # λ(s..s+nout-1)
    oidx = idx[:, :nout]
    xs = zp[oidx] + np.swapaxes(P[oidx] @ lam, -1, -2)                  # (E, nout, C, d)
    return xs


def mask_groups(miss: np.ndarray | None) -> list:
    """Channels that miss the same samples, with that mask: [(channels, mask (T,) or
    None)], channels a slice (all of them, one group) or an index array.

    The numpy recursions share A(n) = F(n)(I - k(n)h) across channels; channels
    that miss different samples need different A (k zeroed where each misses).
    The caller runs the recursion once per group, on ALL channels (keeping the
    group's): the products then have the same shape whatever the grouping, so a
    channel's result depends only on its own mask, bit for bit (a stream split
    elsewhere groups differently; BLAS rounds a product differently when its
    column count changes)."""
    if miss is None or not miss.any():
        return [(slice(None), None)]
    cols: dict[bytes, list[int]] = {}
    for ch in range(miss.shape[1]):
        cols.setdefault(np.ascontiguousarray(miss[:, ch]).tobytes(), []).append(ch)
    if len(cols) == 1:
        return [(slice(None), miss[:, 0])]
    out = []
    for chans in cols.values():
        m = miss[:, chans[0]]
        out.append((np.array(chans), m if m.any() else None))
    return out


def riccati_numpy(c, qdiag, q2, P, want_p, miss=None):
    """Exact gains per sample (a loop: one set of numpy calls per sample).  At samples
    ``miss`` (T,) (None: none) there is no measurement: k = 0, P(n|n) = P(n|n-1)."""
    T, K = c.shape
    d = 2 * K
    k = np.empty((T, d))
    S = np.empty(T)
    Pout = np.empty((T, d, d)) if want_p else None
    F = f_matrices(c)
    hi = np.arange(1, d, 2)
    for n in range(T):
        ph = P[:, hi].sum(axis=1)
        s = ph[hi].sum() + q2[n]
        if want_p:
            Pout[n] = P
        S[n] = s
        if miss is not None and miss[n]:
            k[n] = 0.0
            Pf = P
        else:
            kn = ph / s
            k[n] = kn
            Pf = P - np.outer(kn, ph)
        P = F[n] @ Pf @ F[n].T
        P[np.arange(d), np.arange(d)] += qdiag[n]
        P = 0.5 * (P + P.T)
    return k, S, Pout, P


def envelope(xs: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Peak amplitude from the state pairs: xs (N, C, 2K), c (N, K) -> (N, C, K)."""
    x1, x2 = xs[..., 0::2], xs[..., 1::2]
    cc = c[:, None, :]
    s2 = np.maximum(1.0 - 0.25 * cc * cc, 1e-300)
    a2 = (x1 * x1 - cc * x1 * x2 + x2 * x2) / s2
    return np.sqrt(np.maximum(a2, 0.0))
