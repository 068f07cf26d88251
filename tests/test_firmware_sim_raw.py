"""RAW mode end to end on the simulated board: the run-ups of Yeh, Pan & Le, truth files, tacho faults, link budget.

- `whirl` and `close_orders` RAW frames decode to counts whose physical values are the truth + noise;
- the truth file (`--truth`) holds t, rpm, turns and the components, consistent with order_signals;
- the TACHO frames of `whirl` give the run-up speed through TachoTracker;
- encoder faults (missed, extra, jitter) are injected as configured, deterministically per seed;
- RAW with a tacho for the motor scenarios (4 channels), clipping and overrun flags;
- link_budget equals docs/PROTOCOL.md's byte budget table and the CLI warns when the UART cannot carry the stream.
"""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.dsp.tacho import TachoTracker
from cmsensord.protocol import (
    FLAG_CLIPPED,
    FLAG_OVERRUN,
    MODE_RAW,
    Decoder,
    FrameType,
    decode_raw,
    decode_status,
    decode_tacho,
    iter_frames,
)
from firmware_sim import cli
from firmware_sim.board import Board, BoardConfig, link_budget, link_streams
from firmware_sim.order_signals import close_orders_runup, whirl_runup
from firmware_sim.scenarios import SCENARIOS, make_scenario, truth_key, write_truth

FS = 25000
L = 250


def _tacho_arrays(frames, chan: int = 0) -> tuple[np.ndarray, list[np.ndarray]]:
    """(t0_unwrapped (F,), [edge offsets]) of the TACHO frames of input ``chan`` among ``frames``:
    what TachoTracker.update takes."""
    tacho = [f for f in frames if f.type == FrameType.TACHO and f.chan == chan]
    return np.array([f.t0_unwrapped for f in tacho], dtype=np.int64), [decode_tacho(f.payload) for f in tacho]


def _decode(data: bytes):
    frames, counters = iter_frames(data)
    assert counters.bytes_discarded == 0 and counters.crc_failures == 0 and counters.frames_lost == 0
    return frames


def _raw_physical(frames, n_channels):
    """Physical values (C, n) of the RAW frames with the STATUS scale/offset, and the STATUS."""
    status = decode_status(next(f for f in frames if f.type == FrameType.STATUS).payload)
    raw = [f for f in frames if f.type == FrameType.RAW]
    counts = np.stack([np.concatenate([decode_raw(f.payload) for f in raw if f.chan == c])
                       for c in range(n_channels)])
    scale = np.array(status.scale)[:, None]
    offset = np.array(status.offset)[:, None]
    return (counts - offset) * scale, status


# --------------------------------------------------------------------------- scenarios

def test_runup_scenarios_are_registered_with_the_papers_durations():
    assert SCENARIOS["whirl"].natural_duration_s == 180.0
    assert SCENARIOS["close_orders"].natural_duration_s == 5.0
    sc = make_scenario("close_orders", duration_s=8.0)
    t = np.array([0.0, 2.5, 5.0, 7.9])
    assert np.allclose(sc.shaft_hz(t) * 60, [0, 1500, 3000, 3000])  # holds the top speed
    assert np.array_equal(sc.shaft_turns(t), close_orders_runup().turns(t))
    slow = make_scenario("whirl", time_scale=2.0)
    assert slow.runup_s == 360.0 and slow.shaft_hz(np.array([180.0]))[0] * 60 == pytest.approx(3500)
    assert make_scenario("whirl", runup_s=60.0).shaft_hz(np.array([60.0]))[0] * 60 == pytest.approx(7000)
    with pytest.raises(ValueError, match="runup_s or time_scale"):
        make_scenario("whirl", runup_s=60.0, time_scale=2.0)
    with pytest.raises(ValueError, match="noise"):
        make_scenario("close_orders", noise=-1.0)


