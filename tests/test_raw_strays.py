"""Stray RAW frames off the block grid through ``cmsensord replay``: a valid-CRC RAW frame whose t0 is
not a whole number of blocks from the stream's (docs/PROTOCOL.md: the frames of a block share its t0,
the blocks follow one another a block apart), sent besides the block's own frames, is dropped with one
``decode_error`` event naming it and why, and the time base stays: the replay gives the messages of the
board without it.  Each case is a small capture replayed by a real process, checked by the exact events
in its MCAP, its summary and its severity."""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.protocol import Decoder, FrameType, encode_frame
from messages import comparable
from processes import cmsensord
from test_board_resets import events, replay
from test_read_size import board

pytestmark = pytest.mark.process

#: the topics of the board's data (all but the events and their log copies)
DATA_TOPICS = ("/cm/ch0/severity", "/cm/ch0/orders", "/cm/ch0/indicators")


def with_strays(data: bytes, off: int, blocks: set[int], seed: int = 0) -> bytes:
    """``data`` with, after the RAW frame of each block in ``blocks`` (block k: t0 250 k), one RAW frame of
    channel 0 under a t0 ``off`` samples past that block's, of random 12-bit counts (garbage that passed
    the CRC); the frames after it numbered on (no seq gap)."""
    rng = np.random.default_rng(seed)
    out, seq = bytearray(), 0
    for f in Decoder().feed(data):
        out += encode_frame(f.type, seq & 0xFFFF, f.t0, f.chan, f.flags, f.payload)
        seq += 1
        if f.type == FrameType.RAW and f.t0 // 250 in blocks:
            out += encode_frame(FrameType.RAW, seq & 0xFFFF, f.t0 + off, 0, 0,
                                rng.integers(0, 4096, 250).astype("<u2").tobytes())
            seq += 1
    return bytes(out)


def topics(msgs) -> dict[str, list]:
    """The messages of each data topic, stamps from the first severity message's (a replay anchors
    its stamps at the wall clock it starts at)."""
    out = comparable(msgs)
    return {t: [(s, m) for u, s, m in out if u == t] for t in DATA_TOPICS}


@pytest.mark.parametrize(("off", "told"), [
    (125, "the newest block taken"), (-125, "behind the newest block {newest}")])
def test_a_stray_frame_each_second_half_a_block_off_the_grid_is_dropped_on_a_commissioned_machine(tmp_path, off,
                                                                                                  told):
    """20 s of a healthy 1-channel RAW board with a tacho, commissioned on itself (``cmsensord calibrate``),
    and after the frame of block 50 of each second from 1 s on a RAW frame of garbage half a block ahead of
    it or behind it: each of the 19 is one decode_error naming its t0 and its block, the journal says 10
    and a summary of the rest, and the replay gives the clean capture's severity (healthy: 0, no failure),
    orders and indicators.  Guards against each stray re-anchoring the time base (1 or 2 config events a
    stray, the order tracker restarted, an observation more: 2019 in 20.2 s) and its garbage block taken
    as an observation: a FAILURE on the commissioned machine."""
    clean = board("raw", 20)
    tmp_path.mkdir(parents=True, exist_ok=True)
    (tmp_path / "healthy.bin").write_bytes(clean)
    site = tmp_path / "site.yaml"
    p = cmsensord("calibrate", str(tmp_path / "healthy.bin"), "--out", str(site), timeout=60)
    assert p.returncode == 0, p.stderr
    _, msgs = replay(tmp_path / "clean", clean, "--config", str(site))
    err, smsgs = replay(tmp_path / "strays", with_strays(clean, off, {100 * s + 50 for s in range(1, 20)}),
                        "--config", str(site))
    assert "ch0: final severity 0.0, max 0.0, 0 failure event(s), 20 decisions" in err
    assert "(2000 observations, 0 missing, 0 frames lost)" in err
    said = [(k, m) for _, k, m in events(smsgs)]
    assert [m for k, m in said if k == "decode_error"] == [
        f"RAW frame of channel 0 at t0 {25_000 * s + 12_500 + off} dropped: t0 off the block grid by +125 "
        f"sample(s) and in block {25_000 * s + 12_500 - (250 if off < 0 else 0)}, "
        + told.format(newest=25_000 * s + 12_500) + " (a stray frame: the time base is kept)" for s in range(1, 20)]
    assert [k for k, _ in said if k != "decode_error"] == [k for _, k, _ in events(msgs)] == ["config", "config"]
    assert "events: config 2, decode_error 19" in err
    lines = [x for x in err.splitlines() if x.startswith("WARNING decode_error: ")]
    assert len(lines) == 11 and lines[-1].startswith("WARNING decode_error: 9 more decode_error event(s) in ")
    assert topics(smsgs) == topics(msgs)


