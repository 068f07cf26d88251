"""The RAW path's batch shortcuts against their one-at-a-time references.

* a checked run of frames hands its TACHO frames to the shaft in one call and its RAW
  frames to the batch in one (:meth:`Processor._passed`): the same messages as one frame
  per call, also when TACHO frames come before any STATUS (only the newest wait);
* :meth:`Shaft.add_many` keeps what :meth:`Shaft.add` of each frame keeps;
* RAW blocks in order are found from t0's steps (:meth:`RawInput.blocks`): the blocks
  and rows of ``np.unique``;
* :func:`rows_physical` converts in one pass: the plain formula's values bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.config import default_config
from cmsensord.dsp.rms import physical_rms, rows_physical
from cmsensord.frame_batch import FrameBatch
from cmsensord.monitor.processor import Processor
from cmsensord.monitor.raw import RawInput
from cmsensord.monitor.shaft import TACHO_WAIT_FRAMES, Shaft
from cmsensord.protocol import Frame, FrameType, Status, _make, iter_frames
from cmsensord.sinks.memory import ListSink
from test_live_batching import by_topic, one_frame_per_call, raw_capture


def in_batches(frames, cfg, size: int) -> ListSink:
    sink = ListSink()
    proc = Processor(cfg, sink, clock_ns=lambda: 10**18)
    for k in range(0, len(frames), size):
        proc.handle(frames[k:k + size])
    proc.finish()
    return sink


@pytest.mark.parametrize("status_late", [False, True])
def test_runs_of_raw_and_tacho_frames_give_the_messages_of_one_frame_per_call(status_late):
    frames, _ = iter_frames(raw_capture(4.0))
    kinds = [f.type for f in frames]
    assert kinds.count(FrameType.RAW) > 300 and kinds.count(FrameType.TACHO) > 300
    if status_late:     # no STATUS in the first 2.5 s: more TACHO frames come than wait
        frames = [f for f in frames if f.type != FrameType.STATUS or f.t0_unwrapped >= 62_500]
        first = next(i for i, f in enumerate(frames) if f.type == FrameType.STATUS)
        assert sum(f.type == FrameType.TACHO for f in frames[:first]) > TACHO_WAIT_FRAMES
    cfg = default_config(1)
    one = by_topic(one_frame_per_call(frames, cfg).messages)
    assert len(one["/cm/ch0/orders recursive"]) > 20 and len(one["/cm/ch0/indicators"]) >= 3
    for size in (64, 1000, len(frames)):
        assert by_topic(in_batches(frames, cfg, size).messages) == one, size


def tacho_frame(k: int, chan: int = 0) -> Frame:
    return Frame(FrameType.TACHO, k & 0xFFFF, 250 * k, chan, 0, b"\x00\x00", 250 * k, 0, 0)


@pytest.mark.parametrize("tracker", [False, True])
@pytest.mark.parametrize("as_batch", [False, True])
def test_add_many_keeps_what_add_of_each_frame_keeps(tracker, as_batch):
    """Also when the frames come as batches of columns (a replay's), kept as such."""
    frames = [tacho_frame(k, chan=k % 3 == 2) for k in range(3 * TACHO_WAIT_FRAMES)]
    one, many = Shaft(default_config(1)), Shaft(default_config(1))
    if tracker:                         # a tracker: nothing is dropped
        one.tacho = many.tacho = object()    # type: ignore[assignment]
    for f in frames:
        one.add(f)
    for k in range(0, len(frames), 77):
        many.add_many(FrameBatch.of(frames[k:k + 77], _make) if as_batch else frames[k:k + 77])
    assert list(many.waiting.joined()) == list(one.waiting.joined())
    assert len(one.waiting) == (2 * TACHO_WAIT_FRAMES if tracker else TACHO_WAIT_FRAMES)
    if as_batch and tracker:
        assert all(type(p) is FrameBatch for p in many.waiting.parts)


def raw_frame(t0: int, chan: int, L: int) -> Frame:
    payload = (np.arange(L, dtype="<u2") + t0 + chan).astype("<u2").tobytes()
    return Frame(FrameType.RAW, 0, t0, chan, 0, payload, t0, 0, 0)


def arrival_blocks(t: list[int], c: list[int]) -> tuple[list[int], list[int]]:
    """(t0 of each block, block of each frame), frame by frame: a block ends where t0 changes or
    a channel of it comes again."""
    t0s: list[int] = []
    row: list[int] = []
    seen: set[int] = set()
    for i, (ti, ci) in enumerate(zip(t, c)):
        if not t0s or ti != t[i - 1] or ci in seen:
            t0s.append(ti)
            seen = set()
        seen.add(ci)
        row.append(len(t0s) - 1)
    return t0s, row


def test_blocks_in_order_are_in_arrival_order_and_out_of_order_those_of_np_unique():
    rng = np.random.default_rng(7)
    L, C = 10, 3
    status = Status(fw_version=256, mode=2, n_channels=C, fs=25000, block_len=L, tacho_inputs=0, tacho_ppr=1,
                    overruns=0, uptime_s=0, scale=(0.5, 1.0, 2.0), offset=(1.0, 2.0, 3.0))
    raw = RawInput(default_config(C))
    for trial in range(200):
        steps = rng.integers(0, 3, rng.integers(1, 20)) * L
        t0 = np.repeat(np.cumsum(steps) + 1000, C)
        chans = np.tile(np.arange(C), len(steps))
        keep = rng.random(t0.size) < 0.8 if trial % 2 else np.ones(t0.size, dtype=bool)
        if trial % 10 == 9 and keep.sum() > 2:     # a board reset: t0 steps back
            t0 = np.concatenate((t0[t0.size // 2:], t0[:t0.size // 2] - 500))
        frames = [raw_frame(int(t), int(c), L) for t, c in zip(t0[keep], chans[keep])]
        if not frames:
            continue
        blocks, _ = raw.blocks(frames, C, L, status)
        t = np.array([f.t0_unwrapped for f in frames])
        if (np.diff(t) < 0).any():                   # a reset: the blocks of np.unique, in arrival order
            uniq, first, row = np.unique(t, return_index=True, return_inverse=True)
            order = np.argsort(first)
            assert np.array_equal(blocks.t0, uniq[order]) and np.array_equal(blocks.row, np.argsort(order)[row])
        else:                                        # a block sent again under its t0 is another block
            want_t0, want_row = arrival_blocks(t.tolist(), [f.chan for f in frames])
            assert blocks.t0.tolist() == want_t0 and blocks.row.tolist() == want_row
        counts = np.array([np.frombuffer(f.payload, "<u2") for f in frames], dtype=np.float64)
        c = np.array([f.chan for f in frames])
        ref = (counts - np.float32(status.offset)[c, None].astype(np.float64)) \
            * np.float32(status.scale)[c, None].astype(np.float64)
        assert np.array_equal(blocks.x, ref)


def test_rows_physical_equals_the_plain_formula_bit_for_bit():
    rng = np.random.default_rng(8)
    counts = rng.integers(0, 1 << 16, (50, 250)).astype(np.uint16)
    scale = rng.random(50).astype(np.float32)
    offset = (rng.random(50) * 4096).astype(np.float32)
    ref = (counts.astype(np.float64) - offset.astype(np.float64)[:, None]) * scale.astype(np.float64)[:, None]
    assert np.array_equal(rows_physical(counts, scale, offset), ref)
    assert np.array_equal(rows_physical(counts.astype(np.int64), scale, offset), ref)
    one_s, one_o = np.full(50, scale[3]), np.full(50, offset[3])    # one channel: one calibration
    ref1 = (counts.astype(np.float64) - np.float64(offset[3])) * np.float64(scale[3])
    assert np.array_equal(rows_physical(counts, one_s, one_o), ref1)
    assert np.array_equal(rows_physical(counts[:, ::2], one_s, one_o), ref1[:, ::2])    # strided counts
    assert rows_physical(counts[:0], scale[:0], offset[:0]).shape == (0, 250)


def test_block_rms_of_physical_values_is_the_plain_formula_bit_for_bit():
    rng = np.random.default_rng(12)
    for L in (1, 7, 250, 1000):
        x = rng.standard_normal((40, L)) * rng.uniform(1e-3, 1e3, (40, 1))
        ref = np.sqrt(np.mean(x * x, axis=-1)).astype(np.float32)
        got = physical_rms(x)
        assert got.dtype == np.float32 and got.tobytes() == ref.tobytes()


def test_samples_of_complete_blocks_equal_the_plain_scatter():
    rng = np.random.default_rng(9)
    L = 6
    for C in (1, 2, 4):
        status = Status(fw_version=256, mode=2, n_channels=C, fs=25000, block_len=L, tacho_inputs=0, tacho_ppr=1,
                        overruns=0, uptime_s=0, scale=(0.5,) * C, offset=(1.0,) * C)
        raw = RawInput(default_config(C))
        for trial in range(30):
            B = int(rng.integers(1, 12))
            pairs = [(1000 + L * b, c) for b in range(B) for c in range(C)]
            if trial % 3 == 1:                       # a lost frame
                del pairs[int(rng.integers(len(pairs)))]
            elif trial % 3 == 2 and C > 1:           # channels out of order in a block
                pairs[0], pairs[1] = pairs[1], pairs[0]
            if not pairs:
                continue
            blocks, _ = raw.blocks([raw_frame(t, c, L) for t, c in pairs], C, L, status)
            for index in ([*range(C)], [C - 1], [*range(C)][::-1]):
                ref = np.full((len(blocks.t0), L, len(index)), np.nan)
                for i, (r, c) in enumerate(zip(blocks.row, blocks.chan)):
                    if c in index:
                        ref[r, :, index.index(c)] = blocks.x[i]
                got = blocks.samples(index)
                assert got.flags.c_contiguous and np.array_equal(got, ref, equal_nan=True), (C, trial, index)
