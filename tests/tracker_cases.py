"""Signals, components and helpers shared by the order tracker's test modules."""

from __future__ import annotations

import functools

import numpy as np

from cmsensord.dsp.order_tracker import BlockStats, OrderTracker, TrackedComponent, have_kernel, reference_track
from firmware_sim.order_signals import close_orders

BACKENDS = ["numpy"] + (["c"] if have_kernel() else [])

CLOSE = [TrackedComponent("order 1", order=1.0, r=50.0),
         TrackedComponent("order 4", order=4.0, r=50.0),
         TrackedComponent("order 4.2", order=4.2, r=50.0)]
WHIRL = [TrackedComponent("order 1", order=1.0, r=50.0),
         TrackedComponent("order 0.47", order=0.47, r=50.0),
         TrackedComponent("47 Hz", freq_hz=47.0, r=50.0)]


def true_block_rms(tr: OrderTracker, blocks: BlockStats, x: np.ndarray) -> np.ndarray:
    """RMS of the true component x (at fs_in) over the input samples each block stands for."""
    out = np.full(len(blocks.start), np.nan)
    for j, s0 in enumerate(blocks.start):
        i0 = s0 * tr.decimate - tr.delay_in
        i1 = i0 + tr.block * tr.decimate
        if i0 >= 0 and i1 <= len(x):
            out[j] = np.sqrt(np.mean(x[i0:i1] ** 2))
    return out


def block_min_rpm(tr: OrderTracker, blocks: BlockStats, rpm: np.ndarray) -> np.ndarray:
    out = np.full(len(blocks.start), -1.0)
    for j, s0 in enumerate(blocks.start):
        i0 = max(0, s0 * tr.decimate - tr.delay_in)
        i1 = i0 + tr.block * tr.decimate
        if i1 <= len(rpm):
            out[j] = rpm[i0:i1].min()
    return out


def eq26(tr, blocks, sig, name, k, min_rpm=800.0):
    """Eq. (26) in % per block whose speed is >= min_rpm throughout, and the blocks' speeds."""
    truth = true_block_rms(tr, blocks, sig.components[name])
    keep = block_min_rpm(tr, blocks, sig.rpm) >= min_rpm
    e = np.abs(blocks.rms[keep, 0, k] - truth[keep]) / truth[keep] * 100.0
    return e, blocks.rpm[keep]


REF_COMPONENTS = [TrackedComponent("order 1", order=1.0, r=50.0),
                  TrackedComponent("order 4", order=4.0, bandwidth_hz=20.0),
                  TrackedComponent("order 4.2", order=4.2, bandwidth_pct=8.0),
                  TrackedComponent("150 Hz", freq_hz=150.0, r=80.0)]


@functools.lru_cache(maxsize=1)
def ref_case_data():
    """1.25 s of close_orders from 180 rpm (through the 300-rpm clamp) with a
    150-Hz tone, on two channels; the reference with a smoother of lag 50, block 200."""
    sig = close_orders(seed=3)
    s = slice(600, 3100)
    t = sig.t[s]
    y = np.stack([sig.y[s] + 3.0 * np.cos(2 * np.pi * 150.0 * t), -0.5 * sig.y[s]], axis=1)
    rpm = sig.rpm[s]
    wave, smooth = reference_track(y, rpm, REF_COMPONENTS, 2000.0, smoother_lag=50, block=200)
    return y, rpm, wave, smooth


def concat(outs, attr):
    return np.concatenate([getattr(o, attr) for o in outs])


def concat_blocks(outs, attr, field):
    return np.concatenate([getattr(getattr(o, attr), field) for o in outs])


SPLIT_SIG = close_orders(fs=10000.0, seed=5, duration_s=1.6)


def one_pass_and_three_pieces(y, rpm, gains, backend, a, b):
    """A tracker and its output after one pass over y, and a second tracker and its
    outputs when fed y[:a], y[a:b], y[b:] (D = 8 from 10 kHz, 2 channels, lag 0.03 s)."""
    kw = {"fs_in": 10000.0, "max_rpm": 3000.0, "n_channels": 2, "gains": gains,
          "smoother_lag_s": 0.03, "backend": backend}
    one = OrderTracker(CLOSE, **kw)
    full = one.process(y, rpm)
    two = OrderTracker(CLOSE, **kw)
    parts = [two.process(y[i:j], rpm[i:j]) for i, j in ((0, a), (a, b), (b, len(y)))]
    return one, full, two, parts
