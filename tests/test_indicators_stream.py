"""The indicator records through the monitoring chain: by board time, whatever the reads."""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.config import config_from_dict
from cmsensord.sinks.schemas import SCHEMAS
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from stream import run_processor

jsonschema = pytest.importorskip("jsonschema")

BEARING = {"name": "de", "channel": "ch0", "elements": 9, "ball_diameter": 7.94, "pitch_diameter": 39.04,
           "contact_angle_deg": 0.0}
CFG = {"indicators": {"bands": [{"name": "low", "lo_hz": 10, "hi_hz": 1000},
                                {"name": "1x", "lo_order": 0.8, "hi_order": 1.2}]},
       "bearings": [BEARING], "channels": [{"name": "ch0"}, {"name": "ch1"}]}


def capture(mode: str, seconds: float = 6.0, tacho: bool = True) -> bytes:
    sc = make_scenario("faulty", n_channels=2, duration_s=seconds, seed=2)
    return Board(sc, BoardConfig(n_channels=2, mode=mode, tacho=tacho)).generate(seconds)


def indicators(data: bytes, chunk: int, cfg: dict = CFG) -> list:
    sink, _, _ = run_processor(data, config_from_dict(cfg), chunk=chunk)
    return [(t, s, m) for t, s, m in sink.messages if t.endswith("/indicators")]


@pytest.fixture(scope="module")
def raw6():
    return capture("raw")


def test_records_do_not_depend_on_how_the_stream_was_read(raw6):
    one = indicators(raw6, chunk=len(raw6))
    assert one == indicators(raw6, chunk=4093) == indicators(raw6, chunk=50_000)
    assert [t for t, _, _ in one].count("/cm/ch0/indicators") == 6


