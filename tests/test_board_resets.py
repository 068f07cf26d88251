"""Board resets through ``cmsensord replay`` (docs/PROTOCOL.md: t0 is the ADC sample index of the
first sample a frame covers, shared by the frames of a block and restarted with the board): each case
is one small capture replayed by a real process, checked by the exact events in its MCAP.  A reset into
RAW mode with a tacho says the order tracker at its first sample whatever the read size; the time_base
event, and the config event of a jump of the board clock, name the t0 the board sent; resets are
rate-limited like any event, and so are odd frames off in t0 between the blocks, with their resets; a t0
a few samples off is no reset; a paced replay paces each segment from its own start."""

from __future__ import annotations

import re

import pytest

from cmsensord.protocol import (
    MODE_RMS,
    Decoder,
    FrameType,
    Status,
    encode_frame,
    encode_rms,
    encode_status,
    encode_tacho,
)
from cmsensord.service.replay import REPLAY_CHUNK
from cmsensord.sinks.mcap_read import read_messages
from processes import cmsensord
from test_read_size import board

pytestmark = pytest.mark.process


def replay(tmp_path, data: bytes, *args: str) -> tuple[str, list]:
    """``cmsensord replay`` of ``data`` (exit 0): its stderr and the messages of its MCAP."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    cap = tmp_path / "cap.bin"
    cap.write_bytes(data)
    p = cmsensord("replay", str(cap), "--out", str(tmp_path / "out"), *args, timeout=60)
    assert p.returncode == 0, p.stderr
    return p.stderr, [m for f in sorted((tmp_path / "out").glob("*.mcap")) for m in read_messages(f)]


def events(msgs) -> list[tuple[int, str, str]]:
    """(stamp from the first event's, kind, message) of every /cm/events record."""
    ev = [(s, m["kind"], m["message"]) for t, s, m in msgs if t == "/cm/events"]
    return [(s - ev[0][0], k, m) for s, k, m in ev]


def rms_board(seconds: float, t0: int = 0, seq: int = 0, value=lambda k: 1.0) -> bytes:
    """A 1-channel RMS board from ``t0`` and ``seq``: a STATUS each second, a frame a block of 250 at
    25 kHz (RMS ``value(k)`` in block k)."""
    st = Status(0x0100, MODE_RMS, 1, 25_000, 250, 0, 0, 0, 0, (1.0,), (0.0,))
    out = bytearray()
    for k in range(round(seconds * 100)):
        if k % 100 == 0:
            out += encode_status(seq, t0 + 250 * k, st)
            seq += 1
        out += encode_rms(seq, t0 + 250 * k, [value(k)])
        seq += 1
    return bytes(out)


def frames_up_to(data: bytes, size: int) -> bytes:
    """The whole frames of ``data`` that fit in ``size`` bytes."""
    out = bytearray()
    for f in Decoder().feed(data):
        frame = encode_frame(f.type, f.seq, f.t0, f.chan, f.flags, f.payload)
        if len(out) + len(frame) > size:
            break
        out += frame
    return bytes(out)


def test_a_reset_into_raw_with_a_tacho_says_the_order_tracker_at_the_reset(tmp_path):
    """A 12.5-kHz RMS board (1 channel, no tacho) that fills replay's first read, reset into 2 RAW channels
    with a tacho whose second read holds 3.9 s of them, one TACHO frame 0.5 s in with an edge outside its
    block: the order tracker's config event is stamped at the reset, its first sample, and written before
    that frame's decode_error.  Guards against the tracker being made after the decisions of that read have
    let the decode_error go, and written late, at its stamp."""
    rms = frames_up_to(board("rms", 180, fs=12_500, tacho=False), REPLAY_CHUNK)
    raw = bytearray()
    for f in Decoder().feed(board("raw", 6, channels=2, fs=12_500)):
        edges = [300 * 256] if f.type == FrameType.TACHO and f.t0 == 6250 else None
        raw += (encode_frame(f.type, f.seq, f.t0, f.chan, f.flags, f.payload) if edges is None
                else encode_tacho(f.seq, f.t0, f.chan, edges))
    _, msgs = replay(tmp_path, rms + bytes(raw))
    after = [(s, k, m.split(":")[0]) for s, k, m in events(msgs) if s >= 170e9]
    reset = after[0][0]
    assert [(s - reset, k, m) for s, k, m in after] == [
        (0, "time_base", "board clock restarted (t0 0 after 2144000)"),
        (0, "config", "board firmware 1.0"),
        (0, "decision_rule", "board block rate 50 blocks/s (fs 12500 / block 250), not 100"),
        (0, "channels", "board now sends 2 channel(s), not 1"),
        (0, "config", "order tracker"),
        (500_000_000, "decode_error", "TACHO frame at t0 6250")]


@pytest.mark.parametrize(("before", "after", "told"), [
    (3_000_000_000, 0, "(t0 0 after 3000049750)"),
    (0, 2**32 - 67_296, "(t0 4294900000 after 49750)")])
def test_the_time_base_event_names_the_t0_the_board_sent(tmp_path, before, after, told):
    """A board up 33 h reset to t0 0; a board reset to a t0 just before its 2^32 wrap (unwrapped, a step
    back to -67296): the time_base event names the t0 fields as sent, not the unwrapped ones
    ("(t0 4294967296 after 3000049750)", "(t0 -67296 after 49750)")."""
    _, msgs = replay(tmp_path, rms_board(2, before, seq=100) + rms_board(2, after))
    assert [m for _, k, m in events(msgs) if k == "time_base"] == [
        f"board clock restarted {told}: time segment 1 starts at the wall clock; the seq gap of 65234 in "
        "front of it is not a loss (seq restarted)"]


def test_a_t0_stepping_back_every_other_frame_is_rate_limited_like_any_event(tmp_path):
    """1 s of a board, then 2000 RMS frames whose t0 goes 0, 250, 0, 250 ... (a t0 field glitching): 1000
    board resets, each a time segment 20 ms on.  /cm/events keeps 5 time_base records a second of event
    time and a summary of the rest each second, as the README promises.  Guards against each reset ending
    the limit's intervals, and all 1000 written one by one (~48 a second)."""
    glitch = b"".join(encode_rms(101 + k, (k % 2) * 250, [1.0]) for k in range(2000))
    _, msgs = replay(tmp_path, rms_board(1) + glitch)
    told = [(s, m) for t, s, m in msgs if t == "/cm/events" and m["kind"] == "time_base"]
    one = [s for s, m in told if "summarised" not in m]
    summaries = [(s, m["summarised"], m["message"]) for s, m in told if "summarised" in m]
    assert len(one) + sum(n for _, n, _ in summaries) == 1000
    assert (len(one), len(summaries)) == (100, 20)
    assert all(sum(0 <= t - s < 1e9 for t in one) <= 5 for s in one)
    assert summaries[0][2] == "45 more time_base event(s) in 0.98 s: at most 5 per 1 s are written one by one"


WRAP = 2**32


@pytest.mark.parametrize(("parts", "told"), [
    ([(WRAP - 12_500, 1.5), (15_000_000, 1.5)], "jumped 599.0 s ahead (t0 15000000 after 24750)"),
    ([(0, 1), (WRAP - 17_500_000, 1), (WRAP - 2_500_000, 1)], "jumped 599.0 s ahead (t0 4292467296 after 4277492046)"),
    ([(0, 1.5), (37_400, 1.5)], "did not advance a block (t0 37400 after 37250)")])
def test_a_jump_of_the_board_clock_names_the_t0_the_board_sent(tmp_path, parts, told):
    """A t0 that jumps 599 s ahead (no reset: within 600 s) across the board's 2^32 wrap, or under it after
    a reset back across it (unwrapped, below 0), and one that steps back 100 samples (less than a block):
    the config event names the t0 fields as sent and the seconds past the block expected next.  Guards
    against the unwrapped t0 and an internal slot ("t0 4309967296 after slot 149", "t0 -2500000 after slot
    199")."""
    data, seq = bytearray(), 0
    for t0, seconds in parts:
        data += rms_board(seconds, t0, seq=seq)
        seq += round(seconds * 100) + -(-round(seconds * 100) // 100)
    _, msgs = replay(tmp_path, bytes(data))
    assert [m for _, k, m in events(msgs) if "board clock" in m and k == "config"] == [
        f"board clock {told}: time base re-anchored"]


def jittered(data: bytes, every: int = 3, off: int = 7) -> bytes:
    """``data`` with the RAW frame of every ``every``-th block from 2 s on under a t0 ``off`` samples
    late (the TACHO frame after it, and the blocks after, under their own)."""
    out = bytearray()
    for f in Decoder().feed(data):
        late = f.type == FrameType.RAW and f.t0 >= 50_000 and (f.t0 // 250) % every == 0
        out += encode_frame(f.type, f.seq, f.t0 + off * late, f.chan, f.flags, f.payload)
    return bytes(out)


@pytest.mark.parametrize(("off", "resets", "held", "span_s"), [
    (2**31, 399, [15] * 19 + [14], 21), (30 * 25_000, 199, [5] * 19 + [3], 51)])
def test_odd_frames_off_in_t0_between_the_blocks_are_rate_limited_with_their_resets(tmp_path, off, resets, held,
                                                                                    span_s):
    """20 s of a 1-channel board and, after every 10th block, one CRC-valid RMS frame of 3 channels whose t0
    is ``off`` samples ahead of the block's (garbage on the link): 2^31, two board resets each; 30 s, one
    (the block after it steps back).  /cm/events keeps 5 ``channels`` and 5 ``time_base`` records a second
    and a summary of the rest each second, every event counted once; the journal (-v) says 10 lines of
    each kind (a per-second summary among them) and one summary of the rest.  Guards against the odd
    frame's event being stamped by the next segment's clock (a day ahead: the log's events 600 s off its
    data), and records of one kind stamped seconds from another's ending each other's intervals: all 200
    channels records written one by one, 10 a second."""
    st = Status(0x0100, MODE_RMS, 1, 25_000, 250, 0, 1, 0, 0, (0.0958,), (2048.0,))
    out, seq = bytearray(), 0
    for k in range(2000):
        if k % 100 == 0:
            out += encode_status(seq, 250 * k, st)
            seq += 1
        out += encode_rms(seq, 250 * k, [1.0])
        seq += 1
        if k % 10 == 9:
            out += encode_rms(seq, (250 * k + off) & 0xFFFFFFFF, [1.0] * 3)
            seq += 1
    err, msgs = replay(tmp_path, bytes(out), "-v")
    assert f"events: channels 200, config 1, time_base {resets}" in err
    for kind, summarised in (("channels", [5] * 20), ("time_base", held)):
        told = [(s, m) for t, s, m in msgs if t == "/cm/events" and m["kind"] == kind]
        one = [s for s, m in told if "summarised" not in m]
        assert len(one) + sum(summarised) == (200 if kind == "channels" else resets)
        assert [m["summarised"] for _, m in told if "summarised" in m] == summarised
        assert max(sum(0 <= t - s < 1e9 for t in one) for s in one) == 5
    stamps = [s for t, s, _ in msgs if t in ("/cm/events", "/cm/ch0/severity")]
    assert stamps[-1] - stamps[0] < span_s * 1e9
    lines = err.splitlines()
    assert sum(x.startswith("INFO channels: ") for x in lines) == 11
    assert "INFO channels: 186 more channels event(s) in 19.9 s (186 frame(s) between them): at most 10 per " \
           "600 s are written one by one" in lines


def test_a_t0_a_few_samples_off_is_no_board_reset(tmp_path):
    """The RAW frame of every third block from 2 s on says a t0 7 samples late (docs/PROTOCOL.md: the
    frames of a block share its t0): the TACHO frame after it, 7 samples behind, is no board reset and the
    RAW samples follow on.  The replay tells what the board's own t0 gives, every observation and order
    there.  Guards against each such step back being a reset: 100 time segments in 3 s, each with an order
    tracker made anew, and 100 missing observations."""
    clean = board("raw", 5)
    err, msgs = replay(tmp_path / "clean", clean)
    jerr, jmsgs = replay(tmp_path / "jittered", jittered(clean))
    assert [(k, m) for _, k, m in events(jmsgs)] == [(k, m) for _, k, m in events(msgs)]
    assert [k for _, k, _ in events(msgs)] == ["config", "config"]
    assert "(500 observations, 0 missing, 0 frames lost)" in jerr
    orders = [[(m["valid"], m["speed_rpm"]) for t, _, m in run if t == "/cm/ch0/orders"] for run in (msgs, jmsgs)]
    assert len(orders[1]) == len(orders[0]) == 50
    assert [v for v, _ in orders[1]] == [v for v, _ in orders[0]] and sum(v for v, _ in orders[0]) == 49
    assert orders[1] == orders[0]


@pytest.mark.parametrize("before", [3_000_000_000, 0])
def test_a_paced_replay_paces_each_segment_from_its_own_start(tmp_path, before):
    """``replay --speed 2`` of 2 s of a board, a reset to t0 0, 2 s more: 2 s of wall time whether the board
    had been up 33 h (t0 3e9: its unwrapped t0 then jumps on by 1.29e9 samples) or had just started (t0 back
    by 2 s).  Guards against the first sleeping 7.2 h at the reset (a run killed at 60 s), and the second not
    pacing the 2 s after the reset (1 s of wall time)."""
    err, msgs = replay(tmp_path, rms_board(2, before, seq=100) + rms_board(2), "--speed", "2")
    wall = float(re.search(r"4\.0 s of ADC time in ([0-9.]+) s wall", err).group(1))
    assert 1.9 <= wall <= 3.5, err
    assert [k for _, k, _ in events(msgs)] == ["config", "time_base"]
