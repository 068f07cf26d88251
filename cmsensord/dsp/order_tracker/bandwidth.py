"""Weighting factor r <-> -3 dB bandwidth <-> envelope time constant, and r per component.

The mapping is the -3 dB width of the isolated steady-state one-component
filter (see docs/order_tracker.md, §4 Bandwidth); :func:`component_r` gives r_k
at any speed for components given by r or by a bandwidth (a cached grid of
speeds, interpolated in log-log).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cmsensord.dsp.order_tracker.components import DEFAULT_R, TrackedComponent
from cmsensord.dsp.order_tracker.design import f_matrices, q_diag, riccati_doubling


def _single_filter(r: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, ...]:
    """The isolated steady-state one-component filter for r, θ (G,): the pieces of
    X̂(n+1) = A X̂(n) + F k y(n),  x̂(n|n) = e₂ᵀ(I - k h) X̂(n) + k₂ y(n), as the
    columns (G, 1) :func:`_single_response` takes: A's four entries a b c d, F k,
    the row e₂ᵀ(I - k h), k₂, and the products b c, b (F k)₂, c (F k)₁ that do not
    depend on the frequency."""
    c = 2.0 * np.cos(theta)[:, None]
    qd, q2 = q_diag(np.asarray(r, dtype=np.float64)[:, None], 1.0)
    P = riccati_doubling(c, qd, q2, 40)
    S = P[:, 1, 1] + q2
    k = P[:, :, 1] / S[:, None]                       # (G, 2)
    F = f_matrices(c)                                # (G, 2, 2)
    IKh = np.eye(2) - k[:, :, None] * np.array([0.0, 1.0])[None, None, :]
    A = F @ IKh
    Fk = (F @ k[:, :, None])[:, :, 0]                 # (G, 2)
    a, b, cc, dd = A[:, 0, 0, None], A[:, 0, 1, None], A[:, 1, 0, None], A[:, 1, 1, None]
    f0, f1 = Fk[:, 0, None], Fk[:, 1, None]
    return a, b, cc, dd, f0, f1, IKh[:, 1, 0, None], IKh[:, 1, 1, None], k[:, 1, None], b * cc, b * f1, cc * f0


def _single_response(filt, nu: np.ndarray) -> np.ndarray:
    """|T(e^{jν})|² of :func:`_single_filter`'s filters at ν (G, M) rad/sample:
    T(z) = e₂ᵀ(I - k h)(zI - A)⁻¹ F k + k₂."""
    a, _, _, dd, f0, f1, row0, row1, k2, bc, bf1, cf0 = filt
    z = np.exp(1j * nu)
    za, zd = z - a, z - dd
    det = za * zd - bc
    u0 = (zd * f0 + bf1) / det
    u1 = (cf0 + za * f1) / det
    T = row0 * u0 + row1 * u1 + k2
    return np.abs(T) ** 2


_WINDOW = 8     # offsets of the grid tried first, around the narrow-band estimate of the edge


def _scan_rows(filt, th2, sgn, off, idx):
    """(g < 1/2) & inside (0, π) at the offsets ``off[idx]`` (rows, n) of each row's side."""
    nu = th2[:, None] + sgn[:, None] * off[idx]
    inside = (nu > 1e-9) & (nu < np.pi - 1e-9)
    return (_single_response(filt, np.clip(nu, 1e-9, np.pi - 1e-9)) < 0.5) & inside


