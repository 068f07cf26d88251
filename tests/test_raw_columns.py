"""A replay's RAW and TACHO frames stay columns (a :class:`FrameBatch`) from the decoder to the
block conversion and the tacho (a frame tuple per RAW and TACHO frame costs ~0.8 µs,
24 000 per 120 s of one channel): each columnar path against the list-of-frames
path it stands beside, on the same frames, with lost frames, frames of other lengths and
channels, steps back and the newest block incomplete."""

from __future__ import annotations

import random

import numpy as np
import pytest

from cmsensord.config import default_config
from cmsensord.dsp.tacho import TachoTracker
from cmsensord.frame_batch import FrameBatch
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.raw import RawInput
from cmsensord.monitor.shaft import Shaft
from cmsensord.protocol import Frame, FrameType, Status, _make, iter_frames
from test_live_batching import raw_capture
from test_tacho_frame_order import Reference, random_t0

L = 10


def status(C: int) -> Status:
    return Status(fw_version=256, mode=2, n_channels=C, fs=25000, block_len=L, tacho_inputs=1, tacho_ppr=1,
                  overruns=0, uptime_s=0, scale=(0.5, 1.0, 2.0, 4.0)[:C], offset=(1.0, 2.0, 3.0, 4.0)[:C])


def raw_frames(rng: np.random.Generator, C: int, trial: int) -> list[Frame]:
    """Blocks of C frames from t0 = 1000 on: some lost, some of another length or a channel
    >= C, a step back, the newest block cut short."""
    out = []
    t = 1000
    for _ in range(int(rng.integers(1, 40))):
        t += L * int(rng.integers(0, 3)) if trial % 4 == 3 else L
        for c in range(C):
            e = rng.random()
            if e < 0.08:
                continue                                         # lost
            n, ch = (L - 1 if e < 0.1 else L), (C if e > 0.98 else c)
            payload = (np.arange(n) * 7 + t + 3 * ch).astype("<u2").tobytes()
            out.append(Frame(FrameType.RAW, 0, t, ch, 0, payload, t, 0, 0))
    if trial % 5 == 4 and len(out) > 4:
        out = out[len(out) // 2:] + out[:len(out) // 2]           # a board reset: steps back
    if trial % 3 == 1 and out and C > 1:
        out.pop()                                                  # the newest block incomplete
    return out


def same_blocks(a, b) -> None:
    assert (a is None) == (b is None)
    if a is not None:
        for f in ("t0", "row", "chan", "x"):
            assert np.array_equal(getattr(a, f), getattr(b, f)), f
        assert a.n_channels == b.n_channels


@pytest.mark.parametrize("C", [1, 3])
@pytest.mark.parametrize("with_status", [True, False])
def test_raw_input_reads_a_batch_as_it_reads_its_frames(C, with_status):
    rng = np.random.default_rng(C)
    st = status(C) if with_status else None
    for trial in range(120):
        frames = raw_frames(rng, C, trial)
        if not frames:
            continue
        cut = int(rng.integers(0, len(frames) + 1))
        got, ref = [], []
        for raw, as_batch in ((RawInput(default_config(C)), True), (RawInput(default_config(C)), False)):
            res = got if as_batch else ref
            for part in (frames[:cut], frames[cut:]):                  # two reads
                raw.add(FrameBatch.of(part, _make) if as_batch else part)
                for final in (False, True):
                    ready, CC, events = raw.ready(st, final)
                    if with_status or C == 1:
                        assert (type(ready) is FrameBatch) == (as_batch and len(ready) > 0) or not ready
                    blocks, ev2 = raw.blocks(ready, CC, L, st) if ready else (None, [])
                    res.append((list(ready), CC, events, ev2, blocks))
                    if not final:
                        res.append(list(raw.waiting.joined()))
        assert len(got) == len(ref)
        for g, r in zip(got, ref):
            if type(r) is list:
                assert g == r
                continue
            assert g[:4] == r[:4]
            same_blocks(g[4], r[4])


@pytest.mark.parametrize("C", [1, 3])
def test_raw_input_drops_the_same_stray_frames_off_the_grid_from_a_batch_as_from_its_frames(C):
    """The frames above with RAW frames off the block grid here and there (before, among or after a block's
    frames, a few samples or most of a block off), read in two parts against a block clock: a batch and its
    frames give the same frames, the same strays dropped and the same events."""
    rng = np.random.default_rng(10 + C)
    st, dropped = status(C), 0
    for trial in range(120):
        frames = raw_frames(rng, C, trial)
        for _ in range(int(rng.integers(0, 4))):
            if frames:
                i = int(rng.integers(0, len(frames)))
                f = frames[i]
                t = f.t0_unwrapped + int(rng.integers(-L + 1, L))
                frames.insert(int(rng.integers(0, len(frames) + 1)), f._replace(t0=t, t0_unwrapped=t))
        if not frames:
            continue
        cut = int(rng.integers(0, len(frames) + 1))
        got, ref = [], []
        for as_batch, res in ((True, got), (False, ref)):
            raw, clock = RawInput(default_config(C)), BlockClock()
            clock.set_rate(25000, L)
            clock.anchor(frames[0].t0_unwrapped, 0)
            for part in (frames[:cut], frames[cut:]):
                raw.add(FrameBatch.of(part, _make) if as_batch else part)
                for final in (False, True):
                    ready, CC, events = raw.ready(st, final, clock)
                    res.append((list(ready), CC, events, raw.strays))
        assert got == ref
        dropped += ref[-1][-1]
    assert dropped > 20


def tacho_frames(rng: random.Random, n: int) -> list[Frame]:
    """TACHO frames of one input (and a few of another) at 1720 rpm, ppr 1, with steps back,
    repeats and lost frames (random_t0), one malformed payload."""
    out = []
    period = 25000 * 60 / 1720
    for k, t in enumerate(random_t0(rng, n)):
        edges = [o for o in range(250) if (t + o) % round(period) == 0]
        payload = len(edges).to_bytes(2, "little") + b"".join(o.to_bytes(4, "little") for o in edges)
        if k == n // 2:
            payload = b"\x05"                                     # malformed
        out.append(Frame(FrameType.TACHO, k & 0xFFFF, t, 1 if k % 17 == 5 else 0, 0, payload, t, 0, 0))
    return out


def test_the_shaft_feeds_a_batch_as_it_feeds_its_frames():
    """Batches of 0-300 TACHO frames (the columnar check above 64): the same frames kept, the
    same events and the same speed as the frames given as lists."""
    rng = random.Random(4)
    clock = BlockClock()
    clock.set_rate(25000, 250)
    clock.anchor(0, 10**18)
    for _ in range(6):
        frames = tacho_frames(rng, rng.randint(50, 900))
        shafts = [Shaft(default_config(1)), Shaft(default_config(1))]
        for s in shafts:
            s.tacho = TachoTracker(25000.0, 1, block_len=250)
        events: list[list] = [[], []]
        i = 0
        while i < len(frames):
            j = i + rng.choice([0, 1, 40, 65, 300])
            for k, s in enumerate(shafts):
                s.add_many(FrameBatch.of(frames[i:j], _make) if k == 0 else frames[i:j])
                events[k] += s.feed(clock) if s.waiting else []
            assert shafts[0]._fed_t0 == shafts[1]._fed_t0
            i = j
        assert events[0] == events[1]
        assert any(e.kind == "decode_error" for e in events[0])
        a, b = (s.tacho for s in shafts)
        samples = np.arange(0, frames[-1].t0_unwrapped, 97)
        assert a.covered_until == b.covered_until
        for x, y in zip(a.evaluate(samples), b.evaluate(samples)):
            assert np.array_equal(x, y, equal_nan=True)


def test_the_columnar_time_order_equals_the_numpy_reference():
    """Batches of 65-400 frames (the columnar path) with steps back and repeats: the frames
    kept, the count dropped and the newest t0 fed, as the former numpy code's."""
    rng = random.Random(5)
    dropped_total = 0
    for _ in range(40):
        shaft, ref = Shaft(default_config()), Reference()
        t0 = random_t0(rng, rng.randint(65, 1200))
        i = 0
        while i < len(t0):
            j = min(len(t0), i + rng.randint(65, 400))
            frames = [Frame(FrameType.TACHO, 0, t, 0, 0, b"\x00\x00", t, 0, 0) for t in t0[i:j]]
            kept, dropped, kept_t0 = shaft._in_time_order_columns(FrameBatch.of(frames, _make))
            want, want_dropped = ref.in_time_order(np.array(t0[i:j], dtype=np.int64))
            assert type(kept) is FrameBatch and list(kept) == [frames[k] for k in want]
            assert len(dropped) == want_dropped and kept_t0 == [t0[i + k] for k in want]
            assert dropped == [t for k, t in enumerate(t0[i:j]) if k not in want]
            assert shaft._fed_t0 == ref.fed
            dropped_total += len(dropped)
            i = j
    assert dropped_total > 50


def test_a_decoded_capture_through_both_paths_gives_the_same_blocks():
    """A real capture's frames (RAW + TACHO + STATUS), split at random: the RAW frames of each
    piece as a batch and as a list give the same blocks."""
    frames, _ = iter_frames(raw_capture(2.0))
    st = next(f for f in frames if f.type == FrameType.STATUS)
    from cmsensord.protocol import decode_status

    s = decode_status(st.payload)
    raws = [f for f in frames if f.type == FrameType.RAW]
    a, b = RawInput(default_config(1)), RawInput(default_config(1))
    for k in range(0, len(raws), 173):
        a.add(FrameBatch.of(raws[k:k + 173], _make))
        b.add(raws[k:k + 173])
        (fa, Ca, _), (fb, Cb, _) = a.ready(s, False), b.ready(s, False)
        assert list(fa) == list(fb) and Ca == Cb
        same_blocks(a.blocks(fa, Ca, s.block_len, s)[0], b.blocks(fb, Cb, s.block_len, s)[0])
