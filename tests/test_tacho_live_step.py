"""A live call's tacho path in compiled steps equals the Python one, bit for bit: its regular
edges in one step (``_trackerkernel.regular_edges``, EdgeRuns._few_edges, what ``feed_few``
takes) against the edge-by-edge repair (``batch_edges = False``) and the Python path without
the kernel (``edge_kernel = False``): the same events, counters, finality, smoothed and causal
speeds, on random edge streams with missed, spurious and duplicated pulses and stops, and on
streams whose interval ratios fall all over 1 +- tol (the decisions at the tolerance edges),
fed about ten frames a call; the edge lists of a call (``edge_lists``) against
TachoTracker._edge_lists and feed_few's checks; the payloads (``tacho_payloads``) against
Shaft's struct reading."""

from __future__ import annotations

import random

import numpy as np
import pytest

from cmsensord.dsp.order_tracker import have_kernel
from cmsensord.dsp.tacho import TachoTracker
from cmsensord.dsp.tacho import tracker as tacho_tracker
from cmsensord.dsp.tacho.edges import EdgeRuns, _kernel
from cmsensord.monitor.shaft import FEW_TACHO, decode_tacho_lists, read_tacho_payloads
from fakes import tacho_payload
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


def feed(t0, edges, cuts, batch: bool = True, kernel: bool = True, seed: int = 0):
    """Feed the frames in calls split at ``cuts`` through ``feed_few`` (a frame's edges in
    random order, now and then a call with a frame from the past or an offset past u32, which
    feed_few passes to feed_flat: it raises); what each call gave."""
    rnd = random.Random(seed)
    tr = TachoTracker(25000, ppr=1, block_len=L)
    tr.batch_edges, tr.edge_kernel = batch, kernel
    out = []
    for a, b in zip([0, *cuts], [*cuts, len(t0)]):
        t, counts = t0[a:b].tolist(), [len(e) for e in edges[a:b]]
        off = [o for e in edges[a:b] for o in rnd.sample(e.tolist(), len(e))]
        e = rnd.random()
        if e < 0.02 and t:
            t[0] = max(0, t[0] - 3 * L)                        # a frame from the past
        elif e < 0.04 and off:
            off[-1] += 2**32                                   # not a u32
        try:
            ev = tr.feed_few(t, counts, off)
        except ValueError as exc:
            ev = [str(exc)]
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
    ref = feed(t0, edges, cuts, batch=False, seed=seed)
    assert not taken
    py = feed(t0, edges, cuts, kernel=False, seed=seed)
    assert not taken
    got = feed(t0, edges, cuts, seed=seed)
    n_edges = sum(map(len, edges))
    assert sum(taken) > 0.5 * n_edges and 0 in taken            # most edges in the step, not all
    same(got, ref)
    same(py, ref)
    c = ref[-1][1]
    assert c.missed + c.extra > 0 and c.lost > 0                 # the stream had repairs and stops
    assert any(isinstance(x, str) for r in ref for x in r[0])    # some calls raised


@pytest.mark.parametrize("seed", range(4))
def test_the_steps_decisions_at_the_tolerance_edges_are_the_edge_by_edge_ones(seed, monkeypatch):
    rnd = random.Random(800 + seed)
    t0, edges = ragged_edges(rnd, 30.0)
    cuts = list(range(rnd.randrange(1, 12), len(t0), 10))
    taken = _spy(monkeypatch)
    ref = feed(t0, edges, cuts, batch=False, seed=seed)
    got = feed(t0, edges, cuts, seed=seed)
    assert sum(taken) > 0.2 * sum(map(len, edges))
    same(got, ref)
    c = ref[-1][1]
    assert c.irregular > 50 and c.missed + c.extra > 0           # many ratios outside 1 +- tol


@pytest.mark.parametrize("seed", range(3))
def test_the_kernels_edge_lists_are_feed_fews_checks_and_lists(seed):
    """``_trackerkernel.edge_lists``: TachoTracker._edge_lists of frames feed_few takes on
    Python ints (TachoTracker._few_ok), None for any other (stepping back in time, a count
    below 0 or not adding up, an offset not u32, more than 64 frames, none)."""
    rnd = random.Random(900 + seed)
    tr = TachoTracker(25000, ppr=1, block_len=L)
    taken = refused = 0
    for _ in range(3000):
        F = rnd.choice([0, 1, 3, 10, 64, 65])
        last = rnd.choice([None, 1000, 10**6])
        t = sorted(rnd.randrange(1000, 2000) for _ in range(F))
        counts = [rnd.choice([0, 0, 1, 1, 2, 5]) for _ in range(F)]
        off = [rnd.randrange(2**32) for _ in range(sum(counts))]
        e = rnd.random()
        if e < 0.1 and F > 1:
            t[rnd.randrange(1, F)] -= rnd.randrange(1, 300)     # a step back in time (or not)
        elif e < 0.15 and off:
            off[rnd.randrange(len(off))] = rnd.choice([-1, 2**32, 2**70])
        elif e < 0.2 and F:
            counts[rnd.randrange(F)] += rnd.choice([-3, 1])
        tr._last_t0 = last
        got = _kernel.edge_lists(t, counts, off, L, last, tacho_tracker._FEW_FRAMES)
        if t and tr._few_ok(t, counts, off):
            assert got == tr._edge_lists(t, counts, off)
            taken += 1
        else:
            assert got is None
            refused += 1
    assert taken > 1000 and refused > 500


@pytest.mark.parametrize("seed", range(3))
def test_the_kernels_tacho_payloads_are_the_struct_reading(seed):
    """``_trackerkernel.tacho_payloads`` (Shaft's decode_tacho_lists of a list of payloads): the
    counts and offsets read_tacho_payloads gives when every payload is well formed, None when
    one is not (too short, too long, not bytes: read_tacho_payloads gives its message)."""
    rnd = random.Random(950 + seed)
    taken = refused = 0
    for _ in range(2000):
        payloads: list = []
        for _ in range(rnd.randrange(FEW_TACHO + 1)):
            p = tacho_payload(rnd, [0, 0, 1, 1, 2, 300], 0.01, 0.01)
            if rnd.random() < 0.01:
                p = bytearray(p)
            payloads.append(p)
        got, want = _kernel.tacho_payloads(payloads), read_tacho_payloads(payloads)
        assert decode_tacho_lists(payloads) == want
        if want[2] or any(type(p) is not bytes for p in payloads):
            assert got is None
            refused += 1
        else:
            assert got == want[:2]
            taken += 1
    assert taken > 500 and refused > 500
