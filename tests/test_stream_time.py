"""Time and memory against what the board sends: resets, t0 stuck or jumping, a STATUS
changing the rate, frames of the other mode, more channels than a configuration names,
a board clock running fast.  Each case is one small capture (or a board on a pty) run
through a real ``cmsensord`` process: it exits 0, says what happened in the exact event
line, its stamps never go backwards and it stays under 100 MB resident."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
import time

import numpy as np

from cmsensord.config import config_from_dict
from cmsensord.protocol import (
    MODE_RAW,
    MODE_RMS,
    Decoder,
    FrameType,
    Status,
    decode_status,
    encode_frame,
    encode_raw,
    encode_rms,
    encode_status,
)
from cmsensord.sinks.mcap_sink import read_messages
from processes import ENV, run_module, start_board, start_daemon, stop
from stream import run_processor

MB = 1024          # ru_maxrss is in kB


def status(c=1, mode=MODE_RMS, fs=25000, block_len=250) -> Status:
    return Status(0x0102, mode, c, fs, block_len, 0, 1, 0, 0, (1.0,) * c, (0.0,) * c)


def rms_run(seq: int, t0s, c=1, st: Status | None = None) -> tuple[bytes, int]:
    """A STATUS (when ``st``) then one RMS frame per t0: (bytes, next seq)."""
    rng = np.random.default_rng(seq)
    out = bytearray()
    if st is not None:
        out += encode_status(seq, int(t0s[0]), st)
        seq += 1
    for t in t0s:
        out += encode_rms(seq, int(t), 0.5 + 0.01 * rng.standard_normal(c))
        seq += 1
    return bytes(out), seq


def blocks(n, start=0, step=250):
    return [start + k * step for k in range(n)]


def replay(tmp_path, data: bytes):
    """``cmsensord replay`` of ``data`` in a process of its own: (completed process with its
    stderr, the MCAP messages, its peak resident kB)."""
    cap = tmp_path / "cap.bin"
    cap.write_bytes(data)
    wrapper = ("import resource, subprocess, sys\n"
               "r = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
               "sys.stderr.write(r.stderr)\n"
               "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
               "sys.exit(r.returncode)\n")
    p = subprocess.run([sys.executable, "-c", wrapper, sys.executable, "-m", "cmsensord", "replay",
                        str(cap), "--out", str(tmp_path / "out")], capture_output=True, text=True,
                       env=ENV, timeout=60)
    msgs = [m for f in sorted((tmp_path / "out").glob("*.mcap")) for m in read_messages(f)]
    return p, msgs, int(p.stdout.split()[-1])


def assert_time_goes_on(msgs) -> None:
    """Every channel's decisions strictly later than the one before, in the order written."""
    topics = {t for t, _, _ in msgs if t.endswith("/severity")}
    assert topics
    for topic in topics:
        stamps = [s for t, s, _ in msgs if t == topic]
        assert all(b > a for a, b in zip(stamps, stamps[1:])), topic


def events(msgs, kind):
    return [(s, m) for t, s, m in msgs if t == "/cm/events" and m["kind"] == kind]


def said(msgs, kind) -> list[str]:
    """The messages of the events of ``kind``."""
    return [m["message"] for _, m in events(msgs, kind)]