def _first_below(filt, th2, sgn, r, off):
    """Per row, whether |T|² drops below 1/2 on the offset grid ``off`` out from θ on its
    side, and the first offset where it does: (has, i).

    |T|² decreases from 1 at θ to each edge (|T|² - 1/2 is a quadratic in cos ν over a
    positive one: two roots, one each side), so the first offset below 1/2 is found in a
    window of _WINDOW offsets around the narrow-band estimate 1/(√2 r sin θ) when the
    window's first offset is inside and not below (else, and when none in it is below,
    the row's whole grid is scanned).  Each value is computed as over the whole grid."""
    n = len(off)
    est = 1.0 / (np.sqrt(2.0) * r * np.maximum(np.abs(np.sin(th2)), 1e-12))
    start = np.clip(np.searchsorted(off, est) - _WINDOW // 2, 0, n - _WINDOW)
    idx = start[:, None] + np.arange(_WINDOW)[None, :]
    below = _scan_rows(filt, th2, sgn, off, idx)
    nu0 = th2 + sgn * off[start]
    first_ok = (start == 0) | (~below[:, 0] & (nu0 > 1e-9) & (nu0 < np.pi - 1e-9))
    ok = first_ok & below.any(axis=1)
    has = ok.copy()
    i = np.where(ok, start + below.argmax(axis=1), 0)
    redo = np.flatnonzero(~ok)
    if redo.size:
        sub = tuple(a[redo] for a in filt)
        full = _scan_rows(sub, th2[redo], sgn[redo], off, np.broadcast_to(np.arange(n), (redo.size, n)))
        has[redo] = full.any(axis=1)
        i[redo] = np.where(has[redo], full.argmax(axis=1), 0)
    return has, i


def r_to_bandwidth(r, freq_hz, fs: float) -> np.ndarray:
    """-3 dB bandwidth [Hz] of the isolated steady-state tracker with weighting factor r.

    The response of the steady-state one-component filter from y to x̂(n|n) is a
    band-pass with |T| = 1 exactly at the tracked frequency f (the model's poles
    are on the unit circle); the bandwidth is f_hi - f_lo where |T|² = 1/2
    either side (an edge at 0 or fs/2 if |T| never drops that far).  It depends
    on r and on θ = 2π f/fs, not on q1.  When B ≪ f (to 0.1 % for B < f/10)::

        B ≈ fs / (√2 π r sin θ),   τ = 1/(π B) ≈ √2 r sin θ / fs

    a first-order low-pass on the complex envelope (:func:`time_constant`):
    the process noise q1 on both samples of the pair (x(n-1), x(n)) is noise
    of variance 2 q1/sin²θ on the envelope, hence the sin θ.  So r is per
    sample and per frequency: the same r is narrower at a higher tracker rate
    and wider at a low frequency.  Vectorised over r and f.
    """
    r, f = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(freq_hz, dtype=np.float64))
    shape = r.shape
    r, f = r.ravel(), f.ravel()
    theta = 2.0 * np.pi * f / fs
    # geometric grid of offsets (rad/sample) outwards from θ (ratio 1.2 between
    # neighbours), then bisection to double precision
    off = np.geomspace(1e-7, np.pi, 100)
    # both edges in one batch: rows [0, G) search below θ, rows [G, 2G) above
    # (elementwise the same operations as one side at a time)
    filt = tuple(np.concatenate([a, a]) for a in _single_filter(r, theta))
    G = theta.size
    th2 = np.concatenate([theta, theta])
    sgn = np.repeat([-1.0, 1.0], G)
    limit = np.repeat([0.0, np.pi], G)
    has, i = _first_below(filt, th2, sgn, np.tile(r, 2), off)
    lo = np.where(i > 0, off[np.maximum(i - 1, 0)], 0.0)
    hi = off[i]
    for _ in range(48):
        mid = 0.5 * (lo + hi)
        gm = _single_response(filt, (th2 + sgn * mid)[:, None])[:, 0]
        lo, hi = np.where(gm < 0.5, lo, mid), np.where(gm < 0.5, mid, hi)
    edge = np.where(has, th2 + sgn * 0.5 * (lo + hi), limit)
    edges = (edge[:G], edge[G:])
    return ((edges[1] - edges[0]) * fs / (2.0 * np.pi)).reshape(shape)