@pytest.mark.parametrize("off", [3, -3])
def test_a_lone_frame_a_few_samples_off_the_grid_is_dropped_and_the_stamps_stay(tmp_path, off):
    """5 s of a healthy RAW board with a tacho and one lone valid-CRC RAW frame of garbage 3 samples past
    block 150's t0 or 3 before block 149's, after that block's frame: one decode_error, and every
    data message and stamp is the clean capture's.  Guards against the lone frame re-anchoring the slots
    (a config event or two and the order tracker restarted, the stamps after it a block late)."""
    clean = board("raw", 5)
    _, msgs = replay(tmp_path / "clean", clean)
    block = 150 if off > 0 else 149
    err, smsgs = replay(tmp_path / "lone", with_strays(clean, off, {block}))
    assert "(500 observations, 0 missing, 0 frames lost)" in err
    t0 = 250 * block + off
    newest = "the newest block taken" if off > 0 else "behind the newest block 37250"
    assert [(k, m) for _, k, m in events(smsgs) if k != "config"] == [
        ("decode_error", f"RAW frame of channel 0 at t0 {t0} dropped: t0 off the block grid by {off:+d} sample(s) "
                         f"and in block {t0 - t0 % 250}, {newest} (a stray frame: the time base is kept)")]
    assert [m for _, k, m in events(smsgs) if k == "config"] == [m for _, k, m in events(msgs) if k == "config"]
    assert topics(smsgs) == topics(msgs)


def _moved(data: bytes, first_stray: bool = False, shift: dict[int, int] | None = None) -> bytes:
    """``data`` with each RAW frame of block k moved ``shift[k]`` samples (all its channels: the board
    sent that block under a t0 a few samples off), and with ``first_stray``, a RAW frame of garbage half a
    block past the first block's t0 sent before it; the frames numbered anew."""
    rng = np.random.default_rng(0)
    frames, done = [], not first_stray
    for f in Decoder().feed(data):
        if f.type == FrameType.RAW and not done:
            frames.append((FrameType.RAW, f.t0 + 125, 0, 0, rng.integers(0, 4096, 250).astype("<u2").tobytes()))
            done = True
        moved = (shift or {}).get(f.t0 // 250, 0) if f.type == FrameType.RAW else 0
        frames.append((f.type, f.t0 + moved, f.chan, f.flags, f.payload))
    return b"".join(encode_frame(k, s & 0xFFFF, *rest) for s, (k, *rest) in enumerate(frames))


def test_both_channels_of_a_block_a_few_samples_off_are_its_own(tmp_path):
    """A 2-channel board sends block 150 under t0 + 3, both its frames: taken as the block's (1200
    observations, no event), as the module says; its second channel was dropped as a stray (1199, one
    missing)."""
    clean = board("raw", 6, channels=2)
    err, msgs = replay(tmp_path / "moved", _moved(clean, shift={150: 3}))
    assert "(1200 observations, 0 missing, 0 frames lost)" in err, err
    assert [k for _, k, _ in events(msgs)] == ["config", "config"]


def test_a_stray_first_frame_does_not_set_the_grid(tmp_path):
    """A garbage RAW frame half a block past the first block's t0, sent before it, on a 2-channel board:
    one decode_error, and the board's frames all taken (1200 observations); it set the grid, every frame of
    the board's was off it and each block's second channel dropped (599 observations, 599 missing)."""
    clean = board("raw", 6, channels=2)
    err, msgs = replay(tmp_path / "first", _moved(clean, first_stray=True))
    assert "(1200 observations, 0 missing, 0 frames lost)" in err, err
    assert [m for _, k, m in events(msgs) if k == "decode_error"] == [
        "RAW frame of channel 0 at t0 125 dropped: t0 off the block grid by +125 sample(s) and in block 0, which "
        "has frames on the grid (a stray frame: the time base is kept)"]