def test_runup_samples_are_components_plus_scaled_noise():
    sc = make_scenario("close_orders", n_channels=2, seed=3, duration_s=6.0)
    x = sc.samples(0, 6 * FS)
    t = np.arange(6 * FS) / FS
    clean = close_orders_runup().clean(t)
    std = 0.05 * 2.0  # 5 % of the order-1 RMS (2 m/s^2)
    assert sc.noise_std == pytest.approx(std)
    for c, g in enumerate((1.0, 0.8)):
        resid = x[c] - g * clean
        assert abs(np.std(resid) / (g * std) - 1) < 0.02
        assert abs(np.mean(resid)) < 0.01
    quiet = make_scenario("close_orders", noise=0.0, duration_s=6.0)
    assert np.allclose(quiet.samples(0, 6 * FS)[0], clean, atol=1e-12, rtol=0)


# --------------------------------------------------------------------------- RAW frames vs truth

def test_close_orders_raw_frames_decode_to_truth_plus_noise(tmp_path):
    sc = make_scenario("close_orders", n_channels=2, seed=1, duration_s=5.0)
    board = Board(sc, BoardConfig(mode="raw", n_channels=2, tacho=True))
    frames = _decode(board.generate(5.0))
    phys, status = _raw_physical(frames, 2)
    assert status.mode == MODE_RAW and phys.shape == (2, 5 * FS)
    assert not any(f.flags & FLAG_CLIPPED for f in frames)  # peaks ~34 m/s^2 in a +-196 m/s^2 range
    path = tmp_path / "truth.npz"
    info = write_truth(sc, path, 5.0)
    truth = np.load(path)
    assert info["samples"] == 5 * FS
    assert list(truth["components"]) == ["order 1", "order 4", "order 4.2"]
    q = status.scale[0]
    # channel 0: the counts are the board's acceleration, quantised
    assert np.max(np.abs(phys[0] - truth["accel"])) <= q / 2 + 1e-4
    comps = sum(truth[truth_key(n)].astype(np.float64) for n in truth["components"])
    noise_std = float(truth["noise_std"])
    resid = phys[0] - comps
    assert abs(np.std(resid) / np.hypot(noise_std, q / np.sqrt(12)) - 1) < 0.03
    assert abs(np.mean(resid)) < 0.01
    # channel 1 (gain 0.8): its own noise, 0.8 x the components
    resid1 = phys[1] - 0.8 * comps
    assert abs(np.std(resid1) / np.hypot(0.8 * noise_std, q / np.sqrt(12)) - 1) < 0.03
    assert abs(np.corrcoef(resid, resid1)[0, 1]) < 0.02


def test_truth_file_is_consistent_with_order_signals(tmp_path):
    sc = make_scenario("whirl", duration_s=200.0)
    full = tmp_path / "full.npz"
    write_truth(sc, full, 2.0)
    d = np.load(full)
    n = 2 * FS
    assert d["t"].dtype == np.float64 and d["order_1"].dtype == np.float32 and d["t"].size == n
    assert np.array_equal(d["t"], np.arange(n) / FS)
    ru = whirl_runup()
    assert np.allclose(d["rpm"], ru.rpm(d["t"])) and np.allclose(d["turns"], ru.turns(d["t"]), rtol=0, atol=1e-12)
    for name, wave in ru.signals(d["t"]).items():
        assert np.allclose(d[truth_key(name)], wave, rtol=0, atol=1e-5)
    assert np.allclose(d["accel"], sc.samples(0, n)[0], rtol=0, atol=1e-5)
    # decimated: the paper's 2 kHz, analytic at t = n / 2000, after the run-up the top speed
    dec = tmp_path / "dec.npz"
    write_truth(sc, dec, 190.0, rate=2000.0)
    d2 = np.load(dec)
    assert d2["t"].size == 380000 and "accel" not in d2
    assert np.array_equal(d2["t"], np.arange(380000) / 2000.0)
    assert d2["rpm"][-1] == pytest.approx(7000) and float(d2["rate"]) == 2000.0
    assert np.allclose(d2["47_Hz"], ru.signals(d2["t"])["47 Hz"], rtol=0, atol=1e-5)
    with pytest.raises(ValueError, match="rate"):
        write_truth(sc, dec, 1.0, rate=50000.0)


