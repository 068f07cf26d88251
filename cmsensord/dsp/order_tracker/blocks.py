"""The order tracker's per-block statistics: per output block the RMS and the mean envelope
of each component's waveform, the mean speed and whether the block is valid.

:func:`stats_numpy` is the reference; the compiled kernel's ``block_stats`` makes the same
numbers (the same operations in numpy's order), and its ``forward_blocks`` runs the filter,
the envelope and these statistics of a call in one pass (:func:`fused_blocks`): the same
numbers again, without the per-sample arrays in between.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from cmsensord.dsp.order_tracker.state import BlockStats, TrackerState, miss_blocks, with_carry

if TYPE_CHECKING:
    from cmsensord.dsp.order_tracker.tracker import OrderTracker


def stats_numpy(wave: np.ndarray, env: np.ndarray, rpm: np.ndarray, min_rpm: float, top_order: float,
                fs_track: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """rms, amplitude (E, C, K), mean speed and validity (E,) of whole blocks: wave/env
    (E, B, C, K), rpm (E, B).  A block is valid where every |rpm| >= min_rpm and the top
    order's frequency stays below half the tracker rate; its rms and amplitude are NaN
    where it is not."""
    # np.mean is the sum over the axis divided by its length: the same operations, without
    # its Python wrapper (this runs at every live call)
    n = wave.shape[1]
    rms = wave * wave
    rms = np.sqrt(rms.sum(axis=1) / n)
    amp = env.sum(axis=1) / n
    rmean = rpm.sum(axis=1) / n
    arpm = np.abs(rpm)
    speed_ok = (arpm >= min_rpm).all(axis=1)                    # NaN -> False
    f_hi = arpm.max(axis=1) / 60.0 * top_order
    valid = speed_ok & (f_hi < 0.5 * fs_track)
    if not valid.all():
        rms[~valid] = np.nan
        amp[~valid] = np.nan
    return rms, amp, rmean, valid


def fused_blocks(kernel, st: TrackerState, n0: int, yd: np.ndarray, c: np.ndarray, k: np.ndarray,
                 rd: np.ndarray, tr: OrderTracker) -> BlockStats:
    """The kernel's ``forward_blocks`` for tracker ``tr`` (its state ``st``): the filter over
    the tracker samples n0 .. of yd (N, C) with coefficients c and gains k from the state's z
    (updated) and their envelope, after the samples carried in the state's partial block
    (``pend``: "wave", "env", "rpm"; none missing), and the statistics of each whole block,
    as :func:`stats_numpy` gives them of the filter's waveform and envelope; the new
    partial block carried (``{}`` when there was none and the call is whole blocks, as the
    numpy path has it)."""
    K, B, pend = tr.K, tr.block, st.pend
    p = len(pend["rpm"]) if pend else 0
    rpm = np.concatenate([pend["rpm"], rd]) if p else np.ascontiguousarray(rd)
    C = st.z.shape[0]
    E = len(rpm) // B
    tail = len(rpm) - E * B
    rms, amp = np.empty((E, C, K)), np.empty((E, C, K))
    rmean, valid = np.empty(E), np.empty(E, dtype=bool)
    tw, te = np.empty((tail, C, K)), np.empty((tail, C, K))
    cw, ce = (pend["wave"], pend["env"]) if p else (tw[:0], te[:0])
    kernel(np.ascontiguousarray(yd), np.ascontiguousarray(c), np.ascontiguousarray(k), st.z, rpm, K, B, p,
           np.ascontiguousarray(cw), np.ascontiguousarray(ce), tr.min_rpm, tr.top_order, 0.5 * tr.fs_track,
           rms, amp, rmean, valid.view(np.uint8), tw, te)
    st.pend = {"wave": tw, "env": te, "rpm": rpm[E * B:].copy()} if p or tail else {}
    st.n_track = n0 + yd.shape[0]
    starts = (n0 - p) + B * np.arange(E)           # the first carried sample is a block start
    return block_stats(starts, rms, amp, rmean, valid, None, B, tr.decimate, tr.delay_in)


def block_stats(starts, rms: np.ndarray, amp: np.ndarray, rmean: np.ndarray, valid: np.ndarray,
                miss: np.ndarray | None, B: int, D: int, delay_in: int) -> BlockStats:
    """The :class:`BlockStats` of blocks starting at tracker samples ``starts`` (E,): their
    input sample (the block's last, through the decimation D and the filter's delay) and
    their missing samples per channel from ``miss`` (E, B, C) or None (none missing)."""
    starts = np.asarray(starts, dtype=np.int64)
    t_in = (starts + B - 1) * D - delay_in
    if miss is None:
        missing = np.zeros((len(starts), rms.shape[1]), dtype=np.int64)
    else:
        missing = np.count_nonzero(miss, axis=1).astype(np.int64)
    return BlockStats(start=starts, t_in=t_in, rpm=rmean, rms=rms, amplitude=amp, valid=valid,
                      missing=missing)


def causal_blocks(tr: OrderTracker, n0, wave, env, rd, miss) -> BlockStats:
    """The causal blocks this call completes: its tracker samples after those carried from
    the last call, the statistics of the whole blocks; the rest is carried (``pend``)."""
    st = tr.state
    B = tr.block
    C, K = tr.C, tr.K
    if miss is None and not (len(st.pend["rpm"]) if st.pend else 0) and not len(rd) % B:
        nb = len(rd) // B                   # whole blocks, nothing carried (a live call): as below
        st.pend = {}
        return tr._block_stats(n0 + B * np.arange(nb), wave.reshape(nb, B, C, K),
                                 env.reshape(nb, B, C, K), rd.reshape(nb, B), None)
    cur = with_carry(st.pend, {"wave": wave, "env": env, "rpm": rd}, miss, tr.C)
    first = n0 - (len(cur["rpm"]) - len(rd))          # index of cur[0], a block start
    nb = len(cur["rpm"]) // B
    used = nb * B
    st.pend = {k: v[used:].copy() for k, v in cur.items()}
    if "miss" in st.pend and not st.pend["miss"].any():
        del st.pend["miss"]
    return tr._block_stats(first + B * np.arange(nb),
                             cur["wave"][:used].reshape(nb, B, C, K),
                             cur["env"][:used].reshape(nb, B, C, K),
                             cur["rpm"][:used].reshape(nb, B),
                             miss_blocks(cur.get("miss"), used, nb, B))
