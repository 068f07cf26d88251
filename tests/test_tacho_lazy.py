"""The tacho's smoothed speed fitted when asked for (``TachoTracker.feed_flat``): the
live Processor feeds the TACHO frames ten times a second and asks for the smoothed speed about
once a second; the knots it then fits are those ``update_flat`` fits at every call, so every
value is the same, bit for bit, on random edge streams with repairs and stops."""

from __future__ import annotations

import random

import numpy as np
import pytest

from cmsensord.dsp.tacho import TachoTracker
from test_tacho_batch import L, random_edges


def feed(t0, edges, cuts, lazy: bool, ask_every: int):
    """Feed the frames in the calls ``cuts`` makes; every ``ask_every`` calls, ask for the
    smoothed and causal speed of the samples covered so far (as the Processor does)."""
    tr = TachoTracker(25000, ppr=1, block_len=L)
    events, asked = [], []
    fits = 0
    fit = tr._fit

    def counting(*args):
        nonlocal fits
        fits += 1
        return fit(*args)

    tr._fit = counting                                   # type: ignore[method-assign]
    for i, (a, b) in enumerate(zip([0, *cuts], [*cuts, len(t0)])):
        counts = [len(e) for e in edges[a:b]]
        off = np.concatenate(edges[a:b]) if b > a else np.empty(0, dtype=np.uint32)
        if lazy:
            events += tr.feed_flat(t0[a:b], counts, off)
        else:
            events += tr.update_flat(t0[a:b], counts, off).events
        if i % ask_every == ask_every - 1:
            s = np.arange(max(0, tr.covered_until - 30000), tr.covered_until)
            asked.append((tr.final_until, tr.evaluate(s), tr.evaluate_causal(s), tr.valid))
    s = np.arange(int(tr.final_until))
    return events, asked, tr.evaluate(s), tr.evaluate_causal(s), tr.counters, fits


def same_values(x, y) -> None:
    if isinstance(x, tuple):
        assert len(x) == len(y)
        for a, b in zip(x, y):
            same_values(a, b)
    elif isinstance(x, np.ndarray):
        assert np.array_equal(x, y, equal_nan=True)          # bit for bit
    else:
        assert x == y


@pytest.mark.parametrize("seed", range(6))
def test_knots_fitted_when_asked_for_give_the_values_of_knots_fitted_at_every_update(seed):
    rnd = random.Random(300 + seed)
    t0, edges = random_edges(rnd, 40.0)
    cuts = sorted(rnd.sample(range(1, len(t0)), 400))         # about ten frames a call, as live
    ref = feed(t0, edges, cuts, lazy=False, ask_every=10)
    got = feed(t0, edges, cuts, lazy=True, ask_every=10)
    assert got[0] == ref[0]                                   # events
    assert len(got[1]) == len(ref[1]) >= 30
    for a, b in zip(got[1], ref[1]):                          # each ask on the way
        same_values(a, b)
    for a, b in zip(got[2:5], ref[2:5]):                      # the end: values and counters
        same_values(a, b)
    assert got[5] < 0.4 * ref[5]                              # far fewer fits
    c = ref[4]
    assert c.missed + c.extra > 0 and c.lost > 0              # the stream had repairs and stops


def test_update_flat_after_feed_flat_returns_the_final_horizon_of_all_edges_fed():
    rnd = random.Random(7)
    t0, edges = random_edges(rnd, 10.0)
    half = len(t0) // 2
    lazy, ref = TachoTracker(25000, ppr=1, block_len=L), TachoTracker(25000, ppr=1, block_len=L)
    for first in (lazy.feed_flat, ref.update_flat):
        first(t0[:half], [len(e) for e in edges[:half]], np.concatenate(edges[:half]))
    args = (t0[half:], [len(e) for e in edges[half:]], np.concatenate(edges[half:]))
    a, b = lazy.update_flat(*args), ref.update_flat(*args)
    assert a.final_until == b.final_until > 0.5 * t0[-1] and a.events == b.events and a.valid == b.valid


def test_the_processor_fed_as_live_fits_the_smoothed_speed_about_once_a_decision(monkeypatch):
    """Fed in parts ending with each /orders block (ten calls a second, as the live loop), the
    Processor asks for the smoothed speed when a decision may be due, not at every call; its
    messages are those of one frame per call (test_live_batching.py checks the loop's batches)."""
    from cmsensord.config import default_config
    from cmsensord.dsp.tacho import smoothing
    from cmsensord.monitor.processor import Processor
    from cmsensord.protocol import FrameType, iter_frames
    from cmsensord.sinks.memory import ListSink
    from test_live_batching import by_topic, one_frame_per_call, raw_capture

    frames, _ = iter_frames(raw_capture(6.0))
    cfg = default_config(1)
    finalised = []
    fin = smoothing.KnotSmoothing._finalise

    def spy(self, ended):
        finalised.append(ended)
        return fin(self, ended)

    monkeypatch.setattr(smoothing.KnotSmoothing, "_finalise", spy)
    sink = ListSink()
    proc = Processor(cfg, sink, clock_ns=lambda: 10**18)
    calls, i = 0, 0
    while i < len(frames):
        wake, j = proc.wake_t0(), i
        while j < len(frames):                  # up to the frame completing the block to wake at
            f = frames[j]
            j += 1
            if wake is None and j - i >= 20 or wake is not None and (
                    f.t0_unwrapped > wake or f.t0_unwrapped == wake and f.type == FrameType.TACHO):
                break
        proc.handle(frames[i:j])
        calls, i = calls + 1, j
    proc.finish()
    assert calls >= 50
    assert len(finalised) <= 3 * 6 + 2                      # not one per call
    monkeypatch.setattr(smoothing.KnotSmoothing, "_finalise", fin)
    assert by_topic(sink.messages) == by_topic(one_frame_per_call(frames, cfg).messages)