def test_cli_writes_capture_and_truth_with_the_natural_duration(tmp_path, capsys):
    cap, truth = tmp_path / "cap.bin", tmp_path / "truth.npz"
    rc = cli.main(["--scenario", "close_orders", "--mode", "raw", "--tacho", "--out", str(cap),
                   "--truth", str(truth)])
    captured = capsys.readouterr()
    assert rc == 0 and "500 blocks" in captured.out and captured.err == ""
    frames = _decode(cap.read_bytes())
    assert sum(f.type == FrameType.RAW for f in frames) == 500
    assert sum(f.type == FrameType.TACHO for f in frames) == 500  # N = 0 frames included
    d = np.load(truth)
    assert d["t"].size == 5 * FS and {"order_1", "order_4", "order_4.2", "rpm", "turns"} <= set(d.files)
    phys, status = _raw_physical(frames, 1)
    assert np.max(np.abs(phys[0] - d["accel"])) <= status.scale[0] / 2 + 1e-4
    rc = cli.main(["--scenario", "close_orders", "--duration", "1", "--out", str(cap), "--truth", str(truth),
                   "--truth-rate", "2000"])
    assert rc == 0 and np.load(truth)["t"].size == 2000
    assert cli.main(["--scenario", "healthy", "--duration", "1", "--out", str(cap), "--truth-rate", "10"]) == 2
    assert "--truth-rate needs --truth" in capsys.readouterr().err


# --------------------------------------------------------------------------- tacho

def test_whirl_tacho_frames_give_the_runup_speed():
    sc = make_scenario("whirl", duration_s=180.0)
    board = Board(sc, BoardConfig(mode="raw", tacho=True))
    dec = Decoder()
    tr = TachoTracker(FS, 1, block_len=L)
    grid = np.arange(0, 180 * FS, 50)
    done = 0
    parts = []

    def feed(frames):  # as the daemon will: query what became final after each update
        nonlocal done
        u = tr.update(*_tacho_arrays(frames))
        s = grid[(grid >= done) & (grid < u.final_until)]
        parts.append((s, *tr.evaluate(s)))
        done = u.final_until

    buf = bytearray()
    for i, data in enumerate(board.iter_block_bytes(18000)):
        buf += data
        if (i + 1) % 500 == 0:
            feed(dec.feed(bytes(buf)))
            buf.clear()
    feed(dec.feed(bytes(buf)) + dec.flush())
    assert dec.counters.crc_failures == 0 and dec.counters.frames["tacho"] == 18000
    assert tr.counters.edges == 10500 and tr.counters.lost == 0  # 7000 rpm x 180 s / 2 = 10500 rev
    s, hz, turns, valid = (np.concatenate(x) for x in zip(*parts))
    assert s[-1] > 179.9 * FS
    true = sc.shaft_hz(s / FS)
    above = true * 60 > 300
    assert valid[above].all()
    assert np.max(np.abs(hz[above] - true[above]) / true[above]) < 1e-3
    assert np.max(np.abs(turns - sc.shaft_turns(s / FS))) < 1e-3


