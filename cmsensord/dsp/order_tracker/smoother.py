"""The order tracker's fixed-lag smoother (docs/order_tracker.md §4 Smoother): each output
block smoothed over its window of the block and the lag after it by the modified
Bryson-Frazier backward pass (:func:`~.recursions.backward_numpy`, or the compiled kernel's
``backward``), with the smoothed blocks' statistics."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from cmsensord.dsp.order_tracker.recursions import backward_numpy, mask_groups
from cmsensord.dsp.order_tracker.state import TrackerOutput, miss_blocks, with_carry

if TYPE_CHECKING:
    from cmsensord.dsp.order_tracker.tracker import OrderTracker

__all__ = ["smooth"]


def smooth(tr: OrderTracker, kernel, out: TrackerOutput, L: int, n0, rd, c, k, S, P, zp, e, miss) -> None:
    """The fixed-lag smoother: each output block whose lag ``L`` has passed, by a backward
    pass over its B + L samples (in ``kernel``, the compiled tracker kernel, with the C
    backend); its index, waveform and blocks set in ``out`` (none yet: empty), the rest of
    the call carried (``hist``)."""
    st = tr.state
    B = tr.block
    cur = with_carry(st.hist, {"rpm": rd, "c": c, "k": k, "S": S, "P": P, "zp": zp, "e": e},
                     miss, tr.C)
    h0 = st.next_smooth * B                              # index of cur[0]
    n_end = n0 + len(rd)
    jb = st.next_smooth
    n_emit = max(0, (n_end - L) // B - jb)
    W = B + L
    d = 2 * tr.K
    if n_emit:
        starts = (np.arange(n_emit) * B).tolist()        # positions in cur
        if tr.backend == "c":
            xs = np.empty((n_emit, B, tr.C, d))
            some = "miss" in cur
            for i, s0 in enumerate(starts):
                sl = slice(s0, s0 + W)
                args: tuple[np.ndarray | int, ...] = (
                    np.ascontiguousarray(cur["c"][sl]), np.ascontiguousarray(cur["k"][sl]),
                    np.ascontiguousarray(cur["S"][sl]), np.ascontiguousarray(cur["P"][sl]),
                    np.ascontiguousarray(cur["zp"][sl]), np.ascontiguousarray(cur["e"][sl]),
                    xs[i], tr.K)
                if some and cur["miss"][sl].any():
                    args += (np.ascontiguousarray(cur["miss"][sl]).view(np.uint8),)
                kernel.backward(*args)
        else:                     # per mask pattern, as in _filter: k = 0 where missing
            acc: np.ndarray | None = None
            for chans, m in mask_groups(cur.get("miss")):
                kg = cur["k"] if m is None else np.where(m[:, None], 0.0, cur["k"])
                res = backward_numpy(cur["c"], kg, cur["S"], cur["P"], cur["zp"], cur["e"],
                                     starts, W, B)
                if acc is None:
                    acc = res
                else:
                    acc[:, :, chans] = res[:, :, chans]
            assert acc is not None  # mask_groups returns at least one group
            xs = acc
        used = n_emit * B
        cb = cur["c"][:used].reshape(n_emit, B, tr.K)
        wave = xs[..., 1::2]
        env = tr._envelope(xs.reshape(used, tr.C, d), cb.reshape(used, tr.K)).reshape(
            n_emit, B, tr.C, tr.K)
        out.smoothed_index = h0 + np.arange(used)
        out.smoothed_waveform = np.ascontiguousarray(wave.reshape(used, tr.C, tr.K))
        out.smoothed_blocks = tr._block_stats(h0 + B * np.arange(n_emit), wave, env,
                                                cur["rpm"][:used].reshape(n_emit, B),
                                                miss_blocks(cur.get("miss"), used, n_emit, B))
    else:
        used = 0
        out.smoothed_index = np.zeros(0, dtype=np.int64)
        out.smoothed_waveform = np.zeros((0, tr.C, tr.K))
        out.smoothed_blocks = tr._block_stats(np.zeros(0, np.int64),
                                                np.zeros((0, B, tr.C, tr.K)),
                                                np.zeros((0, B, tr.C, tr.K)),
                                                np.zeros((0, B)), None)
    st.next_smooth = jb + n_emit
    st.hist = {key: v[used:].copy() for key, v in cur.items()}
    if "miss" in st.hist and not st.hist["miss"].any():
        del st.hist["miss"]
