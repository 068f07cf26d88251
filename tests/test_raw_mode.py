"""RAW mode: the daemon computes the board's RMS itself, so RMS and RAW mode agree."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cmsensord.config import config_from_dict, default_config
from cmsensord.dsp.rms import block_rms, rows_rms
from cmsensord.monitor.processor import Processor
from cmsensord.protocol import Decoder, FrameType
from cmsensord.sinks.memory import ListSink
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from stream import run_processor


def messages(mode, scenario="faulty", seconds=40.0, channels=2, seed=3, skip_bytes=0, cfg=None):
    sc = make_scenario(scenario, n_channels=channels, duration_s=seconds, seed=seed)
    data = Board(sc, BoardConfig(n_channels=channels, mode=mode)).generate(seconds)[skip_bytes:]
    sink, proc, _ = run_processor(data, cfg or default_config(channels), chunk=50_000)
    return sink, proc


def severity_and_events(sink):
    return [(t, s, m) for t, s, m in sink.messages
            if t.endswith("/severity") or (t == "/cm/events" and m["kind"] != "config")]


@pytest.mark.parametrize("scenario", ["faulty", "degrading"])
def test_rms_and_raw_mode_give_the_same_severity_messages(scenario):
    rms, _ = messages("rms", scenario)
    raw, proc = messages("raw", scenario)
    a, b = severity_and_events(rms), severity_and_events(raw)
    assert len([m for m in a if m[0] == "/cm/ch1/severity"]) == 40
    assert any(m["severity_index"] > 0 for t, _, m in a if t.endswith("/severity"))
    assert a == b
    assert proc.observations == 2 * 40 * 100


def test_rows_rms_equals_block_rms():
    rng = np.random.default_rng(0)
    counts = rng.integers(0, 4096, size=(3, 2500)).astype(np.uint16)
    scale = np.array([0.1, 0.05, 0.2], np.float32)
    offset = np.array([2048, 2000, 2100], np.float32)
    per_block = block_rms(counts, scale, offset, 250)
    rows = counts.reshape(30, 250)
    np.testing.assert_array_equal(rows_rms(rows, np.repeat(scale, 10), np.repeat(offset, 10)),
                                  per_block.reshape(-1))
    x = (counts[1, :250].astype(float) - 2000) * float(np.float32(0.05))
    assert per_block[1, 0] == np.float32(np.sqrt(np.mean(x * x)))


def test_raw_frames_before_the_first_status_wait_for_it():
    """Joining mid-stream: RAW blocks before the first STATUS are kept until it arrives."""
    sc = make_scenario("healthy", n_channels=1, duration_s=5, seed=0)
    board = Board(sc, BoardConfig(n_channels=1, mode="raw"))
    data = board.generate(5.0)
    start = data.index(b"\xa5\x5a", 600)          # somewhere in the first second, after STATUS
    sink, proc = messages("raw", "healthy", seconds=5.0, channels=1, seed=0, skip_bytes=start)
    assert proc.raw.dropped == 0
    assert proc.observations == proc.next_slot     # every block from the first received on


def test_config_scale_offset_override_status():
    cfg = default_config(1)
    ch = dataclasses.replace(cfg.channels[0], scale=0.2, offset=2048.0)
    cfg = dataclasses.replace(cfg, channels=(ch,))
    a, _ = messages("raw", "faulty", seconds=5.0, channels=1, cfg=cfg)
    b, _ = messages("raw", "faulty", seconds=5.0, channels=1)
    sa = [m["outliers"] for t, _, m in a.messages if t.endswith("/severity")]
    sb = [m["outliers"] for t, _, m in b.messages if t.endswith("/severity")]
    assert sa != sb          # a different scale changes the observations


def test_a_lost_raw_frame_is_a_missing_observation_of_its_channel_only():
    sc = make_scenario("healthy", n_channels=2, duration_s=3, seed=0)
    data = Board(sc, BoardConfig(n_channels=2, mode="raw")).generate(3.0)
    frames = Decoder().feed(data)
    victim = next(f for f in frames if f.type == FrameType.RAW and f.t0 == 150 * 250 and f.chan == 1)
    cut = data[:victim.offset] + data[victim.offset + 18 + len(victim.payload):]
    sink = ListSink()
    proc = Processor(default_config(2), sink, clock_ns=lambda: 0)
    proc.handle(Decoder().feed(cut))
    proc.finish()
    sev0 = [m["missing"] for t, _, m in sink.messages if t == "/cm/ch0/severity"]
    sev1 = [m["missing"] for t, _, m in sink.messages if t == "/cm/ch1/severity"]
    assert sev0 == [0, 0, 0] and sev1 == [0, 1, 0]
    assert any(m["kind"] == "frames_lost" for t, _, m in sink.messages if t == "/cm/events")


def test_a_microphone_channel_is_not_order_tracked(tmp_path):
    """RAW + tacho with an accelerometer and a microphone: orders of the accelerometer only
    (the microphone's Pa are not a vibration; it has its own vibration estimate)."""
    from cmsensord.acoustic_calib import fit_model, save_calibration

    sc = make_scenario("degrading_mic", n_channels=2, duration_s=60.0, seed=3)
    obs = Board(sc, BoardConfig(n_channels=2, scale=sc.board_scale)).observations(6000)[1].astype(float)
    bg_sc = make_scenario("degrading_mic", n_channels=2, duration_s=30.0, seed=4, machine_off=True)
    bg = Board(bg_sc, BoardConfig(n_channels=2, scale=bg_sc.board_scale)).observations(3000)[1].astype(float)
    cal = tmp_path / "mic.json"
    save_calibration(fit_model(obs[:, 0] ** 2, obs[:, 1] ** 2, bg[:, 1] ** 2), cal)
    cfg = config_from_dict({"channels": [{"name": "acc"}, {"name": "mic", "kind": "microphone"}],
                            "acoustic": {"calibration": str(cal)}})
    data = Board(sc, BoardConfig(n_channels=2, mode="raw", tacho=True, scale=sc.board_scale)).generate(3.0)
    sink, _, _ = run_processor(data, cfg)
    topics = {t for t, _, _ in sink.messages}
    assert "/cm/acc/orders" in topics and "/cm/mic/vibration_estimate" in topics
    assert "/cm/mic/orders" not in topics
