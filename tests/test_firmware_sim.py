"""Specification tests of firmware_sim: scenarios, board framing, tacho, pty, faults, CLI."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import serial

from cmsensord.protocol import (
    FLAG_CLIPPED,
    FLAG_OVERRUN,
    MODE_RAW,
    Decoder,
    FrameType,
    decode_raw,
    decode_rms,
    decode_status,
    decode_tacho,
    iter_frames,
)
from firmware_sim import cli
from firmware_sim.board import Board, BoardConfig
from firmware_sim.faults import inject
from firmware_sim.pty_link import PtyEndpoint
from firmware_sim.scenarios import SCENARIOS, Scenario, make_scenario
from processes import ENV, spawn

FS = 25000
L = 250
U32 = 1 << 32


def _decode(data: bytes):
    frames, counters = iter_frames(data)
    assert counters.bytes_discarded == 0
    assert counters.crc_failures == 0
    return frames


def _velocity_rms_mm_s(acc: np.ndarray, fs: int = FS) -> float:
    """ISO 10816 velocity RMS (10-1000 Hz) by integration in the frequency domain."""
    n = acc.size
    spec = np.fft.rfft(acc)
    f = np.fft.rfftfreq(n, 1 / fs)
    band = (f >= 10) & (f <= 1000)
    vel = spec[band] / (2j * np.pi * f[band])
    return 1e3 * np.sqrt(2 * np.sum(np.abs(vel) ** 2) / n**2)


# --------------------------------------------------------------------------- scenarios

@pytest.mark.parametrize("name", list(SCENARIOS))
def test_samples_do_not_depend_on_chunking(name):
    sc = make_scenario(name, n_channels=2, seed=7, duration_s=10.0)
    whole = sc.samples(0, 50000)
    parts = np.concatenate([sc.samples(0, 12345), sc.samples(12345, 37655)], axis=1)
    assert whole.shape == (2, 50000)
    assert np.array_equal(whole, parts)
    # random access on a fresh instance (no cache) gives the same samples
    fresh = make_scenario(name, n_channels=2, seed=7, duration_s=10.0)
    assert np.array_equal(fresh.samples(30000, 20000), whole[:, 30000:])
    assert np.array_equal(fresh.samples(24999, 2), whole[:, 24999:25001])
    # channel c does not depend on how many channels the board has
    one = make_scenario(name, n_channels=1, seed=7, duration_s=10.0)
    assert np.array_equal(one.samples(0, 50000)[0], whole[0])


def test_make_scenario_rejects_unknown_names_and_params():
    with pytest.raises(ValueError, match="healthy.*faulty.*degrading.*spikes"):
        make_scenario("bearing")
    with pytest.raises(ValueError, match="impact_peek"):
        make_scenario("faulty", impact_peek=3.0)
    with pytest.raises(ValueError, match="n_channels"):
        make_scenario("healthy", n_channels=0)


def test_healthy_velocity_rms_is_good_and_faulty_is_unacceptable():
    healthy = make_scenario("healthy", seed=1).samples(0, 10 * FS)[0]
    faulty = make_scenario("faulty", seed=1).samples(0, 10 * FS)[0]
    v_h = _velocity_rms_mm_s(healthy)
    v_f = _velocity_rms_mm_s(faulty)
    assert 1.0 < v_h < 2.8
    assert v_f > 7.1
    # the bearing defect makes the faulty signal impulsive (kurtosis well above a sine's)
    hp = np.fft.irfft(np.fft.rfft(faulty) * (np.fft.rfftfreq(faulty.size, 1 / FS) > 2000), faulty.size)
    kurt = np.mean(hp**4) / np.mean(hp**2) ** 2
    assert kurt > 4.0


def test_faulty_impacts_repeat_at_bpfo():
    sc = make_scenario("faulty", seed=2, noise_rms=0.0, resonance_noise_rms=0.0,
                       v1x=0, v2x=0, v_line=0, fault_v1x=0, fault_v2x=0, fault_v3x=0)
    x = sc.samples(0, 4 * FS)[0]
    env = np.abs(x)  # envelope spectrum peak at BPFO = 3.58 x 28.66 Hz
    spec = np.abs(np.fft.rfft(env - env.mean()))
    f = np.fft.rfftfreq(env.size, 1 / FS)
    sel = (f > 20) & (f < 500)
    assert abs(f[sel][np.argmax(spec[sel])] - 3.58 * 28.66) < 1.0


def test_degrading_severity_shape_and_levels():
    dur = 200.0
    sc = make_scenario("degrading", duration_s=dur, seed=3)
    t = np.linspace(0, dur, 2001)
    s = sc.severity(t)
    assert np.all(s[t < sc.onset * dur] < 1e-9)
    assert abs(s[np.searchsorted(t, sc.faulty_at * dur)] - 1.0) < 1e-9
    t_peak = t[np.argmax(s)]
    assert (sc.peak_at - 0.05) * dur <= t_peak <= sc.peak_at * dur + 1e-9
    assert 1.3 <= s.max() <= 1.5
    assert s[-1] < s.max()
    assert s[-1] < 1.0
    # the 100 Hz RMS follows the knob: 2 s windows at 10 %, faulty, peak, 100 %
    board = Board(sc, BoardConfig())
    mean_rms = [board.observations(200, int(u * dur * 100) - 200)[1].mean()
                for u in (0.1, sc.faulty_at, sc.peak_at, 1.0)]
    assert mean_rms[1] > 2 * mean_rms[0]
    assert mean_rms[2] > mean_rms[1]
    assert mean_rms[3] < mean_rms[2]


def test_spikes_exactly_25_single_block_spikes_per_second():
    sc = make_scenario("spikes", seed=5, n_channels=2)
    board = Board(sc, BoardConfig(n_channels=2))
    _, rms = board.observations(20 * 100)
    for c, gain in enumerate((1.0, 0.8)):
        threshold = gain * np.sqrt(sc.base_rms * sc.spike_rms)
        high = rms[:, c] > threshold
        per_second = high.reshape(20, 100).sum(axis=1)
        assert np.all(per_second == 25)
        assert not np.any(high[1:] & high[:-1])  # single-block spikes
        truth = sc.severity((np.arange(2000) * L + 100) / FS) > 0.5
        assert np.array_equal(high, truth)


# --------------------------------------------------------------------------- board framing

def test_capture_bytes_are_deterministic_per_seed():
    a = Board(make_scenario("faulty", seed=11), BoardConfig()).generate(2.0)
    b = Board(make_scenario("faulty", seed=11), BoardConfig()).generate(2.0)
    c = Board(make_scenario("faulty", seed=12), BoardConfig()).generate(2.0)
    assert a == b
    assert a != c
    # the board's chunking does not change the bytes either
    board = Board(make_scenario("faulty", seed=11), BoardConfig())
    board.chunk_blocks = 37
    assert board.generate(2.0) == a


def test_rms_frames_match_protocol_formula_on_adc_counts():
    sc = make_scenario("faulty", n_channels=3, seed=4)
    cfg = BoardConfig(n_channels=3, scale=(0.03, 100 / 4096, 0.02), offset=(2040.0, 2048.0, 2050.5))
    board = Board(sc, cfg)
    n_blocks = 250
    frames = _decode(board.generate(n_blocks / 100))
    rms_frames = [f for f in frames if f.type == FrameType.RMS]
    assert len(rms_frames) == n_blocks
    got = np.stack([decode_rms(f) for f in rms_frames])
    status = decode_status(frames[0].payload)
    scale = np.array(status.scale)
    offset = np.array(status.offset)
    counts = board.counts(0, n_blocks * L)
    assert counts.dtype == np.uint16 and counts.max() <= 4095
    for b in range(n_blocks):
        blk = counts[:, b * L:(b + 1) * L].astype(np.float64)
        phys = (blk - offset[:, None]) * scale[:, None]
        expect = np.sqrt(np.mean(phys**2, axis=1)).astype(np.float32)
        assert np.array_equal(got[b], expect), b
        assert np.array_equal(board.rms_block_values(counts[:, b * L:(b + 1) * L]), expect)
    t0, obs = board.observations(n_blocks)
    assert np.array_equal(obs, got)
    assert np.array_equal(t0, np.arange(n_blocks) * L)


def test_status_seq_and_t0_across_u32_and_u16_wraps():
    t0_start = U32 - 30 * L - 17
    cfg = BoardConfig(n_channels=2, tacho=True, t0_start=t0_start, seq_start=65500)
    board = Board(make_scenario("healthy", n_channels=2, seed=1), cfg)
    frames = _decode(board.generate(3.0))
    seqs = np.array([f.seq for f in frames])
    assert seqs[0] == 65500
    assert np.all(np.diff(seqs) % 65536 == 1)
    assert all(f.lost_before == 0 for f in frames)
    status = [f for f in frames if f.type == FrameType.STATUS]
    rms = [f for f in frames if f.type == FrameType.RMS]
    tacho = [f for f in frames if f.type == FrameType.TACHO]
    assert len(rms) == len(tacho) == 300
    assert [f.t0_unwrapped for f in status] == [t0_start + b * L for b in (0, 100, 200)]
    assert frames[0].type == FrameType.STATUS
    assert all(f.t0 < U32 for f in frames)
    unwrapped = np.array([f.t0_unwrapped for f in rms])
    assert np.all(np.diff(unwrapped) == L)
    assert unwrapped[0] == t0_start
    assert any(f.t0 < L * 100 for f in rms)  # wrapped on the wire
    assert [f.t0 for f in rms] == [int(u % U32) for u in unwrapped]
    st = decode_status(status[1].payload)
    assert (st.n_channels, st.fs, st.block_len, st.tacho_inputs, st.tacho_ppr) == (2, FS, L, 1, 1)
    assert st.uptime_s == (t0_start + 100 * L) // FS
    # per block period: STATUS (every 100 blocks) then RMS then TACHO
    assert [f.type for f in frames[:4]] == [FrameType.STATUS, FrameType.RMS, FrameType.TACHO, FrameType.RMS]


def test_raw_mode_frames_carry_the_adc_counts():
    board = Board(make_scenario("faulty", n_channels=2, seed=9), BoardConfig(mode="raw", n_channels=2))
    frames = _decode(board.generate(1.0))
    assert decode_status(frames[0].payload).mode == MODE_RAW
    raw = [f for f in frames if f.type == FrameType.RAW]
    assert len(raw) == 200
    assert [f.chan for f in raw[:4]] == [0, 1, 0, 1]
    counts = board.counts(0, 100 * L)
    got = np.stack([np.concatenate([decode_raw(f.payload) for f in raw[c::2]]) for c in range(2)])
    assert np.array_equal(got, counts)


def test_clipped_and_overrun_flags():
    cfg = BoardConfig(scale=(0.002,), overrun_blocks=(5, 150))  # +-4 m/s^2 full scale: faulty clips
    board = Board(make_scenario("faulty", seed=1), cfg)
    frames = _decode(board.generate(2.0))
    rms = [f for f in frames if f.type == FrameType.RMS]
    counts = board.counts(0, 200 * L).reshape(200, L)
    clipped = ((counts == 0) | (counts == 4095)).any(axis=1)
    assert clipped.any() and not clipped.all()
    assert [bool(f.flags & FLAG_CLIPPED) for f in rms] == clipped.tolist()
    assert [i for i, f in enumerate(rms) if f.flags & FLAG_OVERRUN] == [5, 150]
    status = [decode_status(f.payload) for f in frames if f.type == FrameType.STATUS]
    assert [s.overruns for s in status] == [0, 1]


def test_write_capture_streams_the_same_bytes(tmp_path):
    board = Board(make_scenario("degrading", seed=2, duration_s=20.0), BoardConfig(tacho=True, ppr=2))
    path = tmp_path / "cap.bin"
    summary = board.write_capture(path, 5.0, chunk_blocks=64)
    data = path.read_bytes()
    assert data == board.generate(5.0)
    frames = _decode(data)
    assert summary == {"frames": len(frames), "bytes": len(data), "blocks": 500}


# --------------------------------------------------------------------------- tacho

def test_tacho_edges_of_a_constant_28_66_hz_shaft():
    board = Board(make_scenario("healthy", seed=0), BoardConfig(tacho=True, ppr=1))
    frames = _decode(board.generate(10.0))
    edges = []
    for f in frames:
        if f.type == FrameType.TACHO:
            off = decode_tacho(f.payload)
            assert np.all(off < L * 256)
            edges.extend(f.t0_unwrapped * 256 + off.astype(np.int64))
    edges = np.array(edges)
    assert len(edges) in (286, 287)
    spacing = np.diff(edges) / 256
    assert np.all(np.abs(spacing - FS / 28.66) <= 1 / 256)
    # ppr = 4: four times the edges, a quarter of the spacing
    b4 = Board(make_scenario("healthy", seed=0), BoardConfig(tacho=True, ppr=4))
    blk, off = b4.tacho_edges(0, 1000)
    e4 = blk.astype(np.int64) * L * 256 + off
    assert abs(len(e4) - 4 * len(edges)) <= 4
    assert np.all(np.abs(np.diff(e4) / 256 - FS / (4 * 28.66)) <= 1 / 256)


class _RunUp(Scenario):
    """A silent shaft accelerating from 10 Hz at 5 Hz/s: turns(t) = 10 t + 2.5 t^2."""

    name = "run-up"

    def shaft_hz(self, t):
        return 10.0 + 5.0 * np.asarray(t, dtype=np.float64)

    def severity(self, t):
        return np.zeros(np.shape(t))

    def _render(self, k):
        return np.zeros((self.n_channels, self.segment_len))


def test_tacho_edges_follow_the_integrated_shaft_speed():
    sc = _RunUp(duration_s=10.0)
    tt = np.array([0.0, 0.5, 1.0, 2.345, 7.0])
    assert np.allclose(sc.shaft_turns(tt), 10 * tt + 2.5 * tt**2, atol=1e-9, rtol=0)
    board = Board(sc, BoardConfig(tacho=True, ppr=3))
    frames = _decode(board.generate(4.0))
    edges = np.concatenate([f.t0 * 256 + decode_tacho(f.payload).astype(np.int64)
                            for f in frames if f.type == FrameType.TACHO]) / 256
    m = np.arange(edges.size)  # edge m at ppr * turns = m
    exact = FS * (-10.0 + np.sqrt(100.0 + 10.0 * m / 3)) / 5.0
    assert edges.size == 3 * (10 * 4 + 2.5 * 16)
    assert np.all((edges <= exact + 1e-6) & (exact - edges < 1 / 256 + 1e-6))
    # the angle does not depend on the order of requests (cached whole seconds)
    late_first = _RunUp(duration_s=10.0)
    t = np.linspace(0, 9.99, 777)
    late_first.shaft_turns(np.array([9.5]))
    assert np.array_equal(late_first.shaft_turns(t), sc.shaft_turns(t))


# --------------------------------------------------------------------------- pty

def test_pty_stream_is_paced_and_decodes_contiguously():
    board = Board(make_scenario("healthy", seed=1), BoardConfig(tacho=True))
    with PtyEndpoint() as ep:
        assert os.path.exists(ep.path)
        ser = serial.Serial(ep.path, timeout=0.05)
        stop = threading.Event()
        th = threading.Thread(target=ep.run, args=(board,),
                              kwargs=dict(speed=20.0, duration_s=40.0, stop=stop))
        t_start = time.monotonic()
        th.start()
        dec = Decoder()
        frames = []
        deadline = t_start + 15.0
        while time.monotonic() < deadline:
            data = ser.read(8192)
            if data:
                frames += dec.feed(data)
            elif not th.is_alive():
                break
        elapsed = time.monotonic() - t_start
        stop.set()
        th.join(5.0)
        ser.close()
    assert not th.is_alive()
    assert 2.0 <= elapsed < 12.0  # 40 s at 20x real time: the last block's deadline is at 2 s
    assert ep.stats.dropped_bytes == 0
    assert ep.stats.blocks == 4000
    assert dec.counters.bytes_discarded == 0 and dec.counters.crc_failures == 0
    assert len(frames) == 2 * 4000 + 40
    assert np.all(np.diff([f.seq for f in frames]) % 65536 == 1)
    rms_t0 = [f.t0_unwrapped for f in frames if f.type == FrameType.RMS]
    assert np.all(np.diff(rms_t0) == L)


def test_pty_without_reader_drops_bytes_and_never_blocks():
    board = Board(make_scenario("faulty", n_channels=2, seed=1), BoardConfig(mode="raw", n_channels=2))
    with PtyEndpoint() as ep:
        th = threading.Thread(target=ep.run, args=(board,), kwargs=dict(speed=0, duration_s=10.0))
        th.start()
        th.join(20.0)
        assert not th.is_alive()  # did not block on the full pty
        s = ep.stats
        assert s.blocks == 1000
        assert s.dropped_bytes > 0 and s.dropped_blocks > 0
        assert s.bytes_written + s.dropped_bytes == s.bytes_offered
        dropped_before = s.dropped_bytes
        # a reader arriving later (pyserial flushes the stale input on open) gets a live stream
        ser = serial.Serial(ep.path, timeout=0.05)
        while ser.read(65536):
            pass
        ep.run(Board(make_scenario("healthy", seed=2), BoardConfig()), speed=50.0, duration_s=2.0)
        fresh = ser.read(65536)
        ser.close()
    assert ep.stats.dropped_bytes == dropped_before  # nothing dropped with a reader
    frames = _decode(fresh)
    assert [f.seq for f in frames] == list(range(202))


def test_pty_with_flow_control_waits_for_a_slow_reader_and_drops_nothing():
    """--flow-control (the board under --simulate): a reader that falls behind slows the
    board down; every byte arrives, in order, as the capture writer would write them."""
    def board():
        return Board(make_scenario("faulty", n_channels=2, seed=1), BoardConfig(mode="raw", n_channels=2))

    with PtyEndpoint(flow_control=True) as ep:
        ser = serial.Serial(ep.path, timeout=0.05)
        th = threading.Thread(target=ep.run, args=(board(),), kwargs=dict(speed=0, duration_s=3.0))
        th.start()
        time.sleep(0.5)                                   # the reader is late: the pty fills up
        got = bytearray()
        while th.is_alive() or ser.in_waiting:
            got += ser.read(4096)
            time.sleep(0.002)                             # and slow: ~2 MB/s at most
        got += ser.read(65536)
        ser.close()
    assert ep.stats.dropped_bytes == 0 and ep.stats.blocks == 300
    assert ep.stats.stalled_s > 0.3                       # it did wait for the reader
    assert bytes(got) == board().generate(3.0)


def test_pty_board_with_hold_stops_at_sigterm_whenever_it_lands():
    """SIGTERM at any moment of a 10x stream (the pacing waits on the stop event a
    thousand times a second) ends the board at once; a signal handler setting that
    event could deadlock on the event's own lock (about 1 in 40 kills hung)."""
    for delay in np.linspace(0.05, 0.6, 6):
        sim = spawn([sys.executable, "-m", "firmware_sim", "--pty", "--hold", "--scenario",
                                "healthy", "--speed", "10"], stdout=subprocess.PIPE, text=True, env=ENV)
        assert sim.stdout is not None
        port = sim.stdout.readline().strip()
        fd = os.open(port, os.O_RDONLY | os.O_NOCTTY)
        try:
            time.sleep(delay)
            sim.terminate()
            try:
                code = sim.wait(timeout=5)
            except subprocess.TimeoutExpired:
                sim.kill()
                sim.wait()
                code = None
        finally:
            os.close(fd)
            sim.stdout.close()
        assert code == 0, f"the board did not stop within 5 s of SIGTERM {delay:.2f} s in"


