"""RMS-mode indicators: :meth:`RmsIndicators.add` sums the blocks of an interval in one pass;
it equals a block-by-block loop (kept here as the reference) on random block
times (gaps, steps back, repeats, misaligned starts), NaN values and batch splits."""

from __future__ import annotations

import random
from types import SimpleNamespace

import numpy as np
import pytest

from cmsensord.monitor.indicators import RmsIndicators


class Reference(RmsIndicators):
    """The block-by-block ``add`` as it was before the one-pass sums (a block under the t0 of the
    one before it left out)."""

    def add(self, t0: np.ndarray, vals: np.ndarray) -> list:
        out: list = []
        idx = [ch.index for ch in self.channels]
        v = np.full((len(t0), len(idx)), np.nan)
        have = [i for i, j in enumerate(idx) if j < vals.shape[1]]
        v[:, have] = vals[:, [idx[i] for i in have]]
        for k, t in enumerate(t0.tolist()):
            if t == self.newest:
                continue
            self.newest = t
            if self.start is None or t < self.start:
                out += self._close()
                self.start = t
            elif t >= self.start + self.N:
                out += self._close()
                self.start += (t - self.start) // self.N * self.N
            ok = np.isfinite(v[k])
            self.sq[ok] += v[k, ok].astype(np.float64) ** 2
            self.n += ok
            if t + self.L >= self.start + self.N:
                out += self._close()
        return out


def make(cls, channels):
    cfg = SimpleNamespace(indicators=SimpleNamespace(interval_s=0.1))
    clock = SimpleNamespace(stamp_ns=lambda t: 1000 * int(t))
    chans = tuple(SimpleNamespace(index=i, name=f"ch{i}") for i in channels)
    return cls(cfg, chans, fs=2500, block_len=25, clock=clock)


def block_times(rnd: random.Random, n: int) -> list[int]:
    t, out = rnd.randrange(0, 100), []
    for _ in range(n):
        out.append(t)
        r = rnd.random()
        t += 25 if r < 0.8 else rnd.choice([0, 7, 50, 250, 1000, -25, -600])
    return out


@pytest.mark.parametrize("seed", range(25))
def test_one_pass_sums_equal_the_block_by_block_loop(seed):
    rnd = random.Random(seed)
    channels = rnd.choice([(0, 1, 2, 3), (1, 3), (0, 5)])     # 5: beyond the board's 4 channels
    t0 = np.array(block_times(rnd, 600), dtype=np.int64)
    vals = np.asarray([[rnd.choice([rnd.uniform(0, 3), rnd.uniform(0, 3), np.nan, np.inf])
                        for _ in range(4)] for _ in t0], dtype=np.float32)
    got, ref = make(RmsIndicators, channels), make(Reference, channels)
    cuts = sorted(rnd.sample(range(1, len(t0)), rnd.randrange(0, 8)))
    out_got, out_ref = [], []
    for a, b in zip([0, *cuts], [*cuts, len(t0)]):
        out_got += got.add(t0[a:b], vals[a:b])
        out_ref += ref.add(t0[a:b], vals[a:b])
        assert got.sq.tobytes() == ref.sq.tobytes() and np.array_equal(got.n, ref.n)   # bit for bit
        assert got.start == ref.start
    out_got += got.finish()
    out_ref += ref.finish()
    assert len(out_ref) > 10
    assert out_got == out_ref


@pytest.mark.parametrize("seed", range(12))
def test_whole_intervals_in_one_pass_equal_the_block_by_block_loop(monkeypatch, seed):
    """Long runs of back-to-back blocks (whole intervals summed in one pass), broken
    now and then by a gap, a step back or a misaligned block: the same records and state."""
    from cmsensord.monitor import indicators

    rnd = random.Random(100 + seed)
    t, t0 = rnd.randrange(0, 100), []
    for _ in range(3000):
        t0.append(t)
        t += 25 if rnd.random() < 0.995 else rnd.choice([0, 7, 50, 250, 1000, -25, -600])
    t0_arr = np.array(t0, dtype=np.int64)
    vals = np.asarray([[rnd.choice([rnd.uniform(0, 3)] * 20 + [np.nan]) for _ in range(4)] for _ in t0],
                      dtype=np.float32)
    channels = rnd.choice([(0, 1, 2, 3), (1, 3), (0, 5)])
    cuts = sorted(rnd.sample(range(1, len(t0)), rnd.randrange(0, 8)))
    outs = []
    for one_pass in (1, 1 << 60):
        monkeypatch.setattr(indicators, "ONE_PASS_INTERVALS", one_pass)
        ind, out = make(RmsIndicators, channels), []
        for a, b in zip([0, *cuts], [*cuts, len(t0)]):
            out += ind.add(t0_arr[a:b], vals[a:b])
        out += ind.finish()
        outs.append((out, ind.sq.tobytes(), ind.n.tolist(), ind.start))
    assert len(outs[0][0]) > 200
    assert outs[0] == outs[1]
