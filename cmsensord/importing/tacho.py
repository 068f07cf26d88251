"""Tacho edges for imported recordings: from a pulse column, or at a constant speed.

* :func:`pulse_edges`: rising crossings of ``threshold`` (default: halfway
  between the column's 1st and 99th percentiles) inside each snapshot, at the
  linearly interpolated fractional sample index, as the board's timer capture
  would time them;
* :func:`rpm_edges`: ``ppr`` edges per revolution at ``rpm``, one every
  ``60 fs / (rpm ppr)`` samples of the board clock from sample 0;
* :func:`speed_edges`: ``ppr`` edges per revolution of a column of shaft speed
  in rpm, inside each snapshot: the speed integrated (trapezoids) to the shaft's
  angle, an edge where it passes each ``1 / ppr`` revolution from the snapshot's
  first sample (a speed below 0 counts as standing still);
* :func:`block_edges`: edge positions on the board clock to (block, offset in
  1/256 sample), what the TACHO frames carry (docs/PROTOCOL.md, TACHO).
"""

from __future__ import annotations

import numpy as np

__all__ = ["SUB", "MAX_PPR", "board_ppr", "every_kth", "pulse_edges", "rpm_edges", "speed_edges", "block_edges"]

SUB = 256  # TACHO edge resolution: 1/256 sample
MAX_PPR = 255  # pulses a revolution the board's STATUS frame can announce (docs/PROTOCOL.md)


def board_ppr(ppr: int) -> int:
    """The pulses a revolution the capture carries for a sensor of ``ppr`` (an encoder's 1024):
    ``ppr`` itself up to :data:`MAX_PPR`, else ``ppr / k`` for the least whole ``k`` that
    brings it there (1024 -> 128), so that every ``k``-th edge still marks the same angle."""
    return next(ppr // k for k in range(1, ppr + 1) if ppr % k == 0 and ppr // k <= MAX_PPR)


def every_kth(edges: np.ndarray, bounds: list[tuple[int, int]], k: int) -> np.ndarray:
    """Sorted ``edges`` with every ``k``-th kept, counted from each snapshot's first edge
    (``bounds``: its ``(start, length)``), as a sensor of ``k`` times fewer pulses would give."""
    if k == 1 or not edges.size:
        return edges
    starts = np.array([s for s, _ in bounds] or [0])
    snap = np.searchsorted(starts, edges, side="right") - 1
    first = np.searchsorted(snap, snap, side="left")      # each edge's snapshot's first edge
    return edges[(np.arange(edges.size) - first) % k == 0]


def pulse_edges(x: np.ndarray, bounds: list[tuple[int, int]], threshold: float | None = None) -> np.ndarray:
    """float64 fractional sample indices into ``x`` of the rising crossings of ``threshold``,
    counted only inside each snapshot ``[start, start + length)`` of ``bounds``."""
    x = np.asarray(x, dtype=np.float64)
    if threshold is None:
        lo, hi = np.percentile(x, [1, 99]) if x.size else (0.0, 0.0)
        threshold = 0.5 * (lo + hi)
    below = x < threshold
    i = np.flatnonzero(below[:-1] & ~below[1:])  # x[i] < thr <= x[i + 1]
    if bounds:
        starts = np.array([s for s, _ in bounds])
        ends = np.array([s + n for s, n in bounds])
        k = np.searchsorted(starts, i, side="right") - 1
        i = i[(k >= 0) & (i + 1 < ends[np.maximum(k, 0)])]  # both samples in one snapshot
    frac = (threshold - x[i]) / (x[i + 1] - x[i])
    return i + np.clip(frac, 0.0, 1.0)


def rpm_edges(n_samples: int, fs: float, rpm: float, ppr: int) -> np.ndarray:
    """float64 board sample positions of ``ppr`` pulses a revolution at ``rpm``, in [0, n_samples)."""
    step = 60.0 * fs / (rpm * ppr)
    return np.arange(int(np.ceil(n_samples / step)), dtype=np.float64) * step


def speed_edges(rpm: np.ndarray, bounds: list[tuple[int, int]], fs: float, ppr: int) -> np.ndarray:
    """float64 fractional sample indices into ``rpm`` of ``ppr`` edges a revolution, each
    snapshot ``[start, start + length)`` of ``bounds`` on its own."""
    out = [np.empty(0)]
    for start, n in bounds:
        if n < 2:
            continue
        pulses = np.maximum(np.asarray(rpm[start:start + n], dtype=np.float64), 0.0) * ppr / (60.0 * fs)
        phase = np.concatenate([[0.0], np.cumsum(0.5 * (pulses[1:] + pulses[:-1]))])   # pulses at each sample
        k = np.arange(int(np.floor(phase[-1])) + 1, dtype=np.float64)
        moving = np.concatenate([[True], np.diff(phase) > 0])      # np.interp: increasing x only
        out.append(start + np.interp(k, phase[moving], np.flatnonzero(moving).astype(np.float64)))
    return np.concatenate(out)


def block_edges(pos: np.ndarray, block_len: int, n_blocks: int) -> tuple[np.ndarray, np.ndarray]:
    """(bounds, offsets): edges of block b are ``offsets[bounds[b]:bounds[b + 1]]`` (uint32,
    1/256 sample from the block's t0), for ``pos`` sorted board sample positions."""
    q = np.floor(np.asarray(pos, dtype=np.float64) * SUB).astype(np.int64)
    blk, off = np.divmod(q, block_len * SUB)
    bounds = np.searchsorted(blk, np.arange(n_blocks + 1))
    return bounds, off.astype(np.uint32)
