"""A live call's fast paths give what the general paths give, bit for bit: the segment check of
a call's RAW and TACHO frames in one step (Segments.passes) against frame-by-frame checks and
the one-pass scan, the observation rows of a call with a block in every slot, the block RMS of
complete blocks, one-channel blocks in order, and the newest slot's stamps on the block clock."""

from __future__ import annotations

import numpy as np
import pytest

import cmsensord.monitor.segments as segments
from cmsensord.config import default_config
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.processor import Processor
from cmsensord.monitor.raw import RawBlocks, RawInput
from cmsensord.monitor.slots import observation_rows
from cmsensord.protocol import Frame, FrameType, encode_rms, iter_frames
from cmsensord.sinks.memory import ListSink


def raw_frames(n_channels: int, seconds: float, seed: int) -> list[Frame]:
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    sc = make_scenario("faulty", n_channels=n_channels, duration_s=seconds, seed=seed)
    board = Board(sc, BoardConfig(n_channels=n_channels, mode="raw", tacho=True))
    return iter_frames(b"".join(d for d, _ in board.iter_blocks(board.n_blocks_for(seconds))))[0]


def with_faults(frames: list[Frame], rng: np.random.Generator) -> list[Frame]:
    """Seq gaps (frames left out), a stuck t0, RMS frames of the other mode, a reset (t0 back),
    a jump far ahead and RAW frames off the block grid (strays), each here and there."""
    out: list[Frame] = []
    shift = 0
    rms = iter_frames(encode_rms(0, 0, [1.0]))[0][0]
    for k, f in enumerate(frames):
        r = rng.random()
        if k > 200 and r < 0.004:                   # lost: the next frame says so
            out.append(f._replace(t0_unwrapped=f.t0_unwrapped + shift, lost_before=1))
            continue
        if k > 200 and r < 0.006:
            shift -= int(rng.integers(1, 25000 * 5))         # a reset: t0 steps back
        elif k > 200 and r < 0.007:
            shift += 601 * 25000                    # further ahead than MAX_GAP_S: a reset too
        f = f._replace(t0_unwrapped=f.t0_unwrapped + shift)
        out.append(f)
        if k > 200 and r > 0.997:
            out.append(f if f.type is FrameType.RAW else rms._replace(t0_unwrapped=f.t0_unwrapped))
        elif k > 200 and r > 0.994 and f.type is FrameType.RAW:
            out.append(f._replace(t0_unwrapped=f.t0_unwrapped + int(rng.integers(1, 250))))
    return out


def run(frames: list[Frame], sizes: list[int], monkeypatch, fast: bool, n_channels: int):
    took: list[bool] = []
    passes = segments.Segments.passes

    def spy(self, part):
        ok = passes(self, part) if fast else False
        took.append(ok)
        return ok

    sink = ListSink()
    with monkeypatch.context() as m:
        m.setattr(segments.Segments, "passes", spy)
        proc = Processor(default_config(n_channels), sink, clock_ns=lambda: 10**18)
        k = 0
        for n in sizes:
            proc.handle(frames[k:k + n])
            k += n
        proc.finish()
    msgs = [(t, st, {k: v for k, v in msg.items() if k != "uptime_s"} if t == "/cm/diagnostics" else msg)
            for t, st, msg in sink.messages]
    return repr(msgs), proc.event_counts, took


@pytest.mark.parametrize("n_channels, seed", [(1, 1), (2, 2)])
def test_a_calls_frames_checked_in_one_step_give_the_messages_of_checks_one_by_one(n_channels, seed, monkeypatch):
    rng = np.random.default_rng(seed)
    frames = with_faults(raw_frames(n_channels, 14.0, seed), rng)
    sizes = [int(n) for n in rng.choice([1, 5, 20, 31, 40, 90], size=len(frames))]
    ref, ref_counts, none = run(frames, sizes, monkeypatch, fast=False, n_channels=n_channels)
    got, counts, took = run(frames, sizes, monkeypatch, fast=True, n_channels=n_channels)
    assert not any(none)
    assert sum(took) > 0.5 * len(took) and not all(took)    # most calls in one step, some not
    assert got == ref and counts == ref_counts
    assert ref_counts.get("time_base", 0) >= 2 and ref_counts.get("frames_lost", 0) > 0
    assert "a stray frame: the time base is kept" in ref
    assert "/cm/ch0/orders" in ref


