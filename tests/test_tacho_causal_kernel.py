"""The tacho's causal speed in the compiled kernel equals its numpy path, bit for bit:
the segments of new edges (``_trackerkernel.causal_fit``: the weighted quadratic over the last
``causal_window`` committed edges, with numpy's order of summation) and the order tracker's
speed at its samples (``_trackerkernel.causal_rpm``: the search, the extrapolation, the cap of
overdue edges, 60 x Hz where valid), on random edge streams with missed, spurious and
duplicated pulses and stops, fed in random splits, at causal windows below, at and above the
8 accumulators of numpy's pairwise sum; and the daemon's /orders with the kernel's causal
speed equal those of the numpy path, through ``cmsensord replay``."""

from __future__ import annotations

import json
import random
import subprocess
import sys

import numpy as np
import pytest

from cmsensord.dsp.order_tracker import have_kernel
from cmsensord.dsp.tacho import TachoTracker
from cmsensord.dsp.tacho.causal import CausalSpeed
from processes import ENV
from test_live_batching import raw_capture
from test_tacho_batch import L, random_edges

pytestmark = pytest.mark.skipif(not have_kernel(), reason="the compiled tracker kernel is not built")


def _tracker(kernel: bool, ppr: int, window: int | None) -> TachoTracker:
    tr = TachoTracker(25000, ppr=ppr, block_len=L, causal_window=window)
    tr.causal_kernel = kernel
    return tr


def _segments(tr: TachoTracker) -> np.ndarray:
    tr._flush_segments()
    return tr._sbuf[:, tr._slo:tr._shi].copy()


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize(("ppr", "window"), [(1, None), (1, 2), (1, 5), (1, 8), (1, 13), (2, None),
                                             (4, None)])
def test_the_kernels_causal_segments_and_speed_equal_the_numpy_path(seed, ppr, window):
    rnd = random.Random(1000 * seed + 10 * ppr + (window or 0))
    t0, edges = random_edges(rnd, 30.0)
    cuts = sorted(rnd.sample(range(1, len(t0)), rnd.choice([5, 60, 300])))
    c_tr, np_tr = _tracker(True, ppr, window), _tracker(False, ppr, window)
    compared = 0
    for a, b in zip([0, *cuts], [*cuts, len(t0)]):
        counts = [len(e) for e in edges[a:b]]
        off = np.concatenate(edges[a:b]) if b > a else np.empty(0, dtype=np.uint32)
        assert c_tr.feed_flat(t0[a:b], counts, off) == np_tr.feed_flat(t0[a:b], counts, off)
        seg = _segments(c_tr)
        assert np.array_equal(seg, _segments(np_tr), equal_nan=True)        # bit for bit
        compared += seg.shape[1]
        # the tracker's samples: one in 10 from a base, before, within and past the coverage
        # (the extrapolation, capped where edges are overdue)
        end = c_tr.covered_until
        base = max(0, end - rnd.randrange(1, 60000))
        pos = np.arange(rnd.randrange(10), end - base + rnd.randrange(0, 40000), 10, dtype=np.int64)
        got = c_tr.causal_rpm(base, pos)
        assert np.array_equal(got, np_tr.causal_rpm(base, pos))
        hz, valid = np_tr.evaluate_causal(base + pos)
        assert np.array_equal(got, np.where(valid & np.isfinite(hz), 60.0 * hz, 0.0))
    assert compared > 300


def test_the_kernels_causal_speed_is_zero_before_the_first_segment_and_without_edges():
    tr = _tracker(True, 1, None)
    pos = np.arange(0, 5000, 10, dtype=np.int64)
    assert np.array_equal(tr.causal_rpm(0, pos), np.zeros(pos.size))            # no edges yet
    t0 = np.arange(40, dtype=np.int64) * L
    edges = [np.array([100 * 256], dtype=np.uint32) if k >= 20 and k % 2 == 0 else
             np.empty(0, dtype=np.uint32) for k in range(40)]                     # 50 Hz from 5100
    tr.feed_flat(t0, [len(e) for e in edges], np.concatenate(edges))
    rpm = tr.causal_rpm(0, np.arange(0, 10000, 10, dtype=np.int64))
    assert not rpm[:510].any()                                  # before the first edge's segment
    assert rpm[-1] == pytest.approx(3000.0)                     # 50 Hz
    ref = _tracker(False, 1, None)
    ref.feed_flat(t0, [len(e) for e in edges], np.concatenate(edges))
    assert np.array_equal(rpm, ref.causal_rpm(0, np.arange(0, 10000, 10, dtype=np.int64)))