def bandwidth_to_r(bandwidth_hz, freq_hz, fs: float) -> np.ndarray:
    """The weighting factor r whose isolated filter has this -3 dB bandwidth (inverse of
    :func:`r_to_bandwidth`, by secant iteration in log-log; vectorised)."""
    b, f = np.broadcast_arrays(np.asarray(bandwidth_hz, dtype=np.float64),
                               np.asarray(freq_hz, dtype=np.float64))
    shape = b.shape
    b, f = b.ravel(), f.ravel()
    if not np.all((b > 0) & (b < fs / 2)):          # NaN too (a bandwidth of None): no r is right for it
        raise ValueError(f"bandwidth_hz: expected in (0, fs/2 = {fs / 2}), got {b.min()}..{b.max()}")
    # first guess: the narrow-band relation B ≈ fs / (√2 π r sin θ) (see r_to_bandwidth)
    sin_t = np.maximum(np.sin(2.0 * np.pi * f / fs), 1e-3)
    x0 = np.log(fs / (np.sqrt(2.0) * np.pi * b * sin_t))
    x1 = x0 + 0.01
    g0 = np.log(r_to_bandwidth(np.exp(x0), f, fs)) - np.log(b)
    act = np.arange(b.size)          # elements still iterating (the others have converged,
    for _ in range(30):              # or sit where the bandwidth saturates near 0 or fs/2)
        g1 = np.log(r_to_bandwidth(np.exp(x1[act]), f[act], fs)) - np.log(b[act])
        done = np.abs(g1) < 1e-10    # bandwidth to 1e-10 relative
        x0[act[done]] = x1[act[done]]
        keep = ~done
        if not keep.any():
            break
        a, g1, gp = act[keep], g1[keep], g0[act[keep]]
        den = np.where(g1 != gp, g1 - gp, 1.0)
        x2 = np.where(g1 != gp, x1[a] - g1 * (x1[a] - x0[a]) / den, x1[a])
        x0[a], g0[a] = x1[a], g1
        x1[a] = np.clip(x2, x1[a] - 2.0, x1[a] + 2.0)
        act = a
    else:
        x0[act] = x1[act]
    return np.exp(x0).reshape(shape)


def time_constant(r, freq_hz, fs: float) -> np.ndarray:
    """Envelope time constant [s] of the isolated steady-state tracker: -ΔT/ln ρ,
    ρ the spectral radius of A = F(I - k h) (the decay of an estimation error);
    ≈ √2 r sin θ / fs = 1/(π B) when B ≪ f (see :func:`r_to_bandwidth`)."""
    r, f = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(freq_hz, dtype=np.float64))
    shape = r.shape
    r, f = r.ravel(), f.ravel()
    c = 2.0 * np.cos(2.0 * np.pi * f / fs)[:, None]
    qd, q2 = q_diag(r[:, None], 1.0)
    P = riccati_doubling(c, qd, q2, 40)
    S = P[:, 1, 1] + q2
    k = P[:, :, 1] / S[:, None]
    A = f_matrices(c) @ (np.eye(2) - k[:, :, None] * np.array([0.0, 1.0])[None, None, :])
    rho = np.max(np.abs(np.linalg.eigvals(A)), axis=-1)
    return (-1.0 / (fs * np.log(rho))).reshape(shape)


def component_r(components: Sequence[TrackedComponent], speed, fs: float) -> np.ndarray:
    """Weighting factor r_k at model speeds ``speed`` (T,): (T, K).

    Constant for a component given by r (or none: DEFAULT_R); from
    :func:`bandwidth_to_r` for one given by bandwidth_hz (evaluated at its
    frequency at each speed: a mild dependence) or bandwidth_pct (bandwidth
    = pct/100 x its frequency).  Bandwidth-given orders are computed on a fixed
    grid of 256 speeds (geometric, 10 to 100 000 rpm) and interpolated in
    log-log (to about 1e-4 of the bandwidth), so the result is a smooth,
    deterministic function of the speed.  r is per tracker sample: the same r
    is a different bandwidth in Hz at a different tracker rate.

    The grid values are computed when first needed (the grid points around
    the speeds asked for, all components in one batch) and cached; each is
    the same whenever and with whichever others it is computed.
    """
    speed = np.asarray(speed, dtype=np.float64)
    out = np.empty(speed.shape + (len(components),))
    grid_comps = [c for c in components if (c.bandwidth_hz is not None or c.bandwidth_pct is not None)
                  and c.freq_hz is None]
    span = None
    finite = speed[np.isfinite(speed)] if grid_comps else speed[:0]
    if finite.size:
        s = np.clip(finite, _R_SPEEDS[0], _R_SPEEDS[-1])
        j = np.minimum(np.maximum(np.searchsorted(_R_SPEEDS, s, side="right") - 1, 0), _R_N - 2)
        span = (int(j.min()), int(j.max()) + 2)      # grid points [j0, j1] bracket every speed
        # only the two points around each speed are solved (np.interp reads no others): a
        # table filled at min_rpm and at the running speed needs no r in between
        need = np.zeros(_R_N, dtype=bool)
        need[j] = True
        need[j + 1] = True
        _fill_r_grid(grid_comps, fs, need)
    for i, c in enumerate(components):
        if c.bandwidth_hz is None and c.bandwidth_pct is None:
            out[..., i] = DEFAULT_R if c.r is None else c.r
        elif c.freq_hz is not None:
            key = (c, fs)
            if key not in _R_CACHE:
                _R_CACHE[key] = float(bandwidth_to_r(_fixed_bandwidth(c, fs), c.freq_hz, fs))
            out[..., i] = _R_CACHE[key]
        elif span is None:                           # no finite speed
            out[..., i] = np.nan
        else:
            j0, j1 = span
            lr = _R_CACHE[(c, fs)][j0:j1]
            s = np.clip(speed, _R_SPEEDS[0], _R_SPEEDS[-1])
            out[..., i] = np.exp(np.interp(np.log(s), _R_LOG[j0:j1], lr))
    return out