# ---- item 1: a board reset ---------------------------------------------------------------
def test_a_board_reset_starts_a_new_segment_with_no_bogus_loss_in_replay(tmp_path):
    first, seq = rms_run(0, blocks(3000), st=status())
    again, _ = rms_run(0, blocks(3000), st=status())          # the board restarted: seq and t0 from 0
    p, msgs, rss = replay(tmp_path, first + again)
    assert p.returncode == 0, p.stderr
    assert ("WARNING time_base: board clock restarted (t0 0 after 749750): time segment 1 starts "
            "at the wall clock; the seq gap of 62535 in front of it is not a loss (seq restarted)"
            in p.stderr)
    assert "frames_lost" not in p.stderr and not events(msgs, "frames_lost")
    assert "(6000 observations, 0 missing, 0 frames lost)" in p.stderr
    (stamp, ev), = events(msgs, "time_base")
    assert ev["details"] == {"segment": 1, "reason": "reset"}
    diag = [m for t, _, m in msgs if t == "/cm/diagnostics"]
    assert diag[-1]["link"]["frames_lost"] == 0          # the link's counter leaves the restart out too
    assert_time_goes_on(msgs)
    sev = [s for t, s, _ in msgs if t == "/cm/ch0/severity"]
    assert sum(s < stamp for s in sev) >= 28 and sum(s > stamp for s in sev) >= 28
    assert rss < 100 * MB


