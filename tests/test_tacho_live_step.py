"""A live call's regular tacho edges in one compiled step (``_trackerkernel.regular_edges``,
EdgeRuns._few_edges, what ``feed_few`` takes) equal the edge-by-edge repair
(``batch_edges = False``) and the Python path without the kernel (``edge_kernel = False``):
the same events, counters, finality, smoothed and causal speeds, bit for bit, on random edge
streams with missed, spurious and duplicated pulses and stops, and on streams whose interval
ratios fall all over 1 +- tol (the decisions at the tolerance edges), fed about ten frames a
call."""

from __future__ import annotations

import random

import numpy as np
import pytest

from cmsensord.dsp.order_tracker import have_kernel
from cmsensord.dsp.tacho import TachoTracker
from cmsensord.dsp.tacho.edges import EdgeRuns
from test_tacho_batch import L, random_edges

pytestmark = pytest.mark.skipif(not have_kernel(), reason="the compiled tracker kernel is not built")


def ragged_edges(rnd: random.Random, seconds: float, fs: int = 25000) -> tuple[np.ndarray, list[np.ndarray]]:
    """TACHO frames of a shaft whose pulse intervals vary by up to +-30 % pulse to pulse, so that
    many interval ratios land near 1 +- tol (0.25), with a stop now and then."""
    q, t = [], 0.2 * fs
    while t < seconds * fs:
        t += fs / 30.0 * rnd.uniform(0.7, 1.3)
        if rnd.random() < 0.004:
            t += rnd.uniform(1.0, 2.0) * fs
        q.append(t)
    qq = np.round(np.asarray(q) * 256).astype(np.int64)
    n = int(seconds * fs) // L
    t0 = np.arange(n, dtype=np.int64) * L
    frame = qq // (256 * L)
    return t0, [(qq[frame == k] - t0[k] * 256).astype(np.uint32) for k in range(n)]


def feed(t0, edges, cuts, batch: bool = True, kernel: bool = True):
    """Feed the frames in calls split at ``cuts`` through ``feed_few``; what each call gave."""
    tr = TachoTracker(25000, ppr=1, block_len=L)
    tr.batch_edges, tr.edge_kernel = batch, kernel
    out = []
    for a, b in zip([0, *cuts], [*cuts, len(t0)]):
        counts = [len(e) for e in edges[a:b]]
        off = np.concatenate(edges[a:b]).tolist() if b > a else []
        ev = tr.feed_few(t0[a:b].tolist(), counts, off)
        s = np.arange(max(0, tr.covered_until - 3000), tr.covered_until + 200)
        out.append((ev, tr.counters.snapshot(), tr.final_until, tr.valid, tr.evaluate(s), tr.evaluate_causal(s)))
    return out


def same(got, ref) -> None:
    assert len(got) == len(ref)
    for g, r in zip(got, ref):
        assert g[:4] == r[:4]                                  # events, counters, finality, validity
        for x, y in zip(g[4] + g[5], r[4] + r[5]):             # speed, angle, validity; causal speed
            assert np.array_equal(x, y, equal_nan=True)        # bit for bit


def _spy(monkeypatch) -> list[int]:
    taken: list[int] = []
    step = EdgeRuns._regular_run

    def spy(self, q, adv, j):
        k = step(self, q, adv, j)
        taken.append(k)
        return k

    monkeypatch.setattr(EdgeRuns, "_regular_run", spy)
    return taken


@pytest.mark.parametrize("seed", range(6))
def test_a_live_calls_edges_in_one_step_equal_the_edge_by_edge_repair(seed, monkeypatch):
    rnd = random.Random(700 + seed)
    t0, edges = random_edges(rnd, 40.0)
    cuts = list(range(rnd.randrange(1, 12), len(t0), rnd.choice([8, 10, 12])))
    taken = _spy(monkeypatch)
    ref = feed(t0, edges, cuts, batch=False)
    assert not taken
    py = feed(t0, edges, cuts, kernel=False)
    assert not taken
    got = feed(t0, edges, cuts)
    n_edges = sum(map(len, edges))
    assert sum(taken) > 0.5 * n_edges and 0 in taken            # most edges in the step, not all
    same(got, ref)
    same(py, ref)
    c = ref[-1][1]
    assert c.missed + c.extra > 0 and c.lost > 0                 # the stream had repairs and stops


@pytest.mark.parametrize("seed", range(4))
def test_the_steps_decisions_at_the_tolerance_edges_are_the_edge_by_edge_ones(seed, monkeypatch):
    rnd = random.Random(800 + seed)
    t0, edges = ragged_edges(rnd, 30.0)
    cuts = list(range(rnd.randrange(1, 12), len(t0), 10))
    taken = _spy(monkeypatch)
    ref = feed(t0, edges, cuts, batch=False)
    got = feed(t0, edges, cuts)
    assert sum(taken) > 0.2 * sum(map(len, edges))
    same(got, ref)
    c = ref[-1][1]
    assert c.irregular > 50 and c.missed + c.extra > 0           # many ratios outside 1 +- tol
