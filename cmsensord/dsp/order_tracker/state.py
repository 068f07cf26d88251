"""What the order tracker returns and what it carries between calls.

:class:`TrackerState` holds every array carried from one call of
:meth:`OrderTracker.process` to the next (a leading channel axis where per
channel); the helpers join the arrays kept from the last call with the new ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np


@dataclass
class BlockStats:
    """Per output block (E blocks): aligned to tracker-sample indices [start, start + B)."""

    start: np.ndarray       # (E,) tracker-sample index of the block's first sample
    t_in: np.ndarray        # (E,) input-sample index the block's LAST sample stands for
    rpm: np.ndarray         # (E,) mean speed over the block (as measured, not clamped)
    rms: np.ndarray         # (E, C, K) RMS of x̂_k over the block; NaN where invalid
    amplitude: np.ndarray   # (E, C, K) mean envelope (peak amplitude); NaN where invalid
    valid: np.ndarray       # (E,) bool: speed >= min_rpm throughout the block
    missing: np.ndarray | None = None   # (E, C) int: the block's samples without a
    #                         measurement (missing input); their estimates are predictions


@dataclass
class TrackerOutput:
    """What one call of :meth:`OrderTracker.process` produced.

    Causal: ``waveform`` (N, C, K) for tracker samples ``index`` (N,) (absolute,
    from the start of the stream), standing for input samples ``t_in``, at
    speed ``rpm``; ``blocks`` the output blocks completed by this call.
    Smoothed (when ``smoother_lag_s`` is set): ``smoothed_index`` /
    ``smoothed_waveform`` / ``smoothed_blocks``, lagging by the smoother's lag.
    ``missing`` (N, C) bool: tracker samples without a measurement (a missing input
    within the anti-alias filter's window, see docs/order_tracker.md §5).
    """

    index: np.ndarray
    t_in: np.ndarray
    rpm: np.ndarray
    waveform: np.ndarray
    blocks: BlockStats
    smoothed_index: np.ndarray | None = None
    smoothed_waveform: np.ndarray | None = None
    smoothed_blocks: BlockStats | None = None
    missing: np.ndarray | None = None


@dataclass
class TrackerState:
    """Everything carried between calls (arrays; a leading channel axis where per channel)."""

    n_in: int                  # input samples consumed
    n_track: int               # tracker samples produced
    skip: int                  # input samples until the next one kept by the decimator
    zi: np.ndarray | None      # (sections, 2, C) sosfilt state
    rpm_line: np.ndarray       # (delay_in,) delayed speed samples (oldest first)
    z: np.ndarray              # (C, 2K) predicted state X̂(n|n-1)
    P: np.ndarray              # (2K, 2K) predicted covariance (exact gains)
    z0: np.ndarray | None = None   # numpy path: X̂ at the start of the current chunk
    aa_part: np.ndarray | None = None   # numpy path: inputs of the anti-alias filter's current block
    last_miss: np.ndarray | None = None   # (C,) input index of the last missing input
    chunk: dict = field(default_factory=dict)   # numpy path: inputs of the current chunk so far
    pend: dict = field(default_factory=dict)    # partial causal block, per-sample arrays
    hist: dict = field(default_factory=dict)    # smoother history from the next block to smooth
    next_smooth: int = 0       # index of the next block to smooth

    def copy(self) -> TrackerState:
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                v = v.copy()
            elif isinstance(v, dict):
                v = {k: a.copy() for k, a in v.items()}
            out[f.name] = v
        return TrackerState(**out)


def _join(parts: list):
    """Arrays (or None throughout) joined along the first axis; dataclasses field by field."""
    first = parts[0]
    if first is None:
        return None
    if isinstance(first, np.ndarray):
        return np.concatenate(parts)
    return type(first)(**{f.name: _join([getattr(p, f.name) for p in parts]) for f in fields(first)})


def join_outputs(outs: list[TrackerOutput]) -> TrackerOutput:
    """The outputs of consecutive calls as the one output of a call on their joined inputs."""
    return outs[0] if len(outs) == 1 else _join(outs)


def cat_miss(before, n_before, now, n_now, C):
    """Missing-sample masks of kept samples (``before``, n_before rows) and new ones
    (``now``), either None for none missing: the concatenation, or None."""
    if before is None and now is None:
        return None
    return np.concatenate([before if before is not None else np.zeros((n_before, C), dtype=bool),
                           now if now is not None else np.zeros((n_now, C), dtype=bool)])


def with_carry(carry, cur, miss, C):
    """The arrays kept from the last call (``carry``: a dict with "rpm", maybe "miss", or
    empty) followed by this call's (``cur``); "miss" only when a sample is missing."""
    p = len(carry["rpm"]) if carry else 0
    if p:
        cur = {k: np.concatenate([carry[k], v]) for k, v in cur.items()}
    m = cat_miss(carry.get("miss") if p else None, p, miss, len(cur["rpm"]) - p, C)
    if m is not None:
        cur["miss"] = m
    return cur


def miss_blocks(miss, used, nb, B):
    """The first ``used`` rows of a mask (or None) as (nb, B, C) blocks (or None)."""
    return None if miss is None else miss[:used].reshape(nb, B, miss.shape[1])
