"""The tacho's one-pass paths equal the edge-by-edge ones they shortcut: regular
edges committed in one pass (cmsensord/dsp/tacho/regular.py) against ``batch_edges = False``
(every edge through the look-ahead repair), and ``update_flat`` (all edges in one array, as
the daemon decodes them) against ``update`` (one array per frame), on random edge streams
with jitter, speed changes, missed, extra and duplicated pulses and stops, in random splits."""

from __future__ import annotations

import random

import numpy as np
import pytest

from cmsensord.dsp.tacho import TachoTracker
from cmsensord.dsp.tacho import tracker as tacho_tracker
from cmsensord.dsp.tacho.edges import EdgeRuns

L = 250


def random_edges(rnd: random.Random, seconds: float, fs: int = 25000) -> tuple[np.ndarray, list[np.ndarray]]:
    """TACHO frames (t0, edge offsets in 1/256 sample) of a shaft with a random speed profile."""
    q, t, hz = [], 0.3 * fs, rnd.uniform(5, 60)
    while t < seconds * fs:
        hz = min(80.0, max(2.0, hz * rnd.uniform(0.97, 1.03)))
        t += fs / hz * (1 + rnd.gauss(0, 0.002))
        e = rnd.random()
        if e < 0.01:
            continue                                     # a missed pulse
        if e < 0.02:
            q.append(t - rnd.uniform(0.2, 0.8) * fs / hz)    # a spurious one before it
        elif e < 0.025:
            q.append(t)                                  # a duplicated edge
        elif e < 0.035:
            t += rnd.uniform(2.0, 4.0) * fs              # the shaft stops a while
        q.append(t)
    qq = np.round(np.sort(np.asarray(q)) * 256).astype(np.int64)
    n = int(seconds * fs) // L
    t0 = np.arange(n, dtype=np.int64) * L
    frame = qq // (256 * L)
    edges = [(qq[frame == k] - t0[k] * 256).astype(np.uint32) for k in range(n)]
    return t0, edges


def run(t0, edges, cuts, batch: bool, flat: bool, monkeypatch=None):
    tr = TachoTracker(25000, ppr=1, block_len=L)
    tr.batch_edges = batch
    events, final = [], []
    for a, b in zip([0, *cuts], [*cuts, len(t0)]):
        if flat:
            counts = [len(e) for e in edges[a:b]]
            off = np.concatenate(edges[a:b]) if b > a else np.empty(0, dtype=np.uint32)
            u = tr.update_flat(t0[a:b], counts, off)
        else:
            u = tr.update(t0[a:b], edges[a:b])
        events += u.events
        final.append((u.final_until, u.valid, u.counters))
    s = np.arange(int(tr.final_until))
    return events, final, tr.evaluate(s), tr.evaluate_causal(s)


def same(a, b) -> None:
    assert a[0] == b[0] and a[1] == b[1]                 # events, finality, validity, counters
    for x, y in zip(a[2] + a[3], b[2] + b[3]):            # speed, angle, validity; causal speed
        assert np.array_equal(x, y, equal_nan=True)       # bit for bit


