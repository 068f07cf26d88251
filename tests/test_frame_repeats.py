"""Frames the link delivers twice (cmsensord/frame_repeats.py): dropped, counted, one event each.

Guards against a frame received again read as ~65,535 lost frames (its seq gap, rule 3 alone) and,
its t0 behind the newest, as a board that restarted its clock: a `frames_lost` event of 65535, a
`time_base` re-anchoring, the order tracker restarted, and other messages at other read sizes.
"""

from __future__ import annotations

import json

import pytest

from cmsensord.protocol import OVERHEAD, Decoder, FrameType, encode_frame, iter_frames
from cmsensord.sinks.mcap_sink import read_messages
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from messages import comparable
from processes import board_then_daemon, cmsensord, run_module
from test_read_size import by_topic

READS = (997, 4114, 65_536, 1 << 20)
DECODERS = {"plain": dict(runs=False), "numpy runs": dict(runs=True, kernel=False), "kernel": dict(kernel=True)}


def board_frames(mode: str = "raw", seconds: float = 14, **kw) -> list:
    sc = make_scenario("healthy", n_channels=1, duration_s=seconds, seed=1)
    return iter_frames(Board(sc, BoardConfig(mode=mode, tacho=True, **kw)).generate(seconds))[0]


def wire(frames) -> bytes:
    return b"".join(encode_frame(f.type, f.seq, f.t0, f.chan, f.flags & 0xFF, f.payload) for f in frames)


def decoded(data: bytes, read: int, **kw):
    dec = Decoder(**kw)
    got = []
    for i in range(0, len(data), read):
        got += dec.feed(data[i:i + read])
    return got + dec.flush(), dec


def as_sent(frames) -> list:
    """What the board sent: the wire's fields (no stream offset, no receiver flags)."""
    return [(f.type, f.seq, f.t0, f.chan, f.flags & 0xFF, f.payload, f.t0_unwrapped) for f in frames]


def again_under_new_seqs(frames, blocks: tuple[int, ...]) -> tuple[bytes, list]:
    """``frames`` with the frames of ``blocks`` (indices of t0 / 250) sent again at once under the
    next seqs, and the frames it holds without them (numbered as sent)."""
    out, taken, seq, block = [], [], frames[0].seq, []
    for i, f in enumerate(frames):
        block.append(f)
        if i + 1 < len(frames) and frames[i + 1].t0 == f.t0:
            continue
        for g in block:
            taken.append(g._replace(seq=seq & 0xFFFF))
            seq += 1
        out += taken[-len(block):]
        if f.t0 // 250 in blocks:
            out += [g._replace(seq=(seq + k) & 0xFFFF) for k, g in enumerate(block)]
            seq += len(block)
        block = []
    return wire(out), taken


SENT = board_frames(overrun_blocks=(3,))

#: name -> (the stream, what was sent, frames lost, frames repeated, [(seq of the frame marked, repeats)])
STREAMS = {
    "one frame twice, every 97th": (
        b"".join(wire([f]) * (2 if i % 97 == 5 else 1) for i, f in enumerate(SENT)), SENT, 0, 29,
        [(SENT[i + 1].seq, 1) for i in range(5, len(SENT) - 1, 97)]),
    "50 frames again": (wire(SENT[:300] + SENT[250:300] + SENT[300:]), SENT, 0, 50, [(SENT[300].seq, 50)]),
    "30 older frames again": (wire(SENT[:300] + SENT[250:280] + SENT[300:]), SENT, 0, 30, [(SENT[300].seq, 30)]),
    "frames again, then 3 lost": (wire(SENT[:300] + SENT[250:300] + SENT[303:]), SENT[:300] + SENT[303:], 3, 50,
                                  [(SENT[303].seq, 50)]),
    "the overrun frame twice": (wire(SENT[:8] + SENT[7:8] + SENT[8:]), SENT, 0, 1, [(SENT[8].seq, 1)]),
}
_DATA, _TAKEN = again_under_new_seqs(SENT, (3, 100, 101, 700))
#: blocks 3 (its RAW frame flagged overrun), 100 and 700 (with a STATUS) and 101 sent again under new seqs
STREAMS["blocks again under new seqs"] = (
    _DATA, _TAKEN, 0, 10,
    [(next(f.seq for f in _TAKEN if f.t0 == (b + 1) * 250), n) for b, n in ((3, 2), (100, 3), (101, 2), (700, 3))])