# --------------------------------------------------------------------------- faults

def test_inject_records_faults_and_decoder_resynchronises():
    data = Board(make_scenario("healthy", seed=3), BoardConfig()).generate(5.0)
    bad, records = inject(data, rate=2e-3, seed=1)
    bad2, records2 = inject(data, rate=2e-3, seed=1)
    assert bad == bad2 and records == records2
    kinds = {r.kind for r in records}
    assert kinds == {"flip", "drop", "insert"}
    n_ins = sum(r.kind == "insert" for r in records)
    n_drop = sum(r.kind == "drop" for r in records)
    assert len(bad) == len(data) + n_ins - n_drop
    offsets = [r.offset for r in records]
    assert offsets == sorted(offsets)
    # replaying the records on the original gives the corrupted stream
    replay = bytearray()
    pos = 0
    for r in records:
        replay += data[pos:r.offset]
        if r.kind == "flip":
            replay.append(data[r.offset] ^ r.detail)
            pos = r.offset + 1
        elif r.kind == "drop":
            pos = r.offset + 1
        else:
            replay.append(r.detail)
            pos = r.offset
    replay += data[pos:]
    assert bytes(replay) == bad
    # exactly the frames no fault touched are recovered (an insert in front of a frame leaves it whole)
    good = _decode(data)
    starts = np.array([f.offset for f in good])
    ends = starts + 18 + np.array([len(f.payload) for f in good])
    hit = np.zeros(len(good), dtype=bool)
    for r in records:
        if r.kind == "insert":  # a byte put in front of data[offset]
            hit |= (starts < r.offset) & (r.offset < ends)
        else:
            hit |= (starts <= r.offset) & (r.offset < ends)
    frames, counters = iter_frames(bad)
    intact = {(f.seq, f.t0, f.payload) for f, h in zip(good, hit) if not h}
    assert {(f.seq, f.t0, f.payload) for f in frames} == intact
    assert counters.crc_failures + counters.header_rejects > 0


