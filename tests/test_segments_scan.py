"""The Processor checks long batches in one pass (Segments.runs): the same
messages and events as checking every frame (the reference: ``SCAN_MIN`` out of reach), on
random streams with odd frames, stuck t0, resets, far jumps, steps back, seq gaps and
restarts, mode changes by STATUS, and on a RAW capture with a tacho."""

from __future__ import annotations

import pytest

import cmsensord.monitor.segments as segments
from cmsensord.config import default_config
from stream import run_processor
from test_stream_random import random_stream


def run(data: bytes, monkeypatch, one_pass: bool, chunk: int):
    passed = []
    passing = segments.Segments._passing

    def spy(self, cols, start):
        k = passing(self, cols, start)
        passed.append(k)
        return k

    with monkeypatch.context() as m:
        m.setattr(segments.Segments, "_passing", spy)
        if not one_pass:
            m.setattr(segments, "SCAN_MIN", 1 << 60)
        sink, proc, _ = run_processor(data, default_config(4), chunk=chunk)
    # the diagnostics' uptime is the process's own clock: all else is compared
    msgs = [(t, st, {k: v for k, v in msg.items() if k != "uptime_s"} if t == "/cm/diagnostics" else msg)
            for t, st, msg in sink.messages]
    return repr(msgs), proc.event_counts, passed


@pytest.mark.parametrize("seed", range(8))
def test_one_pass_checks_give_the_messages_of_frame_by_frame_checks(seed, monkeypatch):
    data = random_stream(seed, 6000)
    ref, ref_counts, none = run(data, monkeypatch, one_pass=False, chunk=1 << 16)
    assert not none
    got, counts, passed = run(data, monkeypatch, one_pass=True, chunk=1 << 16)
    assert sum(passed) > 500 and 0 in passed            # many frames in passes; some checked one by one
    assert got == ref and counts == ref_counts
    assert ref_counts.get("time_base", 0) > 0 and ref_counts.get("frames_lost", 0) > 0


def test_one_pass_checks_on_a_raw_capture_with_a_tacho(monkeypatch):
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    sc = make_scenario("faulty", n_channels=1, duration_s=12.0, seed=1)
    board = Board(sc, BoardConfig(n_channels=1, mode="raw", tacho=True))
    data = b"".join(d for d, _ in board.iter_blocks(board.n_blocks_for(12.0)))
    ref, ref_counts, _ = run(data, monkeypatch, one_pass=False, chunk=1 << 16)
    got, counts, passed = run(data, monkeypatch, one_pass=True, chunk=1 << 16)
    assert sum(passed) > 0.9 * 2 * 1200
    assert got == ref and counts == ref_counts and "/cm/ch0/orders" in ref


def status_frame(seq: int, t0: int, mode: int = 1, fs: int = 25000, block_len: int = 250) -> bytes:
    from cmsensord.protocol import Status, encode_status

    return encode_status(seq, t0, Status(fw_version=0x0100, mode=mode, n_channels=4, fs=fs, block_len=block_len,
                                         tacho_inputs=0, tacho_ppr=0, overruns=0, uptime_s=seq,
                                         scale=(1.0,) * 4, offset=(0.0,) * 4))


def test_one_pass_runs_through_status_frames_that_name_the_mode_and_fs_in_force(monkeypatch):
    """A STATUS frame each second naming the mode and fs in force does not end a pass; one
    that changes the fs (frame 1500) or the mode (frame 2500, to RAW: the RMS frames after it
    are the other mode's) does, and the messages are those of frame-by-frame checks."""
    import numpy as np

    from cmsensord.protocol import encode_rms

    rng = np.random.default_rng(1)
    out, t0, seq = [], 0, 0
    for k in range(3200):
        fs = 25000 if k < 1500 else 20000
        if k % 100 == 0 or k in (1500, 2500):
            out.append(status_frame(seq, t0, mode=2 if k >= 2500 else 1, fs=fs))
            seq += 1
        out.append(encode_rms(seq, t0, rng.uniform(0.5, 1.5, 4)))
        seq += 1
        t0 += 250
    data = b"".join(out)
    ref, ref_counts, _ = run(data, monkeypatch, one_pass=False, chunk=1 << 16)
    got, counts, passed = run(data, monkeypatch, one_pass=True, chunk=1 << 16)
    assert got == ref and counts == ref_counts
    assert max(passed) > 300                # through many STATUS frames at a time
    assert ref_counts.get("decode_error", 0) >= 1 and "/cm/ch0/severity" in ref


def test_one_pass_checks_with_t0_a_few_samples_back_and_a_block_length_change(monkeypatch):
    """A t0 now and then up to 300 samples behind the frame before it (less than a block: no reset; a block
    or more: a reset, :func:`~cmsensord.monitor.clock.is_reset`), and STATUS frames that change the block
    length (64 <-> 250) at the same mode and fs, which moves that line: the messages and events of one-pass
    checks are those of frame-by-frame checks."""
    import numpy as np

    from cmsensord.protocol import encode_rms

    rng = np.random.default_rng(2)
    out, t0, seq, block = [], 0, 0, 250
    for k in range(4000):
        if k % 100 == 0:
            block = 64 if k % 400 == 200 else 250
            out.append(status_frame(seq, t0, block_len=block))
            seq += 1
        out.append(encode_rms(seq, max(0, t0 - int(rng.integers(1, 300))) if rng.random() < 0.1 else t0,
                              rng.uniform(0.5, 1.5, 4)))
        seq += 1
        t0 += block
    data = b"".join(out)
    ref, ref_counts, _ = run(data, monkeypatch, one_pass=False, chunk=1 << 16)
    got, counts, passed = run(data, monkeypatch, one_pass=True, chunk=1 << 16)
    assert got == ref and counts == ref_counts
    assert max(passed) > 50 and 0 in passed
    assert 0 < ref_counts.get("time_base", 0) < 400         # the steps back of a block or more
