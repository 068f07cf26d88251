"""Event-triggered captures through `cmsensord replay` of firmware_sim captures: each holds exactly
pre_s + post_s seconds of the board's samples (compared with the capture file's own RAW / RMS frames),
the periodic tick, the rate limit, the hourly budget and the config errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cmsensord.dsp.rms import rows_physical
from cmsensord.protocol import FrameType, decode_raw, decode_rms, decode_status, iter_frames
from cmsensord.sinks.mcap_read import read_messages
from processes import cmsensord, run_module

FS = 25000


@pytest.fixture(scope="module")
def raw_cap(tmp_path_factory) -> Path:
    cap = tmp_path_factory.mktemp("capture") / "faulty.cap"
    p = run_module("firmware_sim", "--out", str(cap), "--scenario", "faulty", "--mode", "raw", "--tacho",
                   "--duration", "20")
    assert p.returncode == 0, p.stderr
    return cap


def _replay(cap: Path, tmp: Path, capture_yaml: str) -> list[tuple[str, int, dict]]:
    cfg = tmp / "c.yaml"
    cfg.write_text("capture:\n" + "".join(f"  {line}\n" for line in capture_yaml.strip().splitlines()))
    p = cmsensord("replay", str(cap), "--config", str(cfg), "--out", str(tmp / "logs"))
    assert p.returncode == 0, p.stderr
    (log,) = (tmp / "logs").glob("*.mcap")
    return read_messages(log)


def _input_raw(cap: Path) -> tuple[int, np.ndarray]:
    """(t0 of the first sample, channel 0's samples in m/s²) of the capture file, by board t0."""
    frames, _ = iter_frames(cap.read_bytes())
    st = next(decode_status(f.payload) for f in frames if f.type == FrameType.STATUS)
    raw = sorted((f.t0_unwrapped, decode_raw(f.payload)) for f in frames if f.type == FrameType.RAW and f.chan == 0)
    t0 = raw[0][0]
    assert all(b[0] - a[0] == len(a[1]) for a, b in zip(raw, raw[1:]))      # no block lost in the file
    counts = np.concatenate([c for _, c in raw])[None, :]
    return t0, rows_physical(counts, [st.scale[0]], [st.offset[0]])[0]


def _waveforms(msgs):
    return [m for topic, _, m in msgs if topic == "/cm/ch0/capture_waveform"]


def test_capture_holds_exactly_pre_plus_post_seconds_of_the_input_samples(raw_cap, tmp_path):
    msgs = _replay(raw_cap, tmp_path, "every_s: 5\npre_s: 1.5\npost_s: 2\nmin_interval_s: 0\n"
                                      "triggers: [severity_change]")
    t0, x = _input_raw(raw_cap)
    waves = _waveforms(msgs)
    kinds = [w["trigger"]["kind"] for w in waves]
    assert kinds.count("periodic") == 3 and "severity_change" in kinds   # ticks at 5, 10, 15 s (20 s ends first)
    for w in waves:
        assert len(w["samples"]) == 3.5 * FS and w["missing"] == 0 and w["sample_rate_hz"] == FS
        start = w["first_sample"] - t0
        got = np.array(w["samples"], dtype=float)
        np.testing.assert_allclose(got, x[start:start + len(got)], rtol=1e-6, atol=1e-5)   # float32 ring
    ticks = [w["first_sample"] + 1.5 * FS - t0 for w in waves if w["trigger"]["kind"] == "periodic"]
    assert ticks == [5 * FS, 10 * FS, 15 * FS]
    for part in ("spectrum", "envelope"):                # one of each per capture, stamped at its trigger
        assert [m["timestamp"] for topic, _, m in msgs if topic == f"/cm/ch0/capture_{part}"] == \
            [w["timestamp"] for w in waves]
    spectrum = next(m for topic, _, m in msgs if topic == "/cm/ch0/capture_spectrum")
    assert spectrum["kind"] == "spectrum" and len(spectrum["amplitude"]) == 4097
    kept = [m for topic, _, m in msgs if topic == "/cm/events" and m["kind"] == "capture"]
    assert len(kept) == len(waves)
    assert kept[0]["message"] == f"ch0: captured 3.5 s around {waves[0]['trigger']['kind']} (87500 samples, 0 lost)"


def test_each_replayed_capture_is_one_chunk_of_the_log(raw_cap, tmp_path):
    from test_capture_chunk import CAPTURE, chunk_topics
    _replay(raw_cap, tmp_path, "every_s: 4\npre_s: 1\npost_s: 1\nmin_interval_s: 0")
    (log,) = (tmp_path / "logs").glob("*.mcap")
    holding = [names for _, _, names in chunk_topics(log) if set(names) & set(CAPTURE)]
    assert len(holding) == 4 and all(names == list(CAPTURE) for names in holding)   # at 4, 8, 12, 16 s


def test_rate_limit_and_hourly_budget(raw_cap, tmp_path):
    msgs = _replay(raw_cap, tmp_path, "every_s: 1\npre_s: 0.5\npost_s: 0.5\nmin_interval_s: 4\n"
                                      "max_mb_per_hour: 1")
    waves = _waveforms(msgs)
    first = [w["first_sample"] for w in waves]
    assert np.diff(first).tolist() == [4 * FS] * (len(first) - 1)      # one per 4 s, no closer
    skipped = [m["message"] for topic, _, m in msgs if topic == "/cm/events" and m["kind"] == "capture_skipped"]
    assert skipped[0] == "ch0: capture on periodic skipped: 1 s after the last one (capture.min_interval_s 4)"
    # 25000 samples x 12 bytes = 0.3 MB each: the fourth would pass 1 MB in the hour
    assert len(waves) == 3
    assert "ch0: capture on periodic skipped: 0.9 MB written in the last hour (capture.max_mb_per_hour 1)" in skipped


def test_rms_mode_captures_the_block_rms(tmp_path):
    cap = tmp_path / "deg.cap"
    assert run_module("firmware_sim", "--out", str(cap), "--scenario", "degrading", "--duration", "30").returncode == 0
    msgs = _replay(cap, tmp_path, "every_s: 10\npre_s: 2\npost_s: 3\nmin_interval_s: 0")
    frames, _ = iter_frames(cap.read_bytes())
    rms = sorted((f.t0_unwrapped, decode_rms(f)[0]) for f in frames if f.type == FrameType.RMS)
    block = rms[1][0] - rms[0][0]
    by_index = {t0 // block: v for t0, v in rms}
    waves = _waveforms(msgs)
    assert len(waves) == 2 and {w["source"] for w in waves} == {"rms"}
    for w in waves:
        assert w["sample_rate_hz"] == 100 and len(w["samples"]) == 500
        want = [by_index[w["first_sample"] + k] for k in range(500)]
        np.testing.assert_allclose(w["samples"], want, rtol=1e-6, atol=1e-6)
    assert not any(topic == "/cm/ch0/capture_envelope" for topic, _, _ in msgs)


@pytest.mark.parametrize("triggers, said", [
    ("alarm, failure", "unknown trigger 'alarm' (one of alarm_alert, alarm_danger, alarm_clear, severity_change, "
     "anomaly_onset, failure, time_base, tacho_lost, operating_state, manual) (got 'alarm')"),
    # order alarms are alarm-manager rules order_<name>: their events are alarm_alert and
    # alarm_danger, so a capture on order_alarm would never be taken
    ("failure, order_alarm", "order_alarm events are no longer written: order alarms are rules order_<name> "
     "of the alarm manager, use alarm_alert / alarm_danger (got 'order_alarm')"),
])
def test_a_bad_capture_trigger_is_one_line(raw_cap, tmp_path, triggers, said):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(f"capture:\n  triggers: [{triggers}]\n")
    p = cmsensord("replay", str(raw_cap), "--config", str(cfg), "--out", str(tmp_path))
    assert p.returncode == 78                            # EXIT_CONFIG
    assert p.stderr.strip().splitlines() == [f"cmsensord: configuration error: {cfg}: capture.triggers: {said}"]


@pytest.mark.parametrize("carrier, band", [(5000.0, None), (1500.0, (1000.0, 2000.0))])
def test_captured_spectra_are_rms_per_bin_and_the_envelope_demodulates_the_indicators_band(
        tmp_path, carrier, band):
    """An imported 1 g carrier modulated 50 % at 100 Hz, with a 0.3 g sine at 50 Hz: the
    spectrum reads the sine's RMS, the envelope spectrum the modulation's RMS (0.5 g / sqrt 2,
    what envelope_rms reads), of indicators.envelope_band_hz when it is set."""
    fs, g = 25600, 9.80665
    t = np.arange(8 * fs) / fs
    x = (1 + 0.5 * np.cos(2 * np.pi * 100 * t)) * np.cos(2 * np.pi * carrier * t) + 0.3 * np.sin(2 * np.pi * 50 * t)
    np.save(tmp_path / "am.npy", x)
    p = cmsensord("import", str(tmp_path / "am.npy"), "--fs", str(fs), "--unit", "g", "--names", "ch0",
                  "--out", str(tmp_path / "am.bin"))
    assert p.returncode == 0, p.stderr
    cfg = tmp_path / "c.yaml"
    cfg.write_text("output:\n  status_line: false\ncapture:\n  every_s: 4\n  pre_s: 2\n  post_s: 2\n"
                   + (f"indicators:\n  envelope_band_hz: [{band[0]}, {band[1]}]\n" if band else ""))
    p = cmsensord("replay", str(tmp_path / "am.bin"), "--config", str(cfg), "--out", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    spec = next(m for topic, _, m in msgs if topic == "/cm/ch0/capture_spectrum")
    env = next(m for topic, _, m in msgs if topic == "/cm/ch0/capture_envelope")
    ind = [m for topic, _, m in msgs if topic == "/cm/ch0/indicators"][2]

    def peak(m, f0):
        k = round(f0 / m["freq_step_hz"])
        return max(m["amplitude"][k - 2:k + 3])
    assert peak(spec, 50) == pytest.approx(0.3 * g / np.sqrt(2), rel=0.01)
    assert env["band_hz"] == ind["envelope_band_hz"] == list(band or (0.08 * fs, 0.4 * fs))
    # RMS, not 4.903 (0-peak) at 5 kHz, nor 0.0004 with the 1500-Hz carrier outside the default band
    assert peak(env, 100) == pytest.approx(0.5 * g / np.sqrt(2), rel=0.01)
    assert peak(env, 100) == pytest.approx(ind["envelope_rms"], rel=0.01)
