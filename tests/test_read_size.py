"""A stream with a tacho (RAW or RMS mode) gives the same messages however it is read: reads of 997 bytes,
64 kB and 1 MiB give every topic's messages alike (not /cm/diagnostics, which tells how the
stream was read), and every RAW indicator interval and valid order its shaft speed.  Each stream holds what makes the
chains wait for the speed or start again: a link loss of a minute, a board clock jumping a minute,
board resets, a change of rate, a board slower than 25 kHz (one read then holds more board seconds
than the 10 s a wait for the speed lasts).  Guards against a large read letting the waits end
before the TACHO frames in front of them are fed: intervals and orders without a speed, or with
one that decays towards zero, and decisions on the configured f_r."""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.config import config_from_dict
from cmsensord.monitor.raw import RawBlocks
from cmsensord.protocol import Decoder, FrameType, encode_frame
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from stream import run_processor

READS = (997, 65_536, 1 << 20)
#: frames a second of a 1-channel board with a tacho: a data and a TACHO frame a block, a STATUS
FRAMES_PER_S = 201


def board(mode: str, seconds: float, *, fs: int = 25_000, t0: int = 0, seq: int = 0, channels: int = 1,
          ppr: int = 1, scale: tuple[float, ...] | None = None, tacho: bool = True, scenario: str = "healthy") -> bytes:
    """A healthy motor (or ``scenario``) at 1720 rpm on a board with a tacho (1 channel, 1 pulse per revolution
    and the board's default scale unless ``channels``, ``ppr``, ``scale``; no tacho unless ``tacho``)."""
    sc = make_scenario(scenario, n_channels=channels, duration_s=seconds, seed=1, fs=fs)
    cfg = BoardConfig(mode=mode, n_channels=channels, fs=fs, t0_start=t0, seq_start=seq & 0xFFFF, tacho=tacho,
                      ppr=ppr, scale=scale)
    return Board(sc, cfg).generate(seconds)


def frames(data: bytes) -> int:
    return len(Decoder().feed(data))


def link_loss(mode: str) -> bytes:
    first = board(mode, 6)
    return first + board(mode, 6, t0=150_000 + 60 * 25_000, seq=frames(first) + 60 * FRAMES_PER_S)


def clock_jump(mode: str) -> bytes:
    first = board(mode, 6)
    return first + board(mode, 6, t0=150_000 + 60 * 25_000, seq=frames(first))


def resets(mode: str) -> bytes:
    return board(mode, 14) * 3


def rate_change(mode: str) -> bytes:
    first = board(mode, 6)
    return first + board(mode, 12, fs=12_500, t0=150_000, seq=frames(first))


def slow_board(mode: str) -> bytes:
    return board(mode, 24, fs=12_500)


def channel_change(mode: str) -> bytes:
    first = board(mode, 6)
    return first + board(mode, 6, t0=150_000, seq=frames(first), channels=2)


def mode_switch(mode: str) -> bytes:
    first = board(mode, 6)
    return first + board("rms" if mode == "raw" else "raw", 6, t0=150_000, seq=frames(first))


def ppr_change(mode: str, before: int, after: int) -> bytes:
    first = board(mode, 6, ppr=before)
    return first + board(mode, 12, t0=150_000, seq=frames(first), ppr=after)


def calibration_change(mode: str) -> bytes:
    first = board(mode, 6)
    return first + board(mode, 6, t0=150_000, seq=frames(first), scale=(0.02,))


def tacho_goes(mode: str) -> bytes:
    first = board(mode, 6)
    return first + board(mode, 8, t0=150_000, seq=frames(first), tacho=False)


def tacho_stops(mode: str, seconds: float = 20, resume_s: float = 1e9) -> bytes:
    """``seconds`` of the board whose TACHO frames stop at 6 s (until ``resume_s``), the others
    numbered on (none lost)."""
    out, seq = bytearray(), 0
    for f in Decoder().feed(board(mode, seconds)):
        if f.type != FrameType.TACHO or not 150_000 <= f.t0 < resume_s * 25_000:
            out += encode_frame(f.type, seq, f.t0, f.chan, f.flags, f.payload)
            seq += 1
    return bytes(out)


