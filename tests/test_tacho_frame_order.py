"""The shaft's TACHO frame checks on Python ints (cmsensord/monitor/shaft.py: a live
call brings about ten frames) against a numpy reference of the same checks: which frames are kept
(those after the newest t0 fed so far: one step back, or a block's frame again under its t0), how
many are dropped, and the gaps noted
(lost frames), on random t0 sequences with steps back, repeats and gaps, fed in random
batches."""

from __future__ import annotations

import random
from collections import deque
from types import SimpleNamespace

import numpy as np

from cmsensord.config import default_config
from cmsensord.monitor.shaft import Shaft

L = 250


class Reference:
    """The former numpy implementation of Shaft._in_time_order and Shaft._note_gaps (a frame under
    the t0 of the newest one is dropped: a block has one TACHO frame)."""

    def __init__(self) -> None:
        self.fed: int | None = None
        self.prev: int | None = None
        self.gaps: deque[tuple[int, int]] = deque()

    def in_time_order(self, t0: np.ndarray) -> tuple[list[int], int]:
        if not t0.size:
            return [], 0
        newest = np.maximum.accumulate(t0)
        before = np.empty_like(newest)
        before[0] = t0[0] - 1 if self.fed is None else self.fed
        before[1:] = newest[:-1]
        if self.fed is not None:
            before = np.maximum(before, self.fed)
        keep = t0 > before
        self.fed = int(max(before[-1], t0[-1]))
        return np.flatnonzero(keep).tolist(), int((~keep).sum())

    def note_gaps(self, t0: np.ndarray) -> None:
        if not len(t0):
            return
        prev = np.concatenate(([t0[0] if self.prev is None else self.prev], t0[:-1]))
        for a, b in zip(prev[(t0 - prev) > L].tolist(), t0[(t0 - prev) > L].tolist()):
            self.gaps.append((a + L, b))
        self.prev = int(t0[-1])


def random_t0(rnd: random.Random, n: int) -> list[int]:
    """Block starts: mostly consecutive, some lost (gaps), repeated or stepping back."""
    t, out = 10 * L, []
    for _ in range(n):
        e = rnd.random()
        if e < 0.05:
            t += L * rnd.randint(2, 6)          # lost frames
        elif e < 0.08:
            t -= L * rnd.randint(1, 5)          # a step back (dropped)
        elif e > 0.1:
            t += L
        out.append(t)
    return out


def test_frame_order_and_gaps_equal_the_numpy_reference() -> None:
    rnd = random.Random(13)
    dropped_total = gaps_total = 0
    for _ in range(60):
        shaft, ref = Shaft(default_config()), Reference()
        t0 = random_t0(rnd, rnd.randint(1, 300))
        i = 0
        while i <= len(t0):
            j = min(len(t0), i + rnd.choice([0, 1, 2, 10, 37]))    # 0: a call without frames
            frames = [SimpleNamespace(t0_unwrapped=t) for t in t0[i:j]]
            kept, dropped, kept_t0 = shaft._in_time_order(frames)   # type: ignore[arg-type]
            want, want_dropped = ref.in_time_order(np.array(t0[i:j], dtype=np.int64))
            assert [next(k for k, f in enumerate(frames) if f is g) for g in kept] == want
            assert len(dropped) == want_dropped and kept_t0 == [t0[i + k] for k in want]
            assert dropped == [t for k, t in enumerate(t0[i:j]) if k not in want]
            assert shaft._fed_t0 == ref.fed
            shaft._note_gaps(kept_t0, L)
            ref.note_gaps(np.array(kept_t0, dtype=np.int64))
            n = len(shaft._gaps)
            assert list(shaft._gaps) == (list(ref.gaps)[-n:] if n else []) and len(ref.gaps) >= n
            assert shaft._prev_t0 == ref.prev
            dropped_total += len(dropped)
            i = j + 1 if j == len(t0) else j
        gaps_total += len(ref.gaps)
    assert dropped_total > 50 and gaps_total > 50            # both paths were exercised