def test_inject_gap_and_arguments():
    data = bytes(range(256)) * 40
    out, rec = inject(data, rate=1e-3, seed=3, kinds=("gap",), max_gap=100)
    assert rec and all(r.kind == "gap" and 1 <= r.detail <= 100 for r in rec)
    assert len(out) == len(data) - sum(r.detail for r in rec)
    with pytest.raises(ValueError, match="known"):
        inject(data, rate=0.1, seed=0, kinds=("smash",))
    assert inject(data, rate=0.0, seed=0) == (data, [])


# --------------------------------------------------------------------------- CLI

def test_cli_out_list_and_errors(tmp_path, capsys):
    path = tmp_path / "c.bin"
    rc = cli.main(["--scenario", "spikes", "--duration", "3", "--tacho", "--t0-start", str(U32 - 100),
                   "--param", "spike_rms=5", "--out", str(path)])
    out = capsys.readouterr().out
    assert rc == 0
    assert out.count("\n") == 1 and "300 blocks" in out
    frames = _decode(path.read_bytes())
    assert frames[0].t0 == U32 - 100
    assert sum(f.type == FrameType.TACHO for f in frames) == 300

    assert cli.main(["--list"]) == 0
    listing = capsys.readouterr().out
    assert all(name in listing for name in SCENARIOS)

    for argv in (["--scenario", "nope", "--out", str(path)],
                 ["--scenario", "healthy", "--pty", "--out", str(path)],
                 ["--scenario", "healthy", "--channels", "9", "--out", str(path)],
                 ["--scenario", "healthy", "--param", "nope=1", "--out", str(path)],
                 ["--scenario", "healthy"],
                 ["--scenario", "healthy", "--resend-new-seq", "--out", str(path)],
                 ["--scenario", "healthy", "--resend-blocks", "3,-1", "--out", str(path)],
                 ["--bogus"]):
        assert cli.main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("firmware_sim: error:") and err.count("\n") == 1