@pytest.mark.parametrize("decoder", DECODERS)
@pytest.mark.parametrize("name", STREAMS)
def test_a_frame_received_again_is_dropped_counted_and_marked_on_the_next(name, decoder):
    """Every receiver (frame by frame, numpy runs, the compiled kernel) at every read size gives
    the frames the board sent, the counters of the stream without the repeats but for the repeats'
    bytes (discarded) and ``frames_repeated``, and marks the frame after them with their number."""
    data, sent, lost, repeated, marks = STREAMS[name]
    clean = iter_frames(wire(sent))[1]
    for read in READS:
        got, dec = decoded(data, read, **DECODERS[decoder])
        c = dec.counters
        assert as_sent(got) == as_sent(sent), read
        assert [(f.seq, f.flags >> 8) for f in got if f.flags > 0xFF] == marks, read
        assert c.frames == clean.frames and c.overruns == clean.overruns == 1
        assert (c.frames_lost, c.frames_repeated) == (lost, repeated)
        assert c.bytes_received == len(data)
        assert c.bytes_discarded == len(data) - sum(OVERHEAD + len(f.payload) for f in got) > 0
        assert [f.lost_before for f in got if f.lost_before] == ([lost] if lost else [])


def test_a_board_restarting_under_old_seqs_is_no_repeat():
    """A board that restarts 6 frames after its start sends new frames under the seqs it used:
    the ones that differ are taken (the restart's seq gap is there for the Processor to see), a
    frame the very same as before (its first STATUS) is the only one dropped."""
    first = SENT[:6]
    again = [f._replace(payload=bytes(reversed(f.payload))) if f.type == FrameType.RAW else f for f in SENT[:40]]
    for read in READS:
        got, dec = decoded(wire(first + again), read)
        assert as_sent(got) == as_sent(first + again[1:]), read
        assert dec.counters.frames_repeated == 1 and got[6].flags >> 8 == 1
        assert got[6].seq == again[1].seq and got[6].lost_before == (again[1].seq - first[-1].seq - 1) % 65536


def repeated(sent: list, seq: str) -> tuple[bytes, list, list[tuple[int, int]]]:
    """The stream of ``sent`` with frames again (``seq``: "same": every 97th frame at once under its
    seq; "new": blocks 3, 100, 101 and 700 under the next seqs), the frames it holds without them,
    and (repeats, seq of the frame after them) of each run of repeats."""
    if seq == "same":
        return (b"".join(wire([f]) * (2 if i % 97 == 5 else 1) for i, f in enumerate(sent)), sent,
                [(1, sent[i + 1].seq) for i in range(5, len(sent) - 1, 97)])
    data, taken = again_under_new_seqs(sent, (3, 100, 101, 700))
    runs = [(sum(f.t0 == b * 250 for f in taken), next(f.seq for f in taken if f.t0 == (b + 1) * 250))
            for b in (3, 100, 101, 700)]
    return data, taken, runs


@pytest.mark.parametrize("seq", ["same", "new"])
@pytest.mark.parametrize("mode", ["raw", "rms"])
def test_repeats_give_the_messages_of_the_stream_without_them_at_any_read_size(mode, seq):
    """Frames received again, under their seq or the next, change no data message at any read size:
    the messages of the stream without them, and one `frames_repeated` event where each run of
    repeats was (guards against, under their seq, a `frames_lost` of 65535 and a `time_base`
    re-anchoring each; under the next a `config` re-anchoring, the block observed twice and, with
    RAW, the order tracker restarted)."""
    data, sent, runs = repeated(SENT if mode == "raw" else board_frames("rms"), seq)
    want = by_topic(wire([f._replace(seq=i) for i, f in enumerate(sent)]), 65_536)     # numbered on
    for read in READS:
        got = by_topic(data, read)
        events = got.pop("/cm/events")
        got.pop("/cm/log")
        assert got == {t: m for t, m in want.items() if t not in ("/cm/events", "/cm/log")}, read
        repeats = [(s, m) for s, m in events if m["kind"] == "frames_repeated"]
        assert [(s, m) for s, m in events if m["kind"] != "frames_repeated"] == want["/cm/events"]
        assert [(m["message"], m["count"]) for _, m in repeats] == [
            (f"{n} frame(s) received again before seq {after} (the same frames as already received): dropped", n)
            for n, after in runs]