def replugged(tmp_path, first_s: float, then_s: float, *board: str) -> tuple[str, list, int]:
    """Live: a board (firmware_sim ``board`` arguments) runs ``first_s``, goes away and comes back
    restarted (t0 and seq from 0) on the same name for ``then_s``: the daemon's stderr, its
    messages, and the wall clock when the board came back."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--speed", "1", *board, "--link", str(link))
    d = start_daemon(tmp_path, link)
    time.sleep(first_s)
    sim.terminate()
    sim.wait(timeout=5)
    back = time.time_ns()
    sim = start_board("--scenario", "healthy", "--speed", "1", *board, "--link", str(link), "--seed", "1")
    time.sleep(then_s)
    err = stop(d)
    sim.terminate()
    sim.wait(timeout=5)
    assert d.returncode == 0, err
    return err, read_messages(next((tmp_path / "logs").glob("*.mcap"))), back


def test_a_replugged_board_that_restarted_is_a_new_segment_from_the_wall_clock(tmp_path):
    """Live: the board goes away and comes back restarted (t0 and seq from 0) on the same
    name: a time_base event stamped from the wall clock when it is read, no frames_lost, and
    the decisions after it are stamped later than every one before."""
    _, msgs, back = replugged(tmp_path, 2.5, 4.0)
    (stamp, ev), = events(msgs, "time_base")
    assert re.fullmatch(r"board clock restarted \(t0 \d+ after \d+\): time segment 1 starts at the "
                        r"wall clock(; the seq gap of \d+ in front of it is not a loss \(seq restarted\))?",
                        ev["message"]), ev["message"]
    assert back < stamp < back + 5e9      # the wall clock when the restarted board was read
    assert not events(msgs, "frames_lost")
    assert_time_goes_on(msgs)
    assert sum(s > stamp for t, s, _ in msgs if t == "/cm/ch0/severity") >= 1


def raw_capture(tmp_path, seconds: float) -> bytes:
    """A simulated board in RAW mode with a tacho, 1 channel, from t0 and seq 0."""
    cap = tmp_path / f"raw{seconds:g}.bin"
    p = subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "healthy", "--mode", "raw",
                        "--tacho", "--duration", str(seconds), "--out", str(cap)],
                       capture_output=True, text=True, env=ENV, timeout=60)
    assert p.returncode == 0, p.stderr
    return cap.read_bytes()


def test_a_board_reset_restarts_the_shaft_speed_and_the_order_tracker(tmp_path):
    """A board with a tacho restarts (t0 and seq from 0): the shaft speed and the order tracker
    start again with it, so the same 6 s sent again give the same orders and speeds.  Guards
    against every TACHO frame after the reset dropped as "before the newest one in board time" until
    the board's clock passes its uptime before the reset: no speed and no valid order for as
    long as the board had run."""
    one = raw_capture(tmp_path, 6.0)
    p, msgs, rss = replay(tmp_path, one + one)
    assert p.returncode == 0, p.stderr
    assert "not after the newest one in board time" not in p.stderr
    assert not events(msgs, "decode_error")
    (stamp, _), = events(msgs, "time_base")
    hello = [m for m in said(msgs, "config") if m.startswith("order tracker: ")]
    assert len(hello) == 2 and hello[0] == hello[1]
    orders = [(s, m) for t, s, m in msgs if t == "/cm/ch0/orders"]
    before = [(m["valid"], m["speed_rpm"], m["orders"]) for s, m in orders if s < stamp]
    after = [(m["valid"], m["speed_rpm"], m["orders"]) for s, m in orders if s >= stamp]
    assert len(before) == len(after) == 60
    assert sum(v for v, _, _ in before) >= 55
    assert after == before
    speeds = [m["speed_rpm"] for t, _, m in msgs if t == "/cm/ch0/indicators"]
    assert len(speeds) == 12 and None not in speeds and speeds[6:] == speeds[:6]
    assert rss < 100 * MB


def test_a_board_reset_with_a_tacho_gives_the_same_messages_however_the_stream_is_read(tmp_path):
    """Chunk-split invariance across the reset: reads of 997 bytes, 64 kB and the whole stream
    give every topic's messages alike (not /cm/diagnostics, which tells how the stream was read;
    the topics interleave as the parts release them)."""
    data = raw_capture(tmp_path, 3.0) * 2
    cfg = config_from_dict({})
    runs = []
    for chunk in (997, 65_536, len(data)):
        topics: dict[str, list] = {}
        for topic, stamp, msg in run_processor(data, cfg, chunk=chunk)[0].messages:
            if topic != "/cm/diagnostics":
                topics.setdefault(topic, []).append((stamp, msg))
        runs.append(topics)
    assert [m["kind"] for _, m in runs[0]["/cm/events"]].count("time_base") == 1
    assert sum(m["valid"] for _, m in runs[0]["/cm/ch0/orders"]) >= 50
    assert runs[1] == runs[0] and runs[2] == runs[0]


def restated(data: bytes, seq: int, **status) -> bytes:
    """``data`` with its STATUS frames announcing the fields ``status`` and its seq numbers from
    ``seq`` on."""
    out = bytearray()
    for k, f in enumerate(Decoder().feed(data)):
        n = (seq + k) & 0xFFFF
        if f.type == FrameType.STATUS:
            out += encode_status(n, f.t0, dataclasses.replace(decode_status(f.payload), **status))
        else:
            out += encode_frame(f.type, n, f.t0, f.chan, f.flags, f.payload)
    return bytes(out)


def at_rate(data: bytes, fs: int, seq: int) -> bytes:
    """``data`` with its STATUS frames announcing ``fs`` and its seq numbers from ``seq`` on."""
    return restated(data, seq, fs=fs)


def board_goes_on(tmp_path, first_s: float, then_s: float, **status) -> bytes:
    """:func:`raw_capture` of ``first_s`` and ``then_s`` more of the board, its STATUS frames then
    announcing ``status``."""
    first = raw_capture(tmp_path, first_s)
    more = subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "healthy", "--mode", "raw", "--tacho",
                           "--duration", str(then_s), "--t0-start", str(round(25_000 * first_s)),
                           "--out", str(tmp_path / "more.bin")], capture_output=True, text=True, env=ENV, timeout=60)
    assert more.returncode == 0, more.stderr
    return first + restated((tmp_path / "more.bin").read_bytes(), len(Decoder().feed(first)), **status)


def test_a_board_changing_its_scale_is_told_and_the_blocks_before_keep_the_old_one(tmp_path):
    """The board's gain changes at 6 s (STATUS scale 0.02 m/s² per count, its counts as before): the config
    event names the change, the intervals before it keep the old scale (guards against a replay converting the
    RAW blocks waiting when it comes with the new one: seconds of them) and those after take the new."""
    p, msgs, _ = replay(tmp_path, board_goes_on(tmp_path, 6.0, 6.0, scale=(0.02,)))
    assert p.returncode == 0, p.stderr
    assert said(msgs, "config")[2:] == [
        "board changed the calibration of channel 0 (scale 0.09576806 -> 0.02 m/s² per count, offset 2048 -> 2048 "
        "counts): RAW samples from here on are converted with it"]
    accel = [m["accel_rms"] for t, _, m in msgs if t == "/cm/ch0/indicators"]
    assert len(accel) == 12
    assert all(0.6 < v < 0.8 for v in accel[:6]), accel
    assert all(abs(v / w - 0.02 / 0.09576806) < 0.02 for v, w in zip(accel[6:], accel)), accel


def test_a_board_changing_its_tacho_pulses_per_revolution_starts_the_shaft_speed_again(tmp_path):
    """The board says at 6 s that its tacho gives 2 pulses a revolution (its edges as before: the shaft at half
    the speed): the config event names it and the shaft speed starts again on 2 pulses (guards against the tracker
    going on counting 1: 1720 rpm)."""
    p, msgs, _ = replay(tmp_path, board_goes_on(tmp_path, 6.0, 6.0, tacho_ppr=2))
    assert p.returncode == 0, p.stderr
    assert [m.split(", tacho of ")[1] for m in said(msgs, "config") if m.startswith("board firmware")] == [
        "1 pulse(s) per revolution", "2 pulse(s) per revolution"]
    speeds = [m["speed_rpm"] for t, _, m in msgs if t == "/cm/ch0/indicators"]
    assert len(speeds) == 12
    assert all(abs(v - 1720) < 5 for v in speeds[:6]) and all(abs(v - 860) < 3 for v in speeds[6:]), speeds
    assert not [k for k in ("tacho_missed_pulse", "tacho_extra_pulse") if events(msgs, k)]


def test_a_board_changing_fs_restarts_the_shaft_speed_at_the_new_rate(tmp_path):
    """The board goes on at half the rate (STATUS fs 12500), its t0 counting on: the shaft speed
    and the order tracker start again at the new rate, so the same tacho edges in samples are
    half the speed.  Guards against the tracker made at 25 kHz going on reading them at 25 kHz (1720 rpm
    where the board says 860) and the order chain keeping its 25-kHz decimation."""
    first = raw_capture(tmp_path, 6.0)
    again = subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "healthy", "--mode", "raw",
                            "--tacho", "--duration", "6", "--t0-start", "150000", "--out", str(tmp_path / "b.bin")],
                           capture_output=True, text=True, env=ENV, timeout=60)
    assert again.returncode == 0, again.stderr
    p, msgs, _ = replay(tmp_path, first + at_rate((tmp_path / "b.bin").read_bytes(), 12500,
                                                  len(Decoder().feed(first))))
    assert p.returncode == 0, p.stderr
    assert not events(msgs, "frames_lost") and not events(msgs, "decode_error")
    assert "board changed fs/block_len to 12500/250: time base re-anchored" in said(msgs, "config")
    hello = [m.split(",")[1] for m in said(msgs, "config") if m.startswith("order tracker: ")]
    assert hello == [" decimation 20 to 1250 Hz", " decimation 10 to 1250 Hz"]
    speeds = [m["speed_rpm"] for t, _, m in msgs if t == "/cm/ch0/indicators"]
    assert len(speeds) == 18          # 6 s at 25 kHz, then 12 board seconds at 12.5 kHz
    assert all(abs(v - 1720) < 5 for v in speeds[:6]) and all(abs(v - 860) < 3 for v in speeds[6:])
    orders = [m for t, _, m in msgs if t == "/cm/ch0/orders"]
    assert len(orders) == 180
    late = [m["speed_rpm"] for m in orders[70:] if m["valid"]]
    assert len(late) >= 100 and all(abs(v - 860) < 3 for v in late)


def test_a_replugged_raw_board_that_restarted_gets_its_shaft_speed_at_once(tmp_path):
    """Live: a RAW board with a tacho runs 5 s, goes away and comes back restarted on the same
    name for 3.5 s: valid orders come after the time_base event (before the fix none could
    before the new board's clock passed the 5 s of the old one)."""
    err, msgs, _ = replugged(tmp_path, 5.0, 3.5, "--mode", "raw", "--tacho")
    (stamp, _), = events(msgs, "time_base")
    assert "not after the newest one in board time" not in err
    valid_after = [m for t, s, m in msgs if t == "/cm/ch0/orders" and s > stamp and m["valid"]]
    assert len(valid_after) >= 10, len(valid_after)
    assert all(abs(m["speed_rpm"] - 1720) < 20 for m in valid_after)


def test_a_board_clock_running_fast_is_re_anchored_to_the_wall_clock(tmp_path):
    """Live on a pty: a board whose clock runs twice as fast as the wall clock (1 s of blocks
    every 0.5 s for 6.5 s): one time_base event says it ran ahead, and the stamps never go back."""
    master, slave = os.openpty()
    d = start_daemon(tmp_path, os.ttyname(slave), max_drift_s=2.0)
    try:
        time.sleep(1.0)                     # the daemon has opened the port
        seq, t0 = 0, 0
        for k in range(13):
            data, seq = rms_run(seq, blocks(100, start=t0), st=status() if k == 0 else None)
            t0 += 100 * 250
            os.write(master, data)
            time.sleep(0.5)
        err = stop(d)
    finally:
        os.close(master)
        os.close(slave)
    assert d.returncode == 0, err
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    (stamp, ev), = events(msgs, "time_base")
    assert re.fullmatch(r"board clock ahead of the wall clock by \d+\.\d s \(it runs at \d+ Hz for fs "
                        r"25000 Hz\): time segment 1 re-anchored to the wall clock", ev["message"])
    assert ev["details"]["reason"] == "drift" and ev["details"]["offset_s"] > 2.0
    assert 40000 < ev["details"]["rate_hz"] < 60000
    assert_time_goes_on(msgs)


# ---- item 3: stream content never ends the daemon ------------------------------------------
def test_a_t0_stuck_at_one_value_does_not_end_the_replay(tmp_path):
    data, _ = rms_run(0, [1000] * 3000, st=status())
    p, msgs, rss = replay(tmp_path, data)
    assert p.returncode == 0, p.stderr
    assert "Recursion" not in p.stderr and "Traceback" not in p.stderr
    assert "(3000 observations, 0 missing, 0 frames lost)" in p.stderr
    assert_time_goes_on(msgs)
    assert rss < 100 * MB


def taken(tmp_path, adc_s: float, timeout: float = 60.0) -> bool:
    """True once the daemon's status says it processed ``adc_s`` of ADC time and its queue is empty."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        time.sleep(0.5)
        p = run_module("cmsensord", "status", "--config", str(tmp_path / "cmsensord.yaml"))
        m = re.match(r"\[ *([0-9.]+) s\].* q 0 ", p.stdout)
        if m and float(m.group(1)) >= adc_s:
            return True
    return False


def test_a_t0_stuck_at_one_value_does_not_end_the_daemon(tmp_path):
    """Live on a pty: 3000 frames with one t0 (and a STATUS every 100): the daemon runs on,
    stops cleanly on SIGTERM, and its decisions are stamped one after the other."""
    master, slave = os.openpty()
    d = start_daemon(tmp_path, os.ttyname(slave))
    try:
        time.sleep(1.0)                     # the daemon has opened the port
        seq = 0
        for _ in range(30):
            data, seq = rms_run(seq, [1000] * 100, st=status())
            os.write(master, data)
        assert taken(tmp_path, 30.0), "the daemon did not take the 30 s of frames within 60 s"
        assert d.poll() is None
        err = stop(d)
    finally:
        os.close(master)
        os.close(slave)
    assert d.returncode == 0, err
    assert "Recursion" not in err and "Traceback" not in err and "output error" not in err
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    assert len([t for t, _, _ in msgs if t == "/cm/ch0/severity"]) >= 25
    assert_time_goes_on(msgs)


def test_nine_channels_without_a_channel_list_monitor_eight_and_say_so(tmp_path):
    data, _ = rms_run(0, blocks(3000), c=9, st=status(9))
    p, msgs, rss = replay(tmp_path, data)
    assert p.returncode == 0, p.stderr
    assert ("board sends 9 channels, more than the 8 a configuration can name: ch0..ch7 are "
            "monitored, the rest is not") in said(msgs, "config")
    assert {t for t, _, _ in msgs if t.endswith("/severity")} == {f"/cm/ch{i}/severity" for i in range(8)}
    assert_time_goes_on(msgs)


# ---- item 4: bounded memory ----------------------------------------------------------------
def test_t0_jumping_600_s_a_frame_invents_no_missing_observations(tmp_path):
    data, _ = rms_run(0, blocks(300, step=600 * 25000), st=status())
    p, msgs, rss = replay(tmp_path, data)
    assert p.returncode == 0, p.stderr
    assert "(300 observations, 0 missing, 0 frames lost)" in p.stderr
    assert ("board clock jumped 600.0 s ahead (t0 30000000 after 15000000): time base re-anchored"
            in said(msgs, "config"))
    assert len(said(msgs, "config")) == 300       # the STATUS's, and one per jump
    assert rss < 100 * MB


def test_a_gap_of_a_minute_inserts_at_most_10_s_of_missing_observations(tmp_path):
    data, _ = rms_run(0, blocks(1000) + blocks(1000, start=(1000 + 6000) * 250), st=status())
    p, msgs, rss = replay(tmp_path, data)
    assert p.returncode == 0, p.stderr
    assert "(2000 observations, 0 missing, 0 frames lost)" in p.stderr
    assert "board clock jumped 60.0 s ahead (t0 1750000 after 249750): time base re-anchored" in said(msgs, "config")
    assert_time_goes_on(msgs)


def test_a_status_announcing_fs_1_mid_stream_invents_no_missing_observations(tmp_path):
    a, seq = rms_run(0, blocks(3000), st=status())
    b, _ = rms_run(seq, blocks(3000, start=3000 * 250), st=status(fs=1, block_len=1))
    p, msgs, rss = replay(tmp_path, a + b)
    assert p.returncode == 0, p.stderr
    assert "board changed fs/block_len to 1/1: time base re-anchored" in said(msgs, "config")
    assert "(6000 observations, 0 missing, 0 frames lost)" in p.stderr
    assert_time_goes_on(msgs)
    assert rss < 100 * MB


def test_raw_frames_in_an_rms_stream_are_ignored_and_counted(tmp_path):
    a, seq = rms_run(0, blocks(1000), st=status())
    raw = b"".join(encode_raw(seq + k, 1000 * 250 + k * 250, 0, np.full(250, 100, np.uint16))
                   for k in range(500))
    b, _ = rms_run(seq + 500, blocks(1000, start=1000 * 250))
    p, msgs, rss = replay(tmp_path, a + raw + b)
    assert p.returncode == 0, p.stderr
    assert "WARNING decode_error: 500 RAW frame(s) ignored: the board is in RMS mode (STATUS)" in p.stderr
    assert "20.0 s of ADC time" in p.stderr and "(2000 observations, 0 missing, 0 frames lost)" in p.stderr
    assert_time_goes_on(msgs)


def test_rms_frames_in_a_raw_stream_are_ignored_and_counted(tmp_path):
    st = Status(0x0102, MODE_RAW, 1, 25000, 250, 0, 1, 0, 0, (0.01,), (2048.0,))
    rng = np.random.default_rng(0)
    out, seq = bytearray(encode_status(0, 0, st)), 1
    for k in range(2000):
        if 1000 <= k < 1100:
            out += encode_rms(seq, k * 250, [0.5])
        else:
            out += encode_raw(seq, k * 250, 0, (2048 + 50 * rng.standard_normal(250)).astype(np.uint16))
        seq += 1
    p, msgs, rss = replay(tmp_path, bytes(out))
    assert p.returncode == 0, p.stderr
    assert "WARNING decode_error: 100 RMS frame(s) ignored: the board is in RAW mode (STATUS)" in p.stderr
    assert "(1900 observations, 100 missing, 0 frames lost)" in p.stderr
    assert_time_goes_on(msgs)
    assert rss < 100 * MB


# ---- the same invariants under random time ---------------------------------------------------
def random_time_stream(n: int, seed: int) -> bytes:
    """``n`` valid-CRC frames of one channel whose t0 steps are random (on by a block, a few
    blocks, minutes, stuck, back), with STATUS frames of random mode, fs and block_len, and
    RMS and RAW frames mixed."""
    rng = np.random.default_rng(seed)
    out, t0 = bytearray(), 0
    steps = [250, 250, 250, 250, 500, 2500, 0, -250 * 100, 600 * 25000, 10**9]
    for seq in range(n):
        t0 = max(0, t0 + int(rng.choice(steps)))
        r = rng.random()
        if r < 0.02:
            fs, bl = int(rng.choice([1, 100, 25000, 10**6])), int(rng.choice([1, 10, 250, 4096]))
            out += encode_status(seq, t0, status(mode=int(rng.choice([MODE_RMS, MODE_RAW])), fs=fs,
                                                 block_len=bl))
        elif r < 0.8:
            out += encode_rms(seq, t0, [float(rng.choice([0.5, 1e30, np.nan, -1.0]))])
        else:
            out += encode_raw(seq, t0, 0, rng.integers(0, 4096, 250).astype(np.uint16))
    return bytes(out)


def test_random_time_keeps_the_replay_running_bounded_and_in_order(tmp_path):
    """Seeded: 3000 frames here, ``CMSENSORD_STREAM_FRAMES=100000`` for the long run."""
    n = int(os.environ.get("CMSENSORD_STREAM_FRAMES", "3000"))
    p, msgs, rss = replay(tmp_path, random_time_stream(n, seed=11))
    assert p.returncode == 0, p.stderr[-3000:]
    assert "Traceback" not in p.stderr
    assert rss < 100 * MB
    stamps = [s for t, s, _ in msgs if t.endswith("/severity")]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))


def test_tacho_frames_that_stop_coming_are_one_event_in_a_replay(tmp_path):
    """A RAW capture whose TACHO frames stop at 6 s, none lost (the seq numbers go on): `cmsensord replay`
    tells it once, 10 s of board time on, and the intervals after it have no speed (guards against no event
    and a "tacho" speed decaying from 1720 to 11 rpm)."""
    out, seq = bytearray(), 0
    for f in Decoder().feed(raw_capture(tmp_path, 20.0)):
        if f.type != FrameType.TACHO or f.t0 < 150_000:
            out += encode_frame(f.type, seq, f.t0, f.chan, f.flags, f.payload)
            seq += 1
    p, msgs, _ = replay(tmp_path, bytes(out))
    assert p.returncode == 0, p.stderr
    start = next(s for t, s, _ in msgs if t == "/cm/ch0/indicators") - 1_000_000_000     # the stamp of board time 0
    assert [(s - start, m["message"]) for s, m in events(msgs, "tacho_lost")] == [
        (16_000_000_000, "no TACHO frame of input 0 for 10 s of board time while the board sends data: no shaft "
                         "speed since sample 150000")]
    speeds = [m.get("speed_rpm") for t, _, m in msgs if t == "/cm/ch0/indicators"]
    assert len(speeds) == 20 and all(abs(v - 1720) < 5 for v in speeds[:6]) and speeds[6:] == [None] * 14