def general_rows(first, slots, vals, index):
    """Observation rows as slot by slot placement makes them (the reference)."""
    T = int(slots[-1]) + 1 - first
    y = np.full((T, len(index)), np.nan)
    valid = np.zeros((T, len(index)), dtype=bool)
    if vals.shape[1] <= index.max():
        vals = np.pad(vals, ((0, 0), (0, index.max() + 1 - vals.shape[1])), constant_values=np.nan)
    y[slots - first] = vals[:, index]
    valid[slots - first] = True
    valid &= np.isfinite(y)
    return y, valid


@pytest.mark.parametrize("gaps", [False, True])
def test_observation_rows_of_a_block_in_every_slot_are_those_of_slot_by_slot_placement(gaps):
    rng = np.random.default_rng(3)
    for C_board, index in [(1, [0]), (4, [0, 1, 2, 3]), (4, [2, 0]), (2, [0, 3])]:
        vals = rng.normal(size=(12, C_board)).astype(np.float32)
        vals[rng.random(vals.shape) < 0.1] = np.nan
        slots = 40 + np.arange(12) + (np.arange(12) >= 5) * 3 * gaps
        y, valid = observation_rows(40, slots, vals, np.array(index))
        y_ref, valid_ref = general_rows(40, slots, vals, np.array(index))
        assert y.dtype == y_ref.dtype and valid.dtype == valid_ref.dtype
        assert y.tobytes() == y_ref.tobytes() and np.array_equal(valid, valid_ref)


def test_the_rms_of_complete_blocks_is_that_of_blocks_placed_frame_by_frame():
    rng = np.random.default_rng(4)
    for C in (1, 3):
        B, L = 7, 50
        x = rng.normal(size=(B * C, L))
        blocks = RawBlocks(np.arange(B) * L, np.arange(B * C) // C, np.arange(B * C) % C, x, C)
        general = RawBlocks(blocks.t0, blocks.row, blocks.chan, x, C)
        general._complete_memo = False              # the frame-by-frame placement
        assert blocks._complete()
        got, ref = blocks.rms(), general.rms()
        assert got.dtype == ref.dtype == np.float32 and got.tobytes() == ref.tobytes()


def test_one_channel_blocks_in_order_are_one_frame_a_block():
    frames = [f for f in raw_frames(1, 1.0, 5) if f.type is FrameType.RAW]
    raw = RawInput(default_config(1))
    blocks, events = raw.blocks(frames, 1, 250, None)
    t0 = np.array([f.t0_unwrapped for f in frames])
    assert not events and blocks is not None
    assert np.array_equal(blocks.t0, t0) and np.array_equal(blocks.row, np.arange(len(frames)))
    assert blocks._complete() and blocks._check_complete()
    stuck = frames[:5] + [frames[4]] + frames[5:]     # a stuck t0, a block sent again: its channel again
    blocks, _ = raw.blocks(stuck, 1, 250, None)         # is another block under that t0, as in another read
    assert blocks is not None and np.array_equal(blocks.t0, [*t0[:5], t0[4], *t0[5:]])
    assert np.array_equal(blocks.row, np.arange(len(stuck))) and blocks._complete()


def test_the_newest_slots_stamps_are_those_of_its_time_base():
    rng = np.random.default_rng(6)
    clock = BlockClock()
    clock.anchor(1000, 10**18)
    clock.place(np.array([1000]))
    floor = 0
    for k in range(300):
        r = rng.random()
        if r < 0.05:
            clock.new_segment(clock.slot_t0(clock.next_slot) + int(rng.integers(-10**6, 10**6)),
                              10**18 + k * 10**7, int(rng.integers(24000, 26000)))
        elif r < 0.1:
            clock.reanchor(clock.slot_t0(clock.next_slot) + int(rng.integers(-5000, 5000)))
        elif r < 0.12:
            clock.set_rate(int(rng.choice([20000, 25000])), int(rng.choice([200, 250])))
            clock.place(np.array([12345 + k]))
        n = int(rng.integers(1, 30))
        clock.advance(n)
        floor = max(floor, clock.slot_end_ns(clock.next_slot - 1))
        assert clock.last_stamp_ns == clock.slot_stamp_ns(clock.next_slot - 1)
        assert clock.floor_ns == floor
