"""The plain reference: eqs. (10)-(25) one sample at a time with textbook matrices.

The compiled and numpy paths of :class:`~cmsensord.dsp.order_tracker.OrderTracker`
are tested against it (to 1e-9).  See docs/order_tracker.md (§7).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cmsensord.dsp.order_tracker.bandwidth import component_r
from cmsensord.dsp.order_tracker.components import TrackedComponent, model_speed, omega
from cmsensord.dsp.order_tracker.design import q_diag


def reference_track(y, rpm, components: Sequence[TrackedComponent], fs: float, *,
                    q1: float = 0.1, min_rpm: float = 300.0,
                    smoother_lag: int | None = None, block: int = 0):
    """Plain per-sample Kalman one-step prediction of eqs. (10)-(25), exact gains.

    y: (T,) or (T, C) at ``fs`` (no decimation); rpm: (T,).  Returns the filtered
    waveforms x̂_k(n|n), (T, C, K) (or (T, K) for 1-D y).  With ``smoother_lag``
    = L and ``block`` = B it also returns the fixed-lag smoothed waveforms: for
    each block [jB, (j+1)B) a textbook Rauch-Tung-Striebel pass (with
    J = P(n|n) Fᵀ P(n+1|n)⁻¹) over [jB, (j+1)B + L); samples whose window is
    incomplete at the end are NaN.

    NaN in y is a missing sample of that channel: no measurement update, X̂(n|n) =
    X̂(n|n-1), P(n|n) = P(n|n-1) (and the RTS pass uses those).  Each channel is its
    own Kalman filter with its own P; when the channels miss different samples they
    are run one at a time.
    """
    y = np.asarray(y, dtype=np.float64)
    one = y.ndim == 1
    Y = y[:, None] if one else y
    T, C = Y.shape
    gone = np.isnan(Y)
    if C > 1 and (gone != gone[:, :1]).any():             # per-channel P: one channel at a time
        runs = [reference_track(Y[:, c], rpm, components, fs, q1=q1, min_rpm=min_rpm,
                                smoother_lag=smoother_lag, block=block) for c in range(C)]
        if smoother_lag is None:
            return np.stack(runs, axis=1)
        return np.stack([r[0] for r in runs], axis=1), np.stack([r[1] for r in runs], axis=1)
    gone = gone[:, 0]
    K = len(components)
    d = 2 * K
    speed = model_speed(rpm, min_rpm)
    w = omega(components, speed)
    rk = component_r(components, speed, fs)
    h = np.zeros((1, d))
    h[0, 1::2] = 1.0
    qd, q2 = q_diag(rk, q1)
    X = np.zeros((d, C))
    _, q20 = q_diag(component_r(components, np.array([min_rpm]), fs), q1)
    P = q20[0] * np.eye(d)                                  # P(0) = Q2 I, Q2 at min_rpm
    xf_all = np.empty((T, d, C))
    keep = smoother_lag is not None
    if keep:
        Pf_all, F_all = np.empty((T, d, d)), np.empty((T, d, d))
    for n in range(T):
        F = np.zeros((d, d))                                # eqs. (11)-(13)
        for k in range(K):
            F[2 * k, 2 * k + 1] = 1.0
            F[2 * k + 1, 2 * k] = -1.0
            F[2 * k + 1, 2 * k + 1] = 2.0 * math.cos(w[n, k] / fs)
        Q1 = np.diag(qd[n])                                 # eq. (25)
        Q2 = q2[n]
        if gone[n]:                                         # no measurement: time update only
            Xf, Pf = X, P
        else:
            S = (h @ P @ h.T)[0, 0] + Q2
            G = P @ h.T / S                                 # gain (2K, 1)
            e = Y[n][None, :] - h @ X                       # innovation (1, C), eq. (18)
            Xf = X + G @ e
            Pf = P - G @ h @ P
        if keep:
            Pf_all[n], F_all[n] = Pf, F
        xf_all[n] = Xf
        X = F @ Xf                                          # eq. (14)
        P = F @ Pf @ F.T + Q1
        P = 0.5 * (P + P.T)                                 # keep P symmetric (docs/order_tracker.md §3)
    wave = np.transpose(xf_all[:, 1::2, :], (0, 2, 1))      # (T, C, K)
    if smoother_lag is None:
        return wave[:, 0, :] if one else wave
    sm = _reference_smooth(xf_all, Pf_all, F_all, qd, int(smoother_lag), int(block))
    swave = np.transpose(sm[:, 1::2, :], (0, 2, 1))
    return (wave[:, 0, :], swave[:, 0, :]) if one else (wave, swave)


def _reference_smooth(xf_all, Pf_all, F_all, qd, L: int, B: int) -> np.ndarray:
    """Textbook fixed-lag RTS of :func:`reference_track`: for each block [b0, b0 + B) a
    pass J = P(n|n) Fᵀ P(n+1|n)⁻¹ back from b0 + B + L - 1; (T, 2K, C), NaN where the
    window is incomplete."""
    T, d, C = xf_all.shape
    sm = np.full((T, d, C), np.nan)
    for b0 in range(0, T, B):
        b1 = b0 + B
        end = b1 + L
        if end > T:
            break
        xs = xf_all[end - 1]
        for n in range(end - 2, b0 - 1, -1):
            Ppred = F_all[n] @ Pf_all[n] @ F_all[n].T + np.diag(qd[n])   # = P(n+1|n)
            J = np.linalg.solve(Ppred, F_all[n] @ Pf_all[n]).T             # Pf Fᵀ Ppred⁻¹
            xs = xf_all[n] + J @ (xs - F_all[n] @ xf_all[n])
            if n < b1:
                sm[n] = xs
        if b1 - 1 == end - 1:
            sm[end - 1] = xf_all[end - 1]
    return sm