def test_raw_records_carry_every_indicator_with_the_tacho_speed(raw6):
    recs = indicators(raw6, chunk=50_000)
    for _topic, stamp, m in recs:
        jsonschema.validate({"timestamp": {"sec": stamp // 10**9, "nsec": stamp % 10**9}, **m},
                            SCHEMAS["indicators"])
    ch0 = [m for t, _, m in recs if t == "/cm/ch0/indicators"]
    m = ch0[2]
    assert m["mode"] == "raw" and m["missing_fraction"] == 0.0 and m["speed_source"] == "tacho"
    assert m["accel_rms"] > 0 and m["crest_factor"] > 1.4 and m["kurtosis"] > 1
    assert m["velocity_rms_mm_s"] > 0 and m["zone"] in "ABCD" and m["zone_boundaries_mm_s"] == [1.4, 2.8, 4.5]
    assert m["envelope_band_hz"] == [2000.0, 10000.0] and m["velocity_band_hz"] == [10.0, 1000.0]
    f_r = m["speed_rpm"] / 60
    de = m["bearings"][0]
    assert de["name"] == "de" and de["bpfo_hz"] == pytest.approx(9 / 2 * f_r * (1 - 7.94 / 39.04), rel=1e-6)
    assert set(de["lines"]) == {"ftf", "ftf_2x", "bpfo", "bpfo_2x", "bpfi", "bpfi_2x", "bsf", "bsf_2x"}
    assert "unavailable" not in m       # FTF at 11.4 Hz: 11 bins up, resolved (resolution.py)
    bands = {b["name"]: b for b in m["bands"]}
    assert bands["1x"]["lo_hz"] == pytest.approx(0.8 * f_r, rel=1e-6) and bands["low"]["rms"] > 0
    assert all(not m2["bearings"] for t, _, m2 in recs if t == "/cm/ch1/indicators")   # no bearing on ch1


def test_a_lost_raw_frame_leaves_its_interval_with_every_indicator_of_the_samples_it_has(raw6):
    """1 % of the interval lost (under indicators.max_missing_fraction): the spectral indicators
    from the samples it has (dsp/indicators/gapped.py), as those of the intact stream; with
    max_missing_fraction 0, the waveform statistics only."""
    from cmsensord.protocol import Decoder, FrameType

    dec = Decoder()
    frames = dec.feed(raw6)
    victim = next(f for f in frames if f.type == FrameType.RAW and f.chan == 0 and f.t0_unwrapped >= 25000 * 2)
    data = raw6[:victim.offset] + raw6[victim.offset + 18 + len(victim.payload):]   # sync+header+CRC: 18 bytes
    recs = [m for t, _, m in indicators(data, chunk=50_000) if t == "/cm/ch0/indicators"]
    whole = [m for t, _, m in indicators(raw6, chunk=50_000) if t == "/cm/ch0/indicators"]
    hit, ref = recs[2], whole[2]
    assert hit["missing_fraction"] == pytest.approx(250 / 25000)
    assert "unavailable" not in hit and hit["zone"] == ref["zone"]
    assert hit["velocity_rms_mm_s"] == pytest.approx(ref["velocity_rms_mm_s"], rel=0.02)
    assert hit["envelope_rms"] == pytest.approx(ref["envelope_rms"], rel=0.05)
    assert hit["bearings"][0]["lines"]["bpfo"]["amplitude"] == pytest.approx(
        ref["bearings"][0]["lines"]["bpfo"]["amplitude"], rel=0.05)
    assert recs[1] == whole[1] and recs[3] == whole[3]
    strict = {**CFG, "indicators": {**CFG["indicators"], "max_missing_fraction": 0.0}}
    hit = [m for t, _, m in indicators(data, chunk=50_000, cfg=strict) if t == "/cm/ch0/indicators"][2]
    assert "velocity_rms_mm_s" not in hit and "velocity_rms_mm_s" in hit["unavailable"]
    assert hit["accel_rms"] > 0 and "kurtosis" in hit


def test_rms_mode_reports_the_overall_rms_and_the_rest_unavailable():
    raw, rms = capture("raw", tacho=False), capture("rms", tacho=False)
    a = [m for t, _, m in indicators(raw, chunk=50_000) if t == "/cm/ch0/indicators"]
    b = [m for t, _, m in indicators(rms, chunk=50_000) if t == "/cm/ch0/indicators"]
    assert len(b) == 6 and all(m["mode"] == "rms" for m in b)
    assert {"velocity_rms_mm_s", "kurtosis", "envelope_rms", "zone"} <= set(b[0]["unavailable"])
    assert "velocity_rms_mm_s" not in b[0]
    # the board's RMS keeps the DC the RAW record removes: equal within the mean's share
    assert np.allclose([m["accel_rms"] for m in a], [m["accel_rms"] for m in b], rtol=0.02)
    assert "unavailable" in a[0] and a[0]["unavailable"] == ["speed"]       # a bearing, no tacho, no rpm
    with_rpm = {**CFG, "indicators": {**CFG["indicators"], "rpm": 1500}}
    c = [m for t, _, m in indicators(raw, chunk=50_000, cfg=with_rpm) if t == "/cm/ch0/indicators"]
    assert c[0]["speed_source"] == "config" and c[0]["speed_rpm"] == 1500
    assert c[0]["unavailable"] == ["de.ftf"]        # 9.96 Hz: fewer than 10 of the 1-Hz bins up


def test_a_board_reset_ends_the_intervals_in_their_own_time_segment(raw6):
    """The board restarts (t0 and seq from 0 again): the intervals before it are stamped in the
    old segment, the ones after start anew, and no stamp goes back."""
    again = capture("raw", seconds=3.0)
    recs = [(s, m) for t, s, m in indicators(raw6 + again, chunk=50_000) if t == "/cm/ch0/indicators"]
    assert len(recs) == 9 and all(m["missing_fraction"] == 0.0 for _, m in recs)
    stamps = [s for s, _ in recs]
    assert stamps == sorted(stamps) and stamps[0] > 0
    assert [m["accel_rms"] for _, m in recs[6:]] == [m["accel_rms"] for _, m in recs[:3]]   # the same 3 s again
