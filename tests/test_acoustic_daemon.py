"""Microphone channels in the daemon (Orimoto, Ikuta & Wang): configuration, calibration from
captures, /cm/<ch>/vibration_estimate, and monitoring a degrading machine by sound alone."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from cmsensord.acoustic_calib import (
    cross_term_variance,
    fit_captures,
    fit_model,
    load_calibration,
    save_calibration,
)
from cmsensord.config import config_from_dict, config_to_dict
from cmsensord.errors import ConfigError
from cmsensord.sinks.mcap_read import read_messages
from cmsensord.sinks.schemas import SCHEMAS
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from processes import cmsensord, run_module
from stream import run_processor


def board(name, seconds, *, seed=0, channels=2, mode="rms", **params):
    sc = make_scenario(name, n_channels=channels, seed=seed, duration_s=seconds, **params)
    return Board(sc, BoardConfig(mode=mode, n_channels=channels, scale=getattr(sc, "board_scale", None)))


def observations(name, seconds, seed, **params):
    return board(name, seconds, seed=seed, **params).observations(int(seconds * 100))[1].astype(np.float64)


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    """Calibrated on another machine's run: the degrading motor (seed 100, its whole range) with
    the microphone beside the accelerometer, and a minute of background (machine stopped)."""
    pair = observations("degrading_mic", 300.0, 100)
    bg = observations("degrading_mic", 60.0, 101, machine_off=True)
    path = tmp_path_factory.mktemp("cal") / "mic.json"
    save_calibration(fit_model(pair[:, 0] ** 2, pair[:, 1] ** 2, bg[:, 1] ** 2), path)
    return path


def mic_config(calibration, *, acc=True, **extra):
    chans = ([{"name": "acc"}] if acc else []) + [{"name": "mic", "index": 1 if acc else 0,
                                                     "kind": "microphone"}]
    return config_from_dict({"channels": chans, "acoustic": {"calibration": str(calibration)}, **extra})


# --------------------------------------------------------------------------- configuration

def test_microphone_channel_needs_a_loadable_calibration(tmp_path, calibration):
    with pytest.raises(ConfigError) as err:
        config_from_dict({"channels": [{"name": "mic", "kind": "microphone"}]}, source="site.yaml")
    assert str(err.value) == ("site.yaml: channels[0].kind: a microphone channel needs an acoustic "
                              "calibration file (acoustic.calibration or channels[0].calibration) "
                              "(got 'microphone')")
    bad = tmp_path / "bad.json"
    doc = json.loads(calibration.read_text())
    doc["model"]["G"] = -1.0
    bad.write_text(json.dumps(doc))
    with pytest.raises(ConfigError) as err:
        config_from_dict({"channels": [{"name": "mic", "kind": "microphone", "calibration": str(bad)}]},
                         source="site.yaml")
    assert str(err.value) == f"site.yaml: channels[0].calibration: {bad}: model.G: must be > 0, got -1.0"
    with pytest.raises(ConfigError, match=r"channels\[0\].kind: must be one of accelerometer, microphone"):
        config_from_dict({"channels": [{"name": "mic", "kind": "mic"}]})
    with pytest.raises(ConfigError, match="acoustic.zeta_max: must be > 0"):
        config_from_dict({"acoustic": {"zeta_max": 0}})
    cfg = mic_config(calibration)
    assert config_from_dict(config_to_dict(cfg)) == cfg
    assert [c.kind for c in cfg.channels] == ["accelerometer", "microphone"]


# --------------------------------------------------------------------------- calibration from captures

def _captures(tmp_path, mode):
    pair, bg = tmp_path / f"pair_{mode}.bin", tmp_path / f"bg_{mode}.bin"
    pb = board("healthy_mic", 8.0, seed=4, mode=mode)
    bb = board("healthy_mic", 6.0, seed=5, mode=mode, machine_off=True)
    pb.write_capture(pair, 8.0)
    bb.write_capture(bg, 6.0)
    return (pair, bg), (pb, bb)


def test_calibration_from_captures_is_the_same_in_rms_and_raw_mode(tmp_path):
    """The block energies are the same in both modes (z = RMS^2 of the board's block RMS), so the
    fits are identical when the cross term is left out; with it (RAW only) the models still have
    the same fitted moments of z given x and differ only in how var z splits into sound and noise."""
    paths = {mode: _captures(tmp_path, mode)[0] for mode in ("rms", "raw")}
    rms = fit_captures(*paths["rms"], accel=0, mic=1)
    raw0 = fit_captures(*paths["raw"], accel=0, mic=1, cross_var=0.0)
    assert rms.model == raw0.model
    assert rms.model.block_s == 0.01 and rms.info["blocks_paired"] == 800
    assert not rms.info["cross_term_estimated"] and rms.info["cross_var"] == 0.0
    assert rms.info["warnings"][0].startswith("cross term not estimated")
    raw = fit_captures(*paths["raw"], accel=0, mic=1)
    assert raw.info["cross_term_estimated"] and raw.info["cross_var"] > 0 and not raw.info["warnings"]
    m0, m1 = rms.model, raw.model
    for k in ("lam1", "e10", "v1", "F", "G", "u_mean", "x0", "gx0", "block_s"):
        assert getattr(m1, k) == getattr(m0, k), k
    # the fitted moments of z given x (docs §6): b = a0 e11, var z, a0 beta1, a0^2 p22, beta0
    for f in (lambda m: m.a0 * m.e11, lambda m: m.e11 ** 2 + m.v2 - m.v1 ** 2,
              lambda m: m.a0 * (m.p21 + 2 * m.e11 * m.v1), lambda m: m.a0 ** 2 * m.p22,
              lambda m: m.p20 + 2 * m.e10 * m.v1 + m.v2):
        assert f(m1) == pytest.approx(f(m0), rel=1e-9)
    # ... and the noise term carries the cross term
    assert m1.v2 - m0.v2 == pytest.approx(raw.info["cross_var"], rel=1e-9)
    r = run_module("cmsensord.acoustic_calib", "--paired", str(tmp_path / "none.bin"), "--background",
                   str(paths["raw"][1]), "--out", str(tmp_path / "x.json"))
    assert r.returncode == 2 and r.stderr.startswith("acoustic_calib: error: ") and len(r.stderr.splitlines()) == 1
    assert not (tmp_path / "x.json").exists()


def test_command_line_calibration_estimates_the_cross_term_from_raw_captures(tmp_path):
    """`python -m cmsensord.acoustic_calib` as typed, on RAW captures: the cross term from the
    microphone's waveforms; on RMS captures, one warning line that it is missing."""
    (pair, bg), (pb, bb) = _captures(tmp_path, "raw")
    out = tmp_path / "cal.json"
    r = run_module("cmsensord.acoustic_calib", "--paired", str(pair), "--background", str(bg), "--accel", "0",
                   "--mic", "1", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert r.stderr == "" and r.stdout.startswith(f"wrote {out}: 800 paired + 600 background blocks of 10 ms")
    doc = json.loads(out.read_text())
    model = load_calibration(out)
    # the same blocks, straight from the simulator's ADC counts: (count - offset) * scale
    L = pb.block_len
    P = ((pb.counts(0, 800 * L)[1] - pb.offset[1]) * pb.scale[1]).reshape(-1, L)
    Q = ((bb.counts(0, 600 * L)[1] - bb.offset[1]) * bb.scale[1]).reshape(-1, L)
    expected = cross_term_variance(P, Q)
    assert expected > 0
    assert doc["info"]["cross_var"] == pytest.approx(expected, rel=0.25)
    assert doc["info"]["noise_var"] == pytest.approx(doc["info"]["background_var"] + expected, rel=0.25)
    assert model == fit_captures(pair, bg).model
    # RMS captures: the calibration goes on, and says in one line that the cross term is missing
    (pair_r, bg_r), _ = _captures(tmp_path, "rms")
    r = run_module("cmsensord.acoustic_calib", "--paired", str(pair_r), "--background", str(bg_r), "--out", str(out))
    assert r.returncode == 0, r.stderr
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("acoustic_calib: warning: cross term not estimated")
    assert "less accurate" in err[0]
    assert json.loads(out.read_text())["info"]["cross_var"] == 0.0


# --------------------------------------------------------------------------- the daemon

def test_vibration_estimate_messages(calibration):
    import jsonschema

    data = board("faulty_mic", 20.0, seed=2, mode="raw").generate(20.0)
    cfg = mic_config(calibration)
    cfg = dataclasses.replace(cfg, output=dataclasses.replace(cfg.output, akf_trace=True))
    sink, _, _ = run_processor(data, cfg)
    est = sink.topic("/cm/mic/vibration_estimate")
    assert len(est) == 2000 and not sink.topic("/cm/acc/vibration_estimate")
    for m in est[::97]:
        jsonschema.validate({"timestamp": {"sec": 0, "nsec": 0}, **m}, SCHEMAS["vibration_estimate"])
    x = np.array([m["x_hat"] for m in est])
    assert np.all(np.isfinite(x)) and np.all(x > 0)
    assert all(m["x_hat"] == pytest.approx(math.sqrt(m["x_ms"])) for m in est)
    # the bank watches x^: the AKF trace of the microphone channel carries it as y
    trace = sink.topic("/cm/mic/akf")
    assert [t["y"] for t in trace] == [m["x_hat"] for m in est]
    # z is the block mean square of the microphone (Pa^2): RMS^2 of the board's block RMS
    _, rms = board("faulty_mic", 20.0, seed=2).observations(2000)
    np.testing.assert_allclose([m["z"] for m in est], rms[:, 1].astype(np.float64) ** 2, rtol=1e-12)
    # the estimate follows the accelerometer: faulty-motor block RMS, same scale
    acc = rms[:, 0].astype(np.float64)
    assert np.corrcoef(x, acc)[0, 1] > 0.7
    assert np.median(x) == pytest.approx(np.median(acc), rel=0.3)
    assert len(sink.topic("/cm/mic/severity")) == 20


def test_rms_and_raw_mode_and_any_chunking_give_the_same_messages(calibration):
    cfg = mic_config(calibration)
    runs = []
    for mode, chunk in (("rms", 40_000), ("raw", 40_000), ("raw", 7_777)):
        data = board("degrading_mic", 12.0, seed=9, mode=mode).generate(12.0)
        sink, _, _ = run_processor(data, cfg, chunk=chunk)
        runs.append({t: sink.topic(t) for t in ("/cm/mic/vibration_estimate", "/cm/mic/severity",
                                                "/cm/acc/severity")})
    assert runs[0] == runs[1] == runs[2]
    assert [len(v) for v in runs[0].values()] == [1200, 12, 12]


def test_lost_blocks_are_predictions(calibration):
    data = bytearray(board("healthy_mic", 5.0, seed=3).generate(5.0))
    # cut out the frames of some blocks (RMS frames, 26 bytes each incl. 2 channels)
    from cmsensord.protocol import Decoder, FrameType

    frames = Decoder().feed(bytes(data))
    rms = [f for f in frames if f.type == FrameType.RMS]
    drop = {rms[i].offset for i in (100, 101, 250)}
    kept = b"".join(bytes(data[f.offset:f.offset + 18 + len(f.payload)]) for f in frames if f.offset not in drop)
    sink, _, _ = run_processor(kept, mic_config(calibration))
    est = sink.topic("/cm/mic/vibration_estimate")
    assert len(est) == 500
    missing = [i for i, m in enumerate(est) if m["missing"]]
    assert missing == [100, 101, 250]
    assert all(est[i]["z"] is None and est[i]["x_hat"] > 0 for i in missing)


def test_microphone_alone_equals_the_microphone_beside_an_accelerometer(calibration):
    both, _, _ = run_processor(board("degrading_mic", 15.0, seed=4).generate(15.0), mic_config(calibration))
    alone, _, _ = run_processor(board("degrading_mic_only", 15.0, seed=4, channels=1).generate(15.0),
                                mic_config(calibration, acc=False))
    for topic in ("/cm/mic/vibration_estimate", "/cm/mic/severity"):
        assert alone.topic(topic) == both.topic(topic)


def test_degrading_machine_heard_by_the_microphone_only(calibration):
    """The degrading motor (seed 0, 300 s), its microphone alone turned into severity through the
    estimator and the AKF bank, against the accelerometer: the levels rise and fall together and
    agree within one level in most decisions (the bench reports the fraction over seeds)."""
    dur = 300.0
    mic, _, _ = run_processor(board("degrading_mic_only", dur, seed=0, channels=1).generate(dur),
                              mic_config(calibration, acc=False), chunk=400_000)
    acc, _, _ = run_processor(board("degrading", dur, seed=0, channels=1).generate(dur),
                              config_from_dict({"channels": [{"name": "acc"}]}), chunk=400_000)
    lm = np.array([m["level"] for m in mic.topic("/cm/mic/severity")])
    la = np.array([m["level"] for m in acc.topic("/cm/acc/severity")])
    assert len(lm) == len(la) == 300
    within_one = np.mean(np.abs(lm - la) <= 1)
    assert within_one >= 0.75, within_one
    tenth = [lm[s] for s in np.array_split(np.arange(300), 10)]
    assert max(t.max() for t in tenth[:4]) == 0                  # healthy: no anomaly by sound either
    assert np.median(tenth[7]) >= 8 and np.median(tenth[8]) >= 8   # failure heard
    assert np.median(tenth[9]) < np.median(tenth[8])              # and easing heard
    assert any(e["kind"] == "failure" for e in mic.topic("/cm/events"))


def test_a_microphone_channels_capture_is_in_pascal(calibration, tmp_path):
    """A RAW capture of a microphone channel is its sound in Pa, as the accelerometer's is in m/s^2:
    the waveform and spectra say so (the report labels its axes from them)."""
    cap = tmp_path / "pair.bin"
    p = run_module("firmware_sim", "--out", str(cap), "--scenario", "degrading_mic", "--channels", "2",
                   "--mode", "raw", "--duration", "8")
    assert p.returncode == 0, p.stderr
    cfg = tmp_path / "site.yaml"
    cfg.write_text(f"channels:\n  - {{name: acc, index: 0}}\n  - {{name: mic, index: 1, kind: microphone}}\n"
                   f"acoustic: {{calibration: {calibration}}}\n"
                   "capture: {every_s: 4, pre_s: 1, post_s: 1, min_interval_s: 0}\n")
    p = cmsensord("replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    (log,) = (tmp_path / "logs").glob("*.mcap")
    units = {(topic, m["unit"]) for topic, _, m in read_messages(log) if "capture" in topic}
    assert units == {("/cm/acc/capture_waveform", "m/s^2"), ("/cm/acc/capture_spectrum", "m/s^2"),
                     ("/cm/acc/capture_envelope", "m/s^2"), ("/cm/mic/capture_waveform", "Pa"),
                     ("/cm/mic/capture_spectrum", "Pa"), ("/cm/mic/capture_envelope", "Pa")}