def stuck_blocks(mode: str, seconds: float = 14, every: int = 150) -> bytes:
    """The board sends every ``every``-th block's data and TACHO frames a second time under its
    t0 (a t0 that stuck for a block), the data with other values (10 % more), numbered on."""
    out, seq, block = bytearray(), 0, []
    for f in Decoder().feed(board(mode, seconds)):
        block.append(f)
        if f.type == FrameType.TACHO:
            again = [g for g in block if g.type != FrameType.STATUS] if (f.t0 // 250) % every == 7 else []
            for g, stuck in [(g, False) for g in block] + [(g, True) for g in again]:
                payload = g.payload
                if stuck and g.type == FrameType.RMS:
                    payload = (np.frombuffer(payload, "<f4") * 1.1).astype("<f4").tobytes()
                elif stuck and g.type == FrameType.RAW:
                    payload = (np.frombuffer(payload, "<u2") // 2 + 1024).astype("<u2").tobytes()
                out += encode_frame(g.type, seq, g.t0, g.chan, g.flags, payload)
                seq += 1
            block = []
    return bytes(out)


def by_topic(data: bytes, read: int, config: dict | None = None) -> dict[str, list]:
    """The Processor's messages of ``data`` fed in reads of ``read`` bytes, by topic (but
    /cm/diagnostics); ``config``: the settings (default: the defaults)."""
    topics: dict[str, list] = {}
    for topic, stamp, msg in run_processor(data, config_from_dict(config or {}), chunk=read)[0].messages:
        if topic != "/cm/diagnostics":
            topics.setdefault(topic, []).append((stamp, msg))
    return topics


def same_at_every_read_size(data: bytes) -> list[dict[str, list]]:
    """The messages of ``data`` by topic at each read size, asserted alike, one record a stamp in
    time order, and every decision on the tacho's f_r (1720 rpm)."""
    runs = [by_topic(data, read) for read in READS]
    for topic in runs[0]:
        assert runs[1][topic] == runs[0][topic], (topic, READS[1])
        assert runs[2][topic] == runs[0][topic], (topic, READS[2])
    assert runs[1].keys() == runs[0].keys() == runs[2].keys()
    for topic in ("/cm/ch0/indicators", "/cm/ch0/severity"):
        stamps = [s for s, _ in runs[0][topic]]
        assert stamps == sorted(set(stamps)), topic          # one record a stamp, in time order
    f_r = [m["f_r"] for _, m in runs[0]["/cm/ch0/severity"]]
    assert len(f_r) >= 12 and all(abs(v - 1720 / 60) < 0.3 for v in f_r)
    return runs


@pytest.mark.parametrize("mode", ["raw", "rms"])
@pytest.mark.parametrize("make", [channel_change, mode_switch])
def test_a_status_changing_the_channels_or_the_mode_gives_the_same_messages_at_any_read_size(make, mode):
    """A STATUS that changes the channel count or the mode (not the rate): the TACHO frames in
    front of it are fed before the decisions and intervals it ends (a large read must not end
    them on a speed that has not seen those frames: 1612 or 478 rpm for 1720)."""
    runs = same_at_every_read_size(make(mode))
    raw = [m["speed_rpm"] for _, m in runs[0]["/cm/ch0/indicators"] if m["mode"] == "raw"]
    rms_only = make is channel_change and mode == "rms"
    assert len(raw) >= (0 if rms_only else 6) and all(abs(v - 1720) < 20 for v in raw), raw


def test_a_status_changing_the_calibration_converts_the_raw_blocks_before_it_with_the_old_one():
    """The board's scale goes from +-20 g full scale to 0.02 m/s² per count at 6 s (its counts change, not the
    vibration): at any read size the RAW blocks in front of the STATUS are converted with the old scale, so each
    interval's RMS is the board's own (RMS mode), and a config event tells the change.  Guards against the blocks
    waiting when it comes being converted with the new one: the newest block at any read size (0.676 for
    0.683 m/s²), seconds of them in a large read (0.14)."""
    raw, rms = (same_at_every_read_size(calibration_change(mode)) for mode in ("raw", "rms"))
    by_raw = {s: m["accel_rms"] for s, m in raw[0]["/cm/ch0/indicators"]}
    by_rms = {s: m["accel_rms"] for s, m in rms[0]["/cm/ch0/indicators"]}
    assert len(by_raw) == 12 and by_raw.keys() == by_rms.keys()
    assert all(abs(by_raw[s] - by_rms[s]) < 1e-3 for s in by_raw), (by_raw, by_rms)
    change = ("board changed the calibration of channel 0 (scale 0.09576806 -> 0.02 m/s² per count, "
              "offset 2048 -> 2048 counts)")
    for runs, then in ((raw, ": RAW samples from here on are converted with it"), (rms, "")):
        told = [(s, m["message"]) for s, m in runs[0]["/cm/events"] if "calibration" in m["message"]]
        assert told == [(6_000_000_000, change + then)]


@pytest.mark.parametrize("mode", ["raw", "rms"])
def test_tacho_frames_that_stop_coming_are_told_and_give_no_speed(mode):
    """The board announces a tacho but its TACHO frames stop at 6 s (none lost: no seq gap): once the data
    runs 10 s past the last one a tacho_lost event says so, and the intervals and orders let go after the
    longest wait have no speed (orders at 0 rpm, not valid), never the tracker's extrapolation (a "tacho" speed
    decaying from 1720 to 461, 101 ... 11 rpm) with nothing told."""
    runs = same_at_every_read_size(tacho_stops(mode))
    lost = [(s, m["message"]) for s, m in runs[0]["/cm/events"] if m["kind"] == "tacho_lost"]
    assert lost == [(16_000_000_000, "no TACHO frame of input 0 for 10 s of board time while the board sends data: "
                                     "no shaft speed since sample 150000")]
    if mode == "raw":
        speeds = [m.get("speed_rpm") for _, m in runs[0]["/cm/ch0/indicators"]]
        assert len(speeds) == 20 and all(abs(v - 1720) < 5 for v in speeds[:6]) and speeds[6:] == [None] * 14
        late = [(m["speed_rpm"], m["valid"]) for s, m in runs[0]["/cm/ch0/orders"] if s > 6.5e9]
        assert len(late) == 135 and set(late) == {(0.0, False)}


@pytest.mark.parametrize("mode", ["raw", "rms"])
def test_tacho_frames_that_come_again_after_a_silence_give_the_same_messages_at_any_read_size(mode):
    """The TACHO frames stop at 6 s and come again at 18 s.  A small read lets go what waited 10 s before
    they come, a large one after: the speed there is none either way (a silence of 10 s or more is no
    speed whenever it is asked for), and the silence is told once, by the same event.  Guards against the
    orders of the half second after the last edge having 0 rpm at one read size and a decaying speed at
    another (valid, 1573 to 395 rpm), a large read's intervals a decaying "tacho" speed, and the event
    being the tracker's at one read size and the shaft's at another."""
    runs = same_at_every_read_size(tacho_stops(mode, 24, resume_s=18))
    told = [(s, m["kind"]) for s, m in runs[0]["/cm/events"] if m["kind"].startswith("tacho")]
    assert [k for _, k in told] == ["tacho_lost", "tacho_restored"] and told[0][0] == 16_000_000_000
    if mode == "raw":
        orders = [(s, m["speed_rpm"], m["valid"]) for s, m in runs[0]["/cm/ch0/orders"]]
        assert all((v, ok) == (0.0, False) for s, v, ok in orders if 6.1e9 < s < 18e9)     # blocks of 0.1 s
        assert all(ok and abs(v - 1720) < 20 for s, v, ok in orders if s > 18.15e9)


def test_a_tacho_input_the_board_does_not_use_is_told_with_the_inputs_it_does():
    """``tacho.input: 1`` on a board whose TACHO frames come on input 0: 10 s of board time on, one
    tacho_lost event names both (guards against no speed and no word why)."""
    cfg = config_from_dict({"tacho": {"input": 1}})
    runs = [[(s, m["message"]) for t, s, m in run_processor(board("raw", 14), cfg, chunk=read)[0].messages
             if t == "/cm/events" and m["kind"] == "tacho_lost"] for read in READS]
    assert runs == [[(10_000_000_000, "no TACHO frame of input 1 for 10 s of board time while the board sends "
                      "data: no shaft speed since sample 0 (TACHO frames come on input 0: see tacho.input)")]] * 3


@pytest.mark.parametrize("mode", ["raw", "rms"])
def test_a_status_announcing_no_tacho_ends_the_shaft_speed(mode):
    """The board says at 6 s that it has no tacho (and sends no TACHO frame): the shaft speed and the
    order tracker end there, and an event says so; the intervals after it have no speed.  Guards against
    the tracker going on with no edge: intervals with a tacho speed decaying from 1720 to 461, 101, 60 rpm
    and orders to the end of the stream."""
    runs = same_at_every_read_size(tacho_goes(mode))
    told = [(s, m["message"]) for s, m in runs[0]["/cm/events"] if "tacho now" in m["message"]]
    assert told == [(6_000_000_000, "the board has no tacho now: no shaft speed, no orders, decisions on the "
                                    "configured f_r")]
    if mode == "raw":
        speeds = [m.get("speed_rpm") for _, m in runs[0]["/cm/ch0/indicators"]]
        assert len(speeds) == 14 and all(abs(v - 1720) < 5 for v in speeds[:6]) and speeds[6:] == [None] * 8
        assert max(s for s, _ in runs[0]["/cm/ch0/orders"]) < 6e9


@pytest.mark.parametrize("mode", ["raw", "rms"])
@pytest.mark.parametrize(("before", "after"), [(1, 2), (2, 1)])
def test_a_status_changing_the_tacho_pulses_per_revolution_starts_the_shaft_speed_again(mode, before, after):
    """The board's tacho goes from ``before`` to ``after`` pulses per revolution: the shaft speed starts
    again counting ``after`` (guards against it going on counting ``before``: every second pulse removed as spurious,
    29 events a second, or a missed pulse every revolution), and the config event says so."""
    runs = same_at_every_read_size(ppr_change(mode, before, after))
    events = [m for _, m in runs[0]["/cm/events"]]
    assert [e["kind"] for e in events if e["kind"].startswith("tacho")] == []
    told = [e["message"].split(", tacho of ")[1] for e in events if "tacho of" in e["message"]]
    assert told == [f"{before} pulse(s) per revolution", f"{after} pulse(s) per revolution"]
    if mode == "raw":
        orders = [(s, m["speed_rpm"]) for s, m in runs[0]["/cm/ch0/orders"] if m["valid"]]
        assert len(orders) >= 160 and all(abs(v - 1720) < 20 for _, v in orders)
        assert max(s for s, _ in orders) > 17e9


@pytest.mark.parametrize("mode", ["raw", "rms"])
@pytest.mark.parametrize("make", [link_loss, clock_jump, resets, rate_change, slow_board])
def test_the_messages_do_not_depend_on_the_read_size(make, mode):
    runs = same_at_every_read_size(make(mode))
    if mode == "rms":
        return
    speeds = [m.get("speed_rpm") for _, m in runs[0]["/cm/ch0/indicators"]]
    assert len(speeds) >= 12 and all(v is not None and abs(v - 1720) < 20 for v in speeds), speeds
    orders = [m["speed_rpm"] for _, m in runs[0]["/cm/ch0/orders"] if m["valid"]]
    assert len(orders) >= 100 and all(abs(v - 1720) < 20 for v in orders)


@pytest.mark.parametrize("shuffled", [False, True])
def test_raw_pieces_hold_the_blocks_of_the_whole(shuffled):
    """RawBlocks.pieces: runs cut into pieces of at most 2 blocks, each with the samples and block
    RMS of its blocks in the whole (frames in block order: views; shuffled: the masked path)."""
    rng = np.random.default_rng(0)
    t0 = np.array([0, 250, 500, 1000, 1250], dtype=np.int64)      # a lost block between 500 and 1000
    row = np.array([0, 0, 1, 1, 2, 3, 3, 4, 4])                    # block 2 lost its channel 1 frame
    chan = np.array([0, 1, 0, 1, 0, 0, 1, 0, 1])
    x = rng.standard_normal((len(row), 250))
    if shuffled:
        order = rng.permutation(len(row))
        row, chan, x = row[order], chan[order], x[order]
    whole = RawBlocks(t0, row, chan, x, 2)
    pieces = whole.pieces(2)
    assert [p.t0.tolist() for p in pieces] == [[0, 250], [500], [1000, 1250]]
    first = [0, 2, 3]
    for p, a in zip(pieces, first):
        b = a + len(p.t0)
        np.testing.assert_array_equal(p.samples([0, 1]), whole.samples([0, 1])[a:b])
        np.testing.assert_array_equal(p.rms(), whole.rms()[a:b])


def test_an_rms_block_again_under_its_t0_gives_the_same_messages_at_any_read_size():
    """RMS blocks whose t0 stuck (another RMS frame under the t0 of the one before): each is an
    observation of its own, a block later (one `config` event: the time base re-anchored), at
    any read size, and the RMS indicators leave it out (guards against a `missing_fraction` of -0.01,
    the block counted twice, and intervals stamped 10 ms apart at other read sizes)."""
    runs = same_at_every_read_size(stuck_blocks("rms"))
    jumps = [m for _, m in runs[0]["/cm/events"] if m["message"].endswith("time base re-anchored")]
    assert len(jumps) == 10
    missing = [m["missing_fraction"] for _, m in runs[0]["/cm/ch0/indicators"]]
    assert len(missing) >= 13 and all(0.0 <= v <= 1.0 for v in missing), missing


def reset_into_raw_and_back(rms_s: float = 10) -> bytes:
    """A 1-channel RMS board with no tacho for ``rms_s``, reset into 2 RAW channels with a tacho (a faulty
    machine: anomaly events in its first seconds) for 6 s, reset into 3 RMS channels for 10 s whose t0
    starts 67296 samples before its wrap at 2^32 (a step back of 217046 from the newest)."""
    return (board("rms", rms_s, tacho=False) + board("raw", 6, channels=2, scenario="faulty")
            + board("rms", 10, channels=3, tacho=False, t0=2**32 - 67_296))


def test_a_reset_into_raw_with_a_tacho_and_back_gives_the_same_messages_at_any_read_size():
    """Across two resets that change the mode and the channels, every topic's messages are alike at every
    read size, and the order tracker's config event is stamped at its first sample, the reset, ahead of
    the anomaly events of the decisions after it.  Guards against a 1-MiB read making the tracker after its
    first blocks' decisions have let the events before them go: its event written at 13 s, after those."""
    runs = [by_topic(reset_into_raw_and_back(), read) for read in READS]
    assert runs[1] == runs[0] and runs[2] == runs[0]
    told = [(s, m["kind"], m["message"].split(":")[0]) for s, m in runs[0]["/cm/events"]]
    assert told[1:9] == [(10_000_000_000, "time_base", "board clock restarted (t0 0 after 249750)"),
                         (10_000_000_000, "config", "board firmware 1.0"),
                         (10_000_000_000, "channels", "board now sends 2 channel(s), not 1"),
                         (10_000_000_000, "config", "order tracker"),
                         (11_000_000_000, "anomaly_onset", "ch0"),
                         (11_000_000_000, "anomaly_onset", "ch0"),
                         (11_000_000_000, "severity_change", "ch0"),
                         (13_000_000_000, "anomaly_onset", "ch0")]
    assert [(s, m) for s, k, m in told if k == "time_base"][1][0] == 16_000_000_000
    assert sum(m["valid"] for _, m in runs[0]["/cm/ch0/orders"]) == 59


def off_grid(data: bytes, strays: dict[int, tuple[str, int]]) -> bytes:
    """``data`` with a RAW frame of channel 0 (counts of garbage) under a t0 off the block grid at each block k of
    ``strays``: (where, off) puts it ``off`` samples past block k's t0, ``after`` the block's RAW frames (of 2
    channels), ``between`` its channels 0 and 1, or ``before`` them; the frames numbered on (no seq gap)."""
    rng = np.random.default_rng(5)
    frames = []
    for f in Decoder().feed(data):
        where, off = strays.get(f.t0 // 250, ("", 0)) if f.type == FrameType.RAW else ("", 0)
        stray = (FrameType.RAW, f.t0 + off, 0, 0, rng.integers(0, 4096, 250).astype("<u2").tobytes())
        frames += [stray] * (where == "before" and f.chan == 0) + [(f.type, f.t0, f.chan, f.flags, f.payload)]
        frames += [stray] * (where == "between" and f.chan == 0 or where == "after" and f.chan == 1)
    return b"".join(encode_frame(kind, seq & 0xFFFF, *rest) for seq, (kind, *rest) in enumerate(frames))


def test_stray_raw_frames_off_the_grid_give_the_boards_messages_at_any_read_size():
    """12 s of a 2-channel RAW board with a tacho and valid-CRC RAW frames of garbage off the block grid: half a
    block past a block's t0 after its frames, 3 samples before it between its channels, half a block past it
    before them (ahead of the block's own frames): each is dropped with its decode_error at every read size,
    and every other topic is the board's without them (a frame a call, about, too, as live).  Guards against
    the blocks it splits or precedes being taken in two parts at some read sizes, and each re-anchoring the
    time base."""
    clean = board("raw", 12, channels=2)
    strays = {150: ("after", 125), 350: ("between", -3), 550: ("before", 125)}
    data = off_grid(clean, strays)
    runs = same_at_every_read_size(data)
    one = by_topic(data, 300)                           # a RAW frame a call, about
    assert one == runs[0]
    ref = by_topic(clean, READS[0])
    assert {t: m for t, m in runs[0].items() if t not in ("/cm/events", "/cm/log")} == \
        {t: m for t, m in ref.items() if t not in ("/cm/events", "/cm/log")}
    said = [m["message"] for _, m in runs[0]["/cm/events"] if m["kind"] == "decode_error"]
    assert said == [
        "RAW frame of channel 0 at t0 37625 dropped: t0 off the block grid by +125 sample(s) and in block 37500, "
        "the newest block taken (a stray frame: the time base is kept)",
        "RAW frame of channel 0 at t0 87497 dropped: t0 off the block grid by -3 sample(s) and in block 87250, "
        "behind the newest block 87500 (a stray frame: the time base is kept)",
        "RAW frame of channel 0 at t0 137625 dropped: t0 off the block grid by +125 sample(s) and in block 137500, "
        "which has frames on the grid (a stray frame: the time base is kept)"]


def test_a_jump_of_the_board_clock_off_the_grid_keeps_every_frame_at_any_read_size():
    """A 2-channel RAW board whose clock jumps 60 s and 100 samples (off the old grid, past the gap a block
    clock fills): the messages are alike at every read size, no decode_error and none missing; judged against
    the old grid, each block's second channel was a stray (1, 20 or 301 dropped as the reads went)."""
    first = board("raw", 6, channels=2)
    data = first + board("raw", 6, channels=2, t0=150_000 + 60 * 25_000 + 100, seq=frames(first))
    runs = same_at_every_read_size(data)
    assert not [m for _, m in runs[0]["/cm/events"] if m["kind"] == "decode_error"]
    for read in READS:
        proc = run_processor(data, config_from_dict({}), chunk=read)[1]
        assert (proc.observations, proc.missing_observations) == (1200, 0), read
