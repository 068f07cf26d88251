"""The order tracker's input side (docs/order_tracker.md §4 Decimation, §5): the input
through the anti-alias low-pass with every D-th sample kept, the speed at those samples
delayed as the filter delays the signal, and which tracker samples miss a measurement;
``tr`` is the :class:`~.tracker.OrderTracker` whose input it is."""

from __future__ import annotations

import numpy as np

from cmsensord.dsp.order_tracker.sos_blocks import SosBlocks
from cmsensord.dsp.order_tracker.speed_line import delayed, delayed_at

__all__ = ["decimate", "missing"]

_NO_MISS = -(1 << 62)   # last_miss of a channel that has not missed an input yet


def missing(tr, gone_in, T):
    """Tracker samples of this call without a measurement, (N, C) bool or None (none),
    and the new ``last_miss``: tracker sample j (input jD, filtered) is missing when
    an input in (jD - W, jD] is, W = ``missing_window`` (the state carries the last
    missing input per channel across calls).  Changes no state.  (None, not an
    array of False, is what the rest passes on when nothing is missing: no
    per-call cost on the common path.)"""
    st = tr.state
    W = tr.missing_window
    n0 = st.n_in
    last = st.last_miss
    first = st.skip if tr.sos is not None else 0
    if gone_in is None and n0 + first - int(last.max()) >= W:
        return None, last                       # the common case: nothing missing near
    take = np.arange(first, T, tr.decimate)
    pos = n0 + take
    if gone_in is None:
        m = (pos[:, None] - last[None, :]) < W
        return (m if m.any() else None), last
    idx = np.where(gone_in, (n0 + np.arange(T))[:, None], _NO_MISS)
    lm = np.maximum(np.maximum.accumulate(idx, axis=0), last[None, :])
    m = (pos[:, None] - lm[take]) < W
    return (m if m.any() else None), lm[-1].copy()


def decimate(tr, kernel, y, rpm):
    """The call's input ``y`` (T, C) through the anti-alias low-pass with every D-th sample
    kept, and the speeds ``rpm`` at those samples (delayed as the filter delays): yd (N, C),
    rd (N,); the filter's carry, the skip and the input count move on (``kernel``: the compiled
    tracker kernel, used with the C backend)."""
    st = tr.state
    if callable(rpm) and (tr.sos is None or y.shape[0] == 0):
        rpm = np.asarray(rpm(np.arange(y.shape[0])), dtype=np.float64)
    if tr.sos is None:
        st.n_in += y.shape[0]
        return y, rpm
    if y.shape[0] == 0:
        return y, rpm
    take = np.arange(st.skip, y.shape[0], tr.decimate)
    if tr.backend == "c":           # filter and keep every D-th sample in one pass
        yd = np.empty((len(take), tr.C))
        kernel.sosfilt(tr.sos, np.ascontiguousarray(y), st.zi, yd, st.skip,
                               tr.decimate)
    else:                             # the numpy path: the kept outputs by blocks, no scipy
        if tr._sos_blocks is None:
            tr._sos_blocks = SosBlocks(tr.sos, tr.decimate)
        yd, st.zi, st.aa_part = tr._sos_blocks(y, st.zi, st.aa_part)
    if callable(rpm):
        rd = delayed_at(st, tr.delay_in, tr.decimate, rpm, y.shape[0], take)
    else:
        rd = delayed(st, tr.delay_in, rpm, take) if tr.delay_in else rpm[take]
    st.skip = int((st.skip - y.shape[0]) % tr.decimate)
    st.n_in += y.shape[0]
    return yd, rd