@pytest.mark.parametrize("new_seq", [False, True])
def test_replay_of_a_capture_whose_board_sent_blocks_twice(tmp_path, new_seq):
    """`cmsensord replay` of a firmware_sim capture whose board sent two blocks twice, under their
    seqs or the next (block 200: a STATUS, a RAW and a TACHO frame; block 250: a RAW and a TACHO
    frame): one event each naming the frames, no frame lost, no re-anchoring, the repeats on the
    summary's link line and in the diagnostics; the messages of the capture without them."""
    again = ["--resend-blocks", "200,250"] + (["--resend-new-seq"] if new_seq else [])
    for name, extra in (("twice", again), ("clean", [])):
        made = run_module("firmware_sim", "--scenario", "healthy", "--mode", "raw", "--tacho", "--duration", "6",
                          "--out", str(tmp_path / f"{name}.bin"), *extra)
        assert made.returncode == 0, made.stderr
    runs = {}
    for name in ("twice", "clean"):
        r = cmsensord("replay", str(tmp_path / f"{name}.bin"), "--out", str(tmp_path / name))
        assert r.returncode == 0, r.stderr
        runs[name] = (r.stderr, read_messages(next((tmp_path / name).glob("*.mcap"))))
    stderr, messages = runs["twice"]
    taken = iter_frames((tmp_path / "twice.bin").read_bytes())[0]
    after = [next(f.seq for f in taken if f.t0 == (b + 1) * 250) for b in (200, 250)]
    assert [f.flags >> 8 for f in taken if f.flags > 0xFF] == [3, 2]
    events = [m for t, _, m in messages if t == "/cm/events"]
    assert [m["message"] for m in events if m["kind"] == "frames_repeated"] == [
        f"3 frame(s) received again before seq {after[0]} (the same frames as already received): dropped",
        f"2 frame(s) received again before seq {after[1]} (the same frames as already received): dropped"]
    assert not [m for m in events if m["kind"] in ("frames_lost", "time_base")]
    assert "  events: config 2, frames_repeated 2\n" in stderr and " 0 frames lost)" in stderr
    assert "bad header(s), 5 frame(s) received twice)" in stderr
    link = [m["link"] for t, _, m in messages if t == "/cm/diagnostics"][-1]
    assert (link["frames_repeated"], link["frames_lost"], link["frames_raw"]) == (5, 0, 600)
    assert comparable([m for m in messages if m[0] != "/cm/diagnostics"
                       and not (m[0] in ("/cm/events", "/cm/log") and "received again" in json.dumps(m[2]))]) \
        == comparable([m for m in runs["clean"][1] if m[0] != "/cm/diagnostics"])


@pytest.mark.parametrize("mode", ["rms", "raw"])
def test_frames_received_again_at_the_end_of_a_capture_are_told(tmp_path, mode):
    """A capture whose last three frames came twice (a retried write at the end): one event at the
    end of the stream naming them; no frame came after them to carry the count, and nothing said so
    (the link counted them, the events did not)."""
    frames = board_frames(mode, 5)
    cap = tmp_path / "twice.bin"
    cap.write_bytes(wire(frames) + wire(frames[-3:]))
    r = cmsensord("replay", str(cap), "--out", str(tmp_path / "logs"))
    assert r.returncode == 0, r.stderr
    events = [m for t, _, m in read_messages(next((tmp_path / "logs").glob("*.mcap"))) if t == "/cm/events"]
    assert [m["message"] for m in events if m["kind"] == "frames_repeated"] == [
        "3 frame(s) received again at the end of the stream (the same frames as already received): dropped"]
    assert "3 frame(s) received twice)" in r.stderr and not [m for m in events if m["kind"] == "frames_lost"]


@pytest.mark.parametrize("new_seq", [False, True])
def test_a_live_board_sending_blocks_twice_is_told_and_replay_matches_live(tmp_path, new_seq):
    """firmware_sim on a real pty sends blocks 1550 and 2250 (an RMS frame each) and 2800 (a STATUS
    and an RMS frame) twice, under their seqs or the next: the live daemon logs one
    `frames_repeated` event for each, loses no frame, and the replay of its capture gives its
    messages."""
    board_then_daemon(tmp_path, "--scenario", "faulty", "--channels", "2", "--duration", "30", "--speed", "5",
                      "--seed", "3", "--resend-blocks", "1550,2250,2800", *(["--resend-new-seq"] if new_seq else []))
    sent = iter_frames(Board(make_scenario("faulty", n_channels=2, duration_s=30.0, seed=3),
                             BoardConfig(n_channels=2, resent_blocks=(1550, 2250, 2800),
                                         resend_new_seq=new_seq)).generate(30.0))[0]
    after = [next(f.seq for f in sent if f.t0 == (b + 1) * 250) for b in (1550, 2250, 2800)]
    live = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    events = [m for t, _, m in live if t == "/cm/events"]
    assert [m["message"] for m in events if m["kind"] == "frames_repeated"] == [
        f"{n} frame(s) received again before seq {s} (the same frames as already received): dropped"
        for n, s in zip((1, 1, 2), after)]
    assert not [m for m in events if m["kind"] in ("frames_lost", "time_base")]
    assert [m["link"]["frames_repeated"] for t, _, m in live if t == "/cm/diagnostics"][-1] == 4
    r = cmsensord("replay", str(tmp_path / "cap.bin"), "--out", str(tmp_path / "replay"))
    assert r.returncode == 0, r.stderr
    assert comparable(live) == comparable(read_messages(next((tmp_path / "replay").glob("*.mcap"))))