def test_pty_board_with_start_on_stdin_sends_nothing_before_its_stdin_ends():
    """--start-on-stdin (how --simulate starts the board once its reader has opened the port):
    no byte before EOF on stdin, the stream after it; SIGTERM while it waits ends it (status 0)."""
    cmd = [sys.executable, "-m", "firmware_sim", "--pty", "--scenario", "healthy", "--start-on-stdin",
           "--duration", "1", "--speed", "5", "--hold"]
    sim = spawn(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=ENV)
    try:
        ser = serial.Serial(sim.stdout.readline().strip(), timeout=0.5)
        assert ser.read(1) == b""                    # waits: nothing in 0.5 s
        sim.stdin.close()
        assert len(ser.read(4096)) > 100             # and streams after EOF
        ser.close()
        sim.terminate()
        assert sim.wait(timeout=10) == 0
    finally:
        if sim.poll() is None:
            sim.kill()
    waiting = spawn(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=ENV)
    waiting.stdout.readline()
    waiting.terminate()
    assert waiting.wait(timeout=5) == 0


def test_help_gives_the_mode_every_scenario_defaults_to(tmp_path):
    """`python -m firmware_sim --scenario whirl --out f.bin` writes RMS frames without a tacho, as
    its --help says (cmsensord --simulate, not firmware_sim, runs the run-ups in RAW mode)."""
    from processes import run_module

    text = " ".join(run_module("firmware_sim", "--help").stdout.split())
    assert ("--mode {rms,raw} RMS frames or RAW blocks (default rms, for every scenario: the run-ups' orders "
            "need --mode raw --tacho, which cmsensord --simulate gives them)") in text
    assert "--tacho send a TACHO frame per block (default: none)" in text
    p = run_module("firmware_sim", "--scenario", "close_orders", "--duration", "1", "--out", str(tmp_path / "c.bin"))
    assert p.returncode == 0, p.stderr
    assert ", 1 ch, rms, 1 s, 100 blocks, 101 frames," in p.stdout, p.stdout