def _fixed_bandwidth(c: TrackedComponent, fs: float) -> float:
    """The -3 dB bandwidth [Hz] of a fixed-frequency component: its bandwidth_hz, or its
    bandwidth_pct of freq_hz (capped at 0.45 fs, as the orders' grid caps theirs)."""
    if c.bandwidth_hz is not None:
        return c.bandwidth_hz
    assert c.bandwidth_pct is not None and c.freq_hz is not None  # component_r's fixed, bandwidth-given ones
    return min(c.bandwidth_pct / 100.0 * c.freq_hz, 0.45 * fs)


def _fill_r_grid(components: Sequence[TrackedComponent], fs: float, need: np.ndarray) -> None:
    """Compute the log r of the grid points ``need`` (bool, _R_N) not yet cached, for all
    these (bandwidth-given order) components in one batch."""
    idx, bws, fs_, dest = [], [], [], []
    for c in components:
        key = (c, fs)
        lr = _R_CACHE.get(key)
        if lr is None:
            lr = _R_CACHE[key] = np.full(_R_N, np.nan)
        miss = np.flatnonzero(need & np.isnan(lr))
        if not miss.size:
            continue
        grid = _R_SPEEDS[miss]
        f = c.freq(grid)
        if c.bandwidth_hz is not None:
            bw: float | np.ndarray = c.bandwidth_hz
        else:
            assert c.bandwidth_pct is not None  # the components here give one of the two
            bw = c.bandwidth_pct / 100.0 * f
        bws.append(np.minimum(np.broadcast_to(bw, f.shape), 0.45 * fs))
        fs_.append(np.minimum(f, 0.49 * fs))
        idx.append(miss)
        dest.append(lr)
    if not idx:
        return
    lr_all = np.log(bandwidth_to_r(np.concatenate(bws), np.concatenate(fs_), fs))
    n = 0
    for miss, lr in zip(idx, dest):
        lr[miss] = lr_all[n:n + miss.size]
        n += miss.size


_R_GRID = (10.0, 100_000.0)   # rpm range of the bandwidth -> r grid
_R_N = 256                    # its points (geometric)
_R_SPEEDS = np.geomspace(_R_GRID[0], _R_GRID[1], _R_N)
_R_LOG = np.log(_R_SPEEDS)
_R_CACHE: dict = {}           # (component, fs) -> log r on the grid (NaN: not computed yet)


def describe(components: Sequence[TrackedComponent], speed: np.ndarray, fs: float) -> list[dict]:
    """Per component at the model speed ``speed`` (1,): frequency, r, -3 dB bandwidth [Hz and
    %], time constant [s] (of the isolated steady-state filter at the tracker rate ``fs``)."""
    rk = component_r(components, speed, fs)[0]
    out = []
    for c, r in zip(components, rk):
        f = float(c.freq(speed)[0])
        bw = float(r_to_bandwidth(r, f, fs))
        out.append({"name": c.name, "freq_hz": f, "r": float(r), "bandwidth_hz": bw,
                    "bandwidth_pct": 100.0 * bw / f, "time_constant_s": float(time_constant(r, f, fs))})
    return out
