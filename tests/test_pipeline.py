"""Processor: frames -> AKF bank -> decisions -> messages, independent of batching."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from cmsensord.config import default_config
from cmsensord.monitor.processor import Processor
from cmsensord.protocol import Decoder, Status, encode_rms, encode_status
from cmsensord.sinks.memory import ListSink
from cmsensord.source import ByteStreamSource

FIXED_CLOCK = lambda: 1_700_000_000_000_000_000  # noqa: E731


def rms_stream(seconds=12, C=2, seed=0, t0_start=0, drop=(), spike_from=None):
    """Bytes of a board in RMS mode: STATUS every second, one RMS frame per block."""
    rng = np.random.default_rng(seed)
    st_ = Status(fw_version=0x0100, mode=1, n_channels=C, fs=25000, block_len=250, tacho_inputs=0,
                 tacho_ppr=1, overruns=0, uptime_s=0, scale=(0.0244,) * C, offset=(2048.0,) * C)
    out = bytearray()
    seq = 0
    for b in range(seconds * 100):
        t0 = (t0_start + b * 250) % 2**32
        if b % 100 == 0:
            out += encode_status(seq, t0, st_)
            seq += 1
        y = 1.0 + 0.02 * rng.standard_normal(C)
        if spike_from is not None and b >= spike_from * 100 and b % 3 == 0:
            y += 1.5
        if b not in drop:
            out += encode_rms(seq, t0, y.astype(np.float32))
        seq += 1
    return bytes(out)


def run(data: bytes, splits=(), cfg=None):
    cfg = cfg or default_config(2)
    sink = ListSink()
    proc = Processor(cfg, sink, clock_ns=FIXED_CLOCK)
    cuts = [0, *sorted(splits), len(data)]
    for frames in ByteStreamSource(data[a:b] for a, b in zip(cuts, cuts[1:])):
        proc.handle(frames)
    proc.finish()                   # the end of the stream: the events still in the reorder buffer
    return sink, proc


def without_runtime(messages):
    """Drop the fields that depend on the machine's speed (diagnostics uptime)."""
    return [(t, s, m) for t, s, m in messages if t != "/cm/diagnostics"]


def test_severity_every_second_and_anomaly_when_signal_turns_spiky():
    sink, proc = run(rms_stream(seconds=12, spike_from=6))
    sev = sink.topic("/cm/ch0/severity")
    assert len(sev) == 12 and len(sink.topic("/cm/ch1/severity")) == 12
    assert sev[0]["transient"] is True and all(not s["transient"] for s in sev[1:])
    assert all(s["severity_index"] == 0 for s in sev[1:6])
    assert sev[-1]["severity_index"] > 0                    # outliers every 3rd block: 33/s >= f_r
    kinds = {e["kind"] for e in sink.topic("/cm/events")}
    assert {"anomaly_onset", "severity_change", "config"} <= kinds
    assert len(sink.topic("/cm/diagnostics")) == 12
    stamps = [s for t, s, _ in sink.messages if t == "/cm/ch0/severity"]
    assert np.all(np.diff(stamps) == 1_000_000_000)         # ADC clock, 1 s apart


def test_lost_frames_are_missing_observations_and_an_event():
    sink, proc = run(rms_stream(seconds=5, drop={250, 251, 252}))
    sev = sink.topic("/cm/ch0/severity")
    assert [s["missing"] for s in sev] == [0, 0, 3, 0, 0]
    lost = [e for e in sink.topic("/cm/events") if e["kind"] == "frames_lost"]
    assert len(lost) == 1 and lost[0]["count"] == 3
    assert proc.observations == 2 * (500 - 3) and proc.missing_observations == 2 * 3


@settings(max_examples=20, deadline=None)
@given(splits=st.lists(st.integers(min_value=0, max_value=40000), max_size=6))
def test_any_split_of_the_byte_stream_gives_the_same_messages(splits):
    data = rms_stream(seconds=4, spike_from=2)
    one, _ = run(data)
    many, _ = run(data, splits=[s % len(data) for s in splits])
    assert without_runtime(one.messages) == without_runtime(many.messages)