def test_tacho_faults_are_injected_as_configured():
    sc = make_scenario("healthy", seed=4)
    clean = Board(sc, BoardConfig(tacho=True)).tacho_pulses(0, 1000)
    assert clean["pulse"].tolist() == list(range(287)) and not clean["extra"].any()
    # listed pulses
    b = Board(sc, BoardConfig(tacho=True, tacho_missed=(5, 17), tacho_extra=(3,)))
    got = b.tacho_pulses(0, 1000)
    assert got["missed"].tolist() == [5, 17]
    real = got["edges"][~got["extra"]]
    assert np.array_equal(real, np.delete(clean["edges"], [5, 17]))
    (extra_at,) = got["edges"][got["extra"]]
    e3, e4 = clean["edges"][3], clean["edges"][4]
    assert e3 + 0.29 * (e4 - e3) < extra_at < e3 + 0.71 * (e4 - e3)
    blk, off = b.tacho_edges(0, 1000)
    assert np.array_equal(blk.astype(np.int64) * L * 256 + off, got["edges"])
    # probabilities and jitter
    cfg = dict(tacho=True, ppr=4, tacho_missed=0.05, tacho_extra=0.05, tacho_jitter=2.0)
    pb = Board(sc, BoardConfig(**cfg))
    got = pb.tacho_pulses(0, 6000)  # 60 s: 6878 pulses
    n = 4 * 28.66 * 60
    assert abs(got["missed"].size - 0.05 * n) < 4 * np.sqrt(0.05 * n)
    assert abs(got["extra"].sum() - 0.05 * n) < 4 * np.sqrt(0.05 * n)
    ref = Board(sc, BoardConfig(tacho=True, ppr=4)).tacho_pulses(0, 6000)
    real = ~got["extra"]
    dt = (got["edges"][real] - ref["edges"][np.isin(ref["pulse"], got["pulse"][real])]) / 256
    assert abs(np.std(dt) - 2.0) < 0.1 and abs(np.mean(dt)) < 0.1
    # deterministic per seed, independent of chunking, different for another seed
    again = Board(make_scenario("healthy", seed=4), BoardConfig(**cfg))
    parts = [again.tacho_edges(a, n) for a, n in ((0, 2500), (2500, 1), (2501, 3499))]
    assert np.array_equal(np.concatenate([p[0] for p in parts]), pb.tacho_edges(0, 6000)[0])
    assert np.array_equal(np.concatenate([p[1] for p in parts]), pb.tacho_edges(0, 6000)[1])
    other = Board(make_scenario("healthy", seed=5), BoardConfig(**cfg)).tacho_pulses(0, 6000)
    assert not np.array_equal(other["missed"], got["missed"])
    with pytest.raises(ValueError, match="tacho_missed"):
        BoardConfig(tacho_missed=1.5)
    with pytest.raises(ValueError, match="tacho_jitter"):
        BoardConfig(tacho_jitter=-1.0)


def test_cli_tacho_fault_flags_reach_the_frames(tmp_path):
    path = tmp_path / "f.bin"
    assert cli.main(["--scenario", "healthy", "--duration", "2", "--tacho", "--tacho-missed", "5,17",
                     "--tacho-extra", "0.1", "--tacho-jitter", "1", "--out", str(path)]) == 0
    frames = _decode(path.read_bytes())
    edges = np.concatenate([f.t0 * 256 + decode_tacho(f.payload).astype(np.int64)
                            for f in frames if f.type == FrameType.TACHO])
    b = Board(make_scenario("healthy", duration_s=2.0),
              BoardConfig(tacho=True, tacho_missed=(5, 17), tacho_extra=0.1, tacho_jitter=1.0))
    assert np.array_equal(edges, b.tacho_pulses(0, 200)["edges"])
    assert cli.main(["--scenario", "healthy", "--tacho-missed", "x", "--out", str(path)]) == 2


# --------------------------------------------------------------------------- RAW for the motor

