"""Captures at any read size: a capture's messages, the shaft speed and lines marked on its
spectra, and its events are those of the stream, not of how it was read.

Guards against a RAW capture written as soon as the ring holds its last sample, with the speed
the tacho has reached by then (a large read: the whole window's; 997-byte reads: less of it),
and its `capture` event, stamped at the trigger, coming after the event log has written later
records at some read sizes (then taking the newest stamp).  And against the periodic ticks
starting their captures as the samples come, the events' triggers as the events come: in a
large read of an RMS stream, whose decisions wait for the tacho, every tick of the read would
come before the decisions' events, so an anomaly's capture would be skipped as "-19 s after the
last one" (a replay losing the captures the live daemon made)."""

from __future__ import annotations

import pytest
import yaml

from cmsensord.sinks.mcap_sink import read_messages
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from processes import board_then_daemon, cmsensord
from test_read_size import READS, by_topic

S = 1_000_000_000
CONFIG = {"capture": {"triggers": ["severity_change", "anomaly_onset", "failure", "tacho_lost", "alarm_alert"],
                      "every_s": 7.0, "pre_s": 2.0, "post_s": 2.0, "min_interval_s": 5.0},
          "alarms": {"rules": [{"name": "acc", "indicator": "accel_rms", "alert": 0.5, "danger": 5.0}]}}


FAULTS = [{}, {"tacho_extra": 0.3, "tacho_missed": 0.3, "tacho_jitter": 3.0}]


def same_at_every_read_size(data: bytes) -> dict[str, list]:
    runs = [by_topic(data, read, CONFIG) for read in READS]
    for topic in runs[0]:
        for k in (1, 2):
            assert runs[k].get(topic) == runs[0][topic], (topic, READS[k])
    assert runs[1].keys() == runs[0].keys() == runs[2].keys()
    return runs[0]


def captured(run: dict[str, list]) -> list[tuple[int, str]]:
    """(stamp, trigger kind) of each capture written, asserted alike on its topic and its event."""
    waves = [(s, m["trigger"]["kind"]) for s, m in run["/cm/ch0/capture_waveform"]]
    assert [s for s, _ in waves] == [s for s, m in run["/cm/events"] if m["kind"] == "capture"]
    return waves


@pytest.mark.parametrize("faults", FAULTS, ids=["clean", "tacho faults"])
def test_raw_captures_are_the_same_at_every_read_size(faults):
    sc = make_scenario("faulty", n_channels=1, duration_s=24, seed=2)
    run = same_at_every_read_size(Board(sc, BoardConfig(mode="raw", tacho=True, **faults)).generate(24))
    spectra = [m for _, m in run["/cm/ch0/capture_spectrum"]]
    assert len(spectra) == 4 and all(m["speed_source"] == "tacho" for m in spectra)
    if not faults:
        assert all(abs(m["shaft_speed_rpm"] - 1719.6) < 0.1 for m in spectra)
    assert captured(run) == [(2 * S, "anomaly_onset"), (7 * S, "periodic"), (14 * S, "periodic"), (21 * S, "periodic")]


@pytest.mark.parametrize("faults", FAULTS, ids=["clean", "tacho faults"])
def test_rms_captures_take_ticks_and_events_in_stamp_order_at_every_read_size(faults):
    """The anomaly at 2 s is captured and the decisions' other triggers up to 7 s are refused by
    min_interval_s 5, at every read size; then the ticks every 7 s."""
    sc = make_scenario("faulty", n_channels=1, duration_s=24, seed=3)
    run = same_at_every_read_size(Board(sc, BoardConfig(mode="rms", tacho=True, **faults)).generate(24))
    assert captured(run) == [(2 * S, "anomaly_onset"), (7 * S, "periodic"), (14 * S, "periodic"), (21 * S, "periodic")]
    skipped = [m["message"] for _, m in run["/cm/events"] if m["kind"] == "capture_skipped"]
    assert skipped and all(m.endswith(("s after the last one (capture.min_interval_s 5)",
                                       "its pre_s reaches back before the stream's start")) for m in skipped)
    assert not [m for m in skipped if "-" in m.split("skipped: ")[1][:3]]


def test_the_daemon_on_a_pty_captures_what_the_replay_of_its_capture_does(tmp_path):
    """An RMS board with a tacho on a pty, the daemon on it with captures: its capture messages
    and events are those of `cmsensord replay` of the bytes it read (1-MB reads)."""
    cfg = yaml.safe_dump({k: v for k, v in CONFIG.items()})
    board_then_daemon(tmp_path, "--scenario", "faulty", "--mode", "rms", "--tacho", "--duration", "24",
                      "--speed", "4", "--seed", "3", config=cfg)
    (tmp_path / "replay.yaml").write_text(cfg + f"output:\n  dir: {tmp_path / 'replay'}\n")
    r = cmsensord("replay", str(tmp_path / "cap.bin"), "--config", str(tmp_path / "replay.yaml"))
    assert r.returncode == 0, r.stderr

    def kept(folder):
        return [(t, s, m) for f in sorted(folder.glob("*.mcap")) for t, s, m in read_messages(f)
                if "capture" in t or (t == "/cm/events" and m["kind"].startswith("capture"))]

    def relative(messages):             # by topic; only the wall-clock anchor differs
        base = min(s for t, s, _ in messages if t.endswith("capture_waveform"))
        out: dict[str, list] = {}
        for t, s, m in messages:
            out.setdefault(t, []).append((s - base, {k: v for k, v in m.items() if k != "timestamp"}))
        return out

    live, replayed = kept(tmp_path / "logs"), kept(tmp_path / "replay")
    triggers = [m["trigger"]["kind"] for t, _, m in live if t.endswith("capture_waveform")]
    assert triggers[:2] == ["anomaly_onset", "periodic"]
    assert relative(live) == relative(replayed)