@pytest.mark.parametrize("seed", range(12))
def test_regular_edges_in_one_pass_equal_the_edge_by_edge_repair(seed, monkeypatch):
    rnd = random.Random(seed)
    t0, edges = random_edges(rnd, 40.0)
    cuts = sorted(rnd.sample(range(1, len(t0)), rnd.choice([3, 20, 200])))
    committed = []
    commit = EdgeRuns._commit_regular

    def spy(self, q, adv):
        committed.append(q.size)
        commit(self, q, adv)

    monkeypatch.setattr(EdgeRuns, "_commit_regular", spy)
    ref = run(t0, edges, cuts, batch=False, flat=False)
    assert not committed
    got = run(t0, edges, cuts, batch=True, flat=False)
    assert sum(committed) > 0.1 * sum(map(len, edges))    # the one-pass path took its share
    same(got, ref)
    c = ref[1][-1][2]
    assert c.missed + c.extra > 0 and c.lost > 0              # the stream had repairs and stops


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("flat", [False, True])
def test_a_live_calls_regular_edges_in_one_step_equal_the_edge_by_edge_repair(seed, flat, monkeypatch):
    """Calls of about ten frames (a live call's few edges: each regular one committed in one
    step, EdgeRuns._regular_edge) against the edge-by-edge path (batch_edges False): the same
    events, finality, counters, speeds and causal speeds, bit for bit, on streams with missed,
    spurious and duplicated pulses and stops."""
    rnd = random.Random(300 + seed)
    t0, edges = random_edges(rnd, 40.0)
    cuts = list(range(rnd.randrange(1, 12), len(t0), 10))
    taken = []
    one_step = EdgeRuns._regular_edge

    def spy(self, q, adv):
        ok = one_step(self, q, adv)
        taken.append(ok)
        return ok

    monkeypatch.setattr(EdgeRuns, "_regular_edge", spy)
    ref = run(t0, edges, cuts, batch=False, flat=flat)
    assert not taken
    got = run(t0, edges, cuts, batch=True, flat=flat)
    assert sum(taken) > 0.5 * sum(map(len, edges)) and not all(taken)   # most edges, not all
    same(got, ref)
    c = ref[1][-1][2]
    assert c.missed + c.extra > 0 and c.lost > 0              # the stream had repairs and stops


@pytest.mark.parametrize("seed", range(4))
def test_update_flat_equals_update(seed):
    rnd = random.Random(100 + seed)
    t0, edges = random_edges(rnd, 20.0)
    cuts = sorted(rnd.sample(range(1, len(t0)), 30))
    same(run(t0, edges, cuts, batch=True, flat=True), run(t0, edges, cuts, batch=True, flat=False))


def test_update_flat_checks_its_arguments_and_raises_like_update_on_a_step_back():
    tr = TachoTracker(25000, ppr=1)
    with pytest.raises(ValueError, match="one edge count per frame"):
        tr.update_flat([0, 250], [1], [5])
    with pytest.raises(ValueError, match="one edge count per frame"):
        tr.update_flat([0, 250], [1, 1], [5])
    ref = TachoTracker(25000, ppr=1)
    with pytest.raises(ValueError) as a:
        tr.update_flat([0, 250, 0, 500], [1, 0, 1, 0], [5, 7])
    with pytest.raises(ValueError) as b:
        ref.update([0, 250, 0, 500], [[5], [], [7], []])
    assert str(a.value) == str(b.value) and "time order" in str(a.value)
    assert tr.counters == ref.counters and tr.covered_until == ref.covered_until


@pytest.mark.parametrize("seed", range(4))
def test_few_frames_on_python_ints_equal_the_array_code(seed, monkeypatch):
    """A live call's ten or so frames take the Python-int path of _update (tracker._few_frames):
    the same events, counters and values as the array code, bit for bit."""
    rnd = random.Random(200 + seed)
    t0, edges = random_edges(rnd, 30.0)
    cuts = sorted(rnd.sample(range(1, len(t0)), 300))         # about ten frames a call
    calls = []
    few = TachoTracker._few_frames

    def spy(self, *args):
        calls.append(few(self, *args))
        return calls[-1]

    monkeypatch.setattr(TachoTracker, "_few_frames", spy)
    got = run(t0, edges, cuts, batch=True, flat=True)
    assert len(calls) > 250 and all(calls)
    monkeypatch.setattr(tacho_tracker, "_FEW_FRAMES", 0)     # every call by the array code
    calls.clear()
    ref = run(t0, edges, cuts, batch=True, flat=True)
    assert not calls
    same(got, ref)
    c = ref[1][-1][2]
    assert c.missed + c.extra > 0 and c.lost > 0              # the stream had repairs and stops
