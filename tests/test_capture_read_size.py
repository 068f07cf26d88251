"""Captures at any read size: a capture's messages, the shaft speed and lines marked on its
spectra, and its events are those of the stream, not of how it was read.

Before, a RAW capture was written as soon as the ring held its last sample, with the speed the
tacho had reached by then (a large read: the whole window's; 997-byte reads: less of it), and
its `capture` event, stamped at the trigger, came after the event log had written later
records at some read sizes (then it took the newest stamp)."""

from __future__ import annotations

import pytest

from cmsensord.config import config_from_dict
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from stream import run_processor

READS = (997, 65_536, 1 << 20)
CONFIG = {"capture": {"triggers": ["severity_change", "anomaly_onset", "failure", "tacho_lost", "alarm_alert"],
                      "every_s": 7.0, "pre_s": 2.0, "post_s": 2.0, "min_interval_s": 5.0},
          "alarms": {"rules": [{"name": "acc", "indicator": "accel_rms", "alert": 0.5, "danger": 5.0}]}}


def by_topic(data: bytes, read: int) -> dict[str, list]:
    out: dict[str, list] = {}
    for topic, stamp, msg in run_processor(data, config_from_dict(CONFIG), chunk=read)[0].messages:
        if topic != "/cm/diagnostics":
            out.setdefault(topic, []).append((stamp, msg))
    return out


@pytest.mark.parametrize("faults", [{}, {"tacho_extra": 0.3, "tacho_missed": 0.3, "tacho_jitter": 3.0}],
                         ids=["clean", "tacho faults"])
def test_raw_captures_are_the_same_at_every_read_size(faults):
    sc = make_scenario("faulty", n_channels=1, duration_s=24, seed=2)
    data = Board(sc, BoardConfig(mode="raw", tacho=True, **faults)).generate(24)
    runs = [by_topic(data, read) for read in READS]
    for topic in runs[0]:
        for k in (1, 2):
            assert runs[k].get(topic) == runs[0][topic], (topic, READS[k])
    assert runs[1].keys() == runs[0].keys() == runs[2].keys()
    spectra = [m for _, m in runs[0]["/cm/ch0/capture_spectrum"]]
    assert len(spectra) == 4 and all(m["speed_source"] == "tacho" for m in spectra)
    if not faults:
        assert all(abs(m["shaft_speed_rpm"] - 1719.6) < 0.1 for m in spectra)
    captured = [m for _, m in runs[0]["/cm/events"] if m["kind"] == "capture"]
    assert [s for s, _ in runs[0]["/cm/ch0/capture_waveform"]] == \
        [s for s, m in runs[0]["/cm/events"] if m["kind"] == "capture"] and len(captured) == 4