def test_raw_motor_four_channels_with_tacho_clipping_and_overrun():
    sc = make_scenario("faulty", n_channels=4, seed=2)
    cfg = BoardConfig(mode="raw", n_channels=4, tacho=True, ppr=2, overrun_blocks=(3, 120),
                      scale=(0.096, 0.002, 0.096, 0.096))  # channel 1: +-4 m/s^2, clips the impacts
    board = Board(sc, cfg)
    frames = _decode(board.generate(2.0))
    types = [f.type for f in frames[:7]]
    assert types == [FrameType.STATUS] + [FrameType.RAW] * 4 + [FrameType.TACHO, FrameType.RAW]
    raw = [f for f in frames if f.type == FrameType.RAW]
    assert len(raw) == 800 and [f.chan for f in raw[:8]] == [0, 1, 2, 3] * 2
    counts = board.counts(0, 200 * L)
    for c in range(4):
        got = np.concatenate([decode_raw(f.payload) for f in raw[c::4]])
        assert np.array_equal(got, counts[c])
        blocks = counts[c].reshape(200, L)
        clipped = ((blocks == 0) | (blocks == 4095)).any(axis=1)
        assert [bool(f.flags & FLAG_CLIPPED) for f in raw[c::4]] == clipped.tolist()
        if c == 1:
            assert clipped.any() and not clipped.all()
        else:
            assert not clipped.any()
    over = [(i // 4, f.chan) for i, f in enumerate(raw) if f.flags & FLAG_OVERRUN]
    assert over == [(3, 0), (120, 0)]
    assert [decode_status(f.payload).overruns for f in frames if f.type == FrameType.STATUS] == [0, 1]
    tacho = [f for f in frames if f.type == FrameType.TACHO]
    assert len(tacho) == 200
    edges = np.concatenate([f.t0 * 256 + decode_tacho(f.payload).astype(np.int64) for f in tacho])
    blk, off = board.tacho_edges(0, 200)
    assert np.array_equal(edges, blk.astype(np.int64) * L * 256 + off)
    assert edges.size == int(2 * 28.66 * 2) + 1


# --------------------------------------------------------------------------- link budget

def test_link_budget_matches_the_protocol_table():
    assert link_streams("rms", 4)["rms"] == 3400  # 18 + 16 = 34 B x 100/s
    assert link_streams("raw", 1)["raw"] == 51800  # 18 + 500 = 518 B x 100/s
    assert link_streams("rms", 1, tacho=True)["tacho"] == 3600  # 18 + 2 + 16 = 36 B x 100/s
    assert link_streams("raw", 3)["status"] == 18 + 20 + 8 * 3
    total, fits, msg = link_budget("raw", 1, 250, 25000, True, 921600)
    assert total == 51800 + 3600 + 46 and fits and "fits" in msg
    total, fits, msg = link_budget("raw", 2, 250, 25000, True, 921600)
    assert total == 2 * 51800 + 3600 + 54 and not fits
    assert "does not fit" in msg and "92,160 B/s" in msg and "\n" not in msg
    assert link_budget("raw", 2, 250, 25000, True, 2_000_000)[1]
    assert link_budget("rms", 4, 250, 25000, True, 115200)[1]  # 7070 B/s of 11520
    assert not link_budget("rms", 8, 250, 25000, True, 57600)[1]  # 18 + 32 = 50 B x 100 + 3600 > 5760
    with pytest.raises(ValueError, match="mode"):
        link_budget("fast", 1, 250, 25000, False, 921600)


def test_cli_warns_when_the_uart_cannot_carry_the_stream(tmp_path, capsys):
    path = tmp_path / "c.bin"
    assert cli.main(["--scenario", "healthy", "--mode", "raw", "--tacho", "--duration", "0.2",
                     "--out", str(path)]) == 0
    assert capsys.readouterr().err == ""  # one raw channel fits 921600 baud
    assert cli.main(["--scenario", "healthy", "--mode", "raw", "--channels", "2", "--duration", "0.2",
                     "--out", str(path)]) == 0
    out = capsys.readouterr()
    assert out.err.count("\n") == 1 and out.err.startswith("firmware_sim: warning:")
    assert "921600-baud" in out.err and "would not carry" in out.err
    assert out.out.count("\n") == 1  # the summary line is unchanged
    assert cli.main(["--scenario", "healthy", "--mode", "raw", "--baud", "460800", "--duration", "0.2",
                     "--out", str(path)]) == 0
    assert "460800-baud" in capsys.readouterr().err
    assert cli.main(["--scenario", "healthy", "--mode", "raw", "--channels", "2", "--pty", "--duration", "0.05",
                     "--speed", "0"]) == 0
    out = capsys.readouterr()
    assert out.out.startswith("/dev/")
    assert "pty has no baud limit" in out.err and "real UART would not carry" in out.err