#: cmsensord with the kernel's causal speed off when the first argument is "off";
#: prints the /orders messages of its log (their stamps, from the wall clock at the start, left out)
CODE = """
import json, sys
from pathlib import Path
from cmsensord.dsp.tacho.causal import CausalSpeed
CausalSpeed.causal_kernel = sys.argv.pop(1) != "off"
from cmsensord.cli import main
rc = main(sys.argv[1:])
from cmsensord.sinks.mcap_sink import read_messages
log = next(Path(sys.argv[-1]).glob("*.mcap"))
print(json.dumps([{k: v for k, v in m.items() if k != "timestamp"}
                  for t, _, m in read_messages(log) if t.endswith("/orders")]))
"""


@pytest.mark.process
def test_the_daemons_orders_with_the_kernels_causal_speed_equal_the_numpy_paths(tmp_path):
    cap = tmp_path / "faulty.cap"
    cap.write_bytes(raw_capture(12.0))
    got = []
    for kernel in ("on", "off"):
        out = tmp_path / kernel
        p = subprocess.run([sys.executable, "-c", CODE, kernel, "replay", str(cap), "--out", str(out)],
                           capture_output=True, text=True, env=ENV, timeout=120)
        assert p.returncode == 0, p.stderr
        got.append(json.loads(p.stdout.strip().splitlines()[-1]))
    assert len(got[0]) >= 100 and sum(m["valid"] for m in got[0]) >= 50
    assert got[0] == got[1]
    assert CausalSpeed.causal_kernel        # the class default: the kernel where it is built


@pytest.mark.parametrize("seed", range(6))
def test_a_few_frames_fed_as_lists_give_what_feed_flat_gives(seed):
    """``feed_few`` (a live call's frames as Python lists, what Shaft.feed decodes) against
    ``feed_flat`` (arrays): the same events, speeds and causal speeds, bit for bit, on random
    edge streams in random splits (most calls of a few frames, some of more than 64, some
    stepping back in time, which both reject the same way)."""
    rnd = random.Random(500 + seed)
    t0, edges = random_edges(rnd, 30.0)
    cuts = sorted(rnd.sample(range(1, len(t0)), 250))
    few, flat = TachoTracker(25000, ppr=1, block_len=L), TachoTracker(25000, ppr=1, block_len=L)
    fed = 0
    for a, b in zip([0, *cuts], [*cuts, len(t0)]):
        t, counts = t0[a:b].tolist(), [len(e) for e in edges[a:b]]
        off = np.concatenate(edges[a:b]).tolist() if b > a else []
        if rnd.random() < 0.03 and t:                      # a frame from the past
            t[0] = max(0, t[0] - 3 * L)
        got, want = [], []
        for tr, out, args in ((few, got, (t, counts, off)),
                              (flat, want, (np.array(t, dtype=np.int64), counts, np.array(off)))):
            try:
                out += (tr.feed_few if tr is few else tr.feed_flat)(*args)
            except ValueError as exc:
                out.append(str(exc))
        assert got == want
        fed += len(t)
        s = np.arange(max(0, few.covered_until - 5000), few.covered_until + 500)
        for x, y in zip(few.evaluate_causal(s) + few.evaluate(s), flat.evaluate_causal(s) + flat.evaluate(s)):
            assert np.array_equal(x, y, equal_nan=True)
    assert fed > 1000 and few.counters == flat.counters and few.final_until == flat.final_until
    with pytest.raises(ValueError, match="one edge count per frame"):
        few.feed_few([few.covered_until], [2], [1])