def test_t0_wrapping_past_2_32_changes_nothing_downstream():
    a, _ = run(rms_stream(seconds=6, spike_from=3, t0_start=0))
    b, _ = run(rms_stream(seconds=6, spike_from=3, t0_start=2**32 - 250 * 150))
    assert without_runtime(a.messages) == without_runtime(b.messages)


def test_akf_trace_per_observation_with_missing_as_null():
    cfg = default_config(2)
    import dataclasses
    cfg = dataclasses.replace(cfg, output=dataclasses.replace(cfg.output, akf_trace=True,
                                                              akf_trace_filter=3))
    sink, _ = run(rms_stream(seconds=3, drop={120}), cfg=cfg)
    tr = sink.topic("/cm/ch1/akf")
    assert len(tr) == 300 and all(m["filter"] == 3 for m in tr)
    assert tr[120]["missing"] is True and tr[120]["y"] is None and tr[120]["z"] is None
    ok = [m for m in tr if not m["missing"]]
    assert all(m["lower"] < m["x_prior"] < m["upper"] for m in ok)
    assert all((m["y"] < m["lower"] or m["y"] > m["upper"]) == m["outlier"] for m in ok)


def test_configured_channel_not_in_the_stream_is_an_event_not_a_crash():
    from cmsensord.config import config_from_dict

    cfg = config_from_dict({"channels": [{"name": "motor", "index": 5}]})
    sink = ListSink()
    proc = Processor(cfg, sink, clock_ns=FIXED_CLOCK)
    proc.handle(Decoder().feed(rms_stream(seconds=2)))
    proc.finish()
    msgs = [m["message"] for m in sink.topic("/cm/events")]
    assert any("none of the configured channels" in m for m in msgs)
    assert not sink.topic("/cm/motor/severity")


def test_a_summary_is_logged_at_the_highest_level_of_the_events_it_counts(caplog):
    """The journal's summary of the lines of a kind held back is at the highest level among
    them: routine INFO lines of a kind whose own level is ERROR are summarised at INFO, and one
    ERROR among them makes the summary an ERROR; /cm/log's copy has that level too."""
    import logging

    from cmsensord.monitor.events import EventLog

    for levels, expected in (([logging.INFO] * 8, logging.INFO),
                             ([logging.INFO] * 7 + [logging.ERROR], logging.ERROR)):
        sink = ListSink()
        log = EventLog(sink, default_stamp=lambda: 0)
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="cmsensord"):
            for i, level in enumerate(levels):          # one second: 5 told one by one, 3 held back
                log.emit("disk_error", None, f"routine {i}", stamp_ns=i, log_level=level)
            log.summarise(final=True)
        told = [(r.levelno, r.getMessage()) for r in caplog.records if r.name == "cmsensord"]
        assert len(told) == 6 and "3 more disk_error event(s)" in told[-1][1], told
        assert told[-1][0] == expected, told
        [summary] = [m for m in sink.topic("/cm/log") if "more disk_error" in m["message"]]
        assert summary["level"] == {logging.INFO: 2, logging.ERROR: 4}[expected]


def test_routine_disk_events_are_not_logged_as_errors(caplog):
    """Retention's deletions are retention events, INFO; "logging resumed" is a disk_error event
    (details.action) for the record, but the sink reports it at INFO in the journal; a real disk
    error stays an ERROR."""
    import logging

    from cmsensord.service.sink import route_sink_events

    class FakeSink(ListSink):
        on_event = None

    sink = FakeSink()
    proc = Processor(default_config(1), sink, clock_ns=lambda: 0)
    route_sink_events(sink, proc.log)
    with caplog.at_level(logging.INFO, logger="cmsensord"):
        sink.on_event("retention", "deleted 2 old files", details={"action": "retention"})
        sink.on_event("disk_error", "logging resumed", details={"action": "resumed"})
        sink.on_event("disk_error", "No space left on device", details={"action": "abandoned"})
        proc.event("disk_error", None, "capture file: No space left on device")
    levels = [r.levelno for r in caplog.records if r.name == "cmsensord"]
    assert levels == [logging.INFO, logging.INFO, logging.ERROR, logging.ERROR]
    assert [m["kind"] for m in sink.topic("/cm/events")] == ["retention"] + ["disk_error"] * 3
