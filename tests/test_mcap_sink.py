"""MCAP sink: the output contract (topics, jsonschema schemas, JSON, {sec, nsec},
no NaN), crash safety (.part -> .mcap, flush by clock) and lenient summaries."""

from __future__ import annotations

import json
import math
import random
import re
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import NonSeekingReader, make_reader
from mcap.stream_reader import StreamReader

from cmsensord.errors import SinkError
from cmsensord.sinks.event_schema import EVENT_KINDS
from cmsensord.sinks.mcap_sink import McapSink, ns_to_stamp, read_messages, summarize
from cmsensord.sinks.schemas import (
    LINK_COUNTERS,
    SCHEMAS,
    TOPIC_DIAGNOSTICS,
    TOPIC_EVENTS,
    akf_topic,
    orders_topic,
    severity_topic,
)
from fakes import FakeClock

T0 = 1_700_000_000_123_456_789  # ns since the epoch


def severity_msg(channel: str = "ch0") -> dict:
    n = 10
    return {
        "channel": channel,
        "severity_index": 0.3,
        "level": 3,
        "anomaly": [1, 1, 1, 0, 0, 0, 0, 0, 0, 0],
        "outliers": [41, 33, 29, 12, 5, 3, 1, 0, 0, 0],
        "f_r": 28.66,
        "r": [4e-3 + i * (0.13 - 4e-3) / n for i in range(1, n + 1)],
        "failure": False,
        "missing": 0,
        "transient": False,
    }


def akf_msg(missing: bool = False) -> dict:
    return {
        "channel": "ch0",
        "filter": 10,
        "y": None if missing else 0.52,
        "x_hat": 0.5,
        "x_prior": 0.49,
        "lower": 0.2,
        "upper": 0.78,
        "z": None if missing else 0.4,
        "outlier": False,
        "q_hat": 1.5e-4,
        "missing": missing,
    }


def event_msg(kind: str = "anomaly_onset") -> dict:
    return {
        "kind": kind,
        "channel": "ch0",
        "message": "ch0: AKF 3 in anomaly (cnt 41 >= f_r 28.66)",
        "filter": 3,
        "severity_index": 0.3,
        "level": 3,
        "details": {"cnt": 41},
    }


def diagnostics_msg() -> dict:
    return {
        "link": {name: i for i, name in enumerate(LINK_COUNTERS)},
        "queue_depth": 3,
        "queue_drops": 0,
        "lag_s": 0.012,
        "observations": 100,
        "uptime_s": 1.0,
    }


def orders_msg() -> dict:
    return {
        "channel": "ch0",
        "speed_rpm": 1720.0,
        "valid": True,
        "method": "recursive",
        "orders": [{"name": "1x", "order": 1.0, "freq_hz": 28.67, "rms": 0.8, "amplitude": 1.13},
                   {"name": "whip", "order": None, "freq_hz": 47.0, "rms": 0.1, "amplitude": 0.14}],
    }


SAMPLES = [
    (severity_topic("ch0"), "severity", severity_msg()),
    (akf_topic("ch0"), "akf", akf_msg()),
    (akf_topic("ch0"), "akf", akf_msg(missing=True)),
    (TOPIC_EVENTS, "event", event_msg()),
    (TOPIC_EVENTS, "event", {"kind": "start", "channel": None, "message": "cmsensord started"}),
    (TOPIC_DIAGNOSTICS, "diagnostics", diagnostics_msg()),
    (orders_topic("ch0"), "orders", orders_msg()),
    ("/cm/mic0/vibration_estimate", "vibration_estimate", {
        "channel": "mic0", "x_hat": 0.21, "x_ms": 0.044, "x_ms_var": 1e-4, "a_hat": 0.6,
        "a_var": 0.01, "y_hat": 0.0069, "y_var": 2e-6, "z": 0.0081, "z_pred": 0.0079,
        "missing": False}),
    ("/cm/log", "log", {"level": 3, "message": "failure: ch0: FAILURE", "name": "ch0", "file": "",
                        "line": 0}),
    ("/cm/ch0/indicators", "indicators", {
        "channel": "ch0", "mode": "raw", "interval_s": 1.0, "missing_fraction": 0.0, "accel_rms": 2.1,
        "accel_peak": 8.4, "crest_factor": 4.0, "kurtosis": 3.2, "velocity_rms_mm_s": 1.9,
        "velocity_band_hz": [10.0, 1000.0], "zone": "B", "zone_boundaries_mm_s": [1.4, 2.8, 4.5],
        "envelope_rms": 0.7, "envelope_band_hz": [2000.0, 10000.0], "speed_rpm": 1480.0,
        "speed_source": "tacho", "bands": [{"name": "low", "lo_hz": 10.0, "hi_hz": 1000.0, "rms": 1.2}],
        "bearings": [{"name": "de", "ftf_hz": 9.9, "bpfo_hz": 88.6, "bpfi_hz": 133.4, "bsf_hz": 58.0,
                      "lines": {"bpfo": {"amplitude": 0.2, "freq_hz": 89.0, "ratio": 12.5}}}]}),
    ("/cm/ch1/indicators", "indicators", {
        "channel": "ch1", "mode": "rms", "interval_s": 1.0, "missing_fraction": 0.0, "accel_rms": 2.1,
        "unavailable": ["accel_peak", "crest_factor", "kurtosis", "velocity_rms_mm_s", "zone"]}),
    ("/cm/ch0/capture_waveform", "capture_waveform", {
        "channel": "ch0", "trigger": {"kind": "alarm_danger", "message": "ch0: danger"}, "source": "raw",
        "sample_rate_hz": 25000.0, "first_sample": 250000, "pre_s": 10.0, "post_s": 10.0, "unit": "m/s^2",
        "missing": 1, "samples": [0.1, 0.0, -0.2], "lost": [1]}),
    ("/cm/ch0/capture_envelope", "capture_spectrum", {
        "channel": "ch0", "trigger": {"kind": "periodic", "message": "every 600 s"}, "kind": "envelope",
        "freq_start_hz": 0.0, "freq_step_hz": 0.05, "band_hz": [2000.0, 10000.0], "unit": "m/s^2",
        "amplitude": [0.0, 0.3, 0.1]}),
    ("/cm/alarms", "alarms", {
        "operating_state": "running", "worst": "alert", "worst_alarm": "de_velocity/ch0", "speed_rpm": 1480.0,
        "alarms": [{"id": "de_velocity/ch0", "rule": "de_velocity", "indicator": "velocity_rms_mm_s",
                    "channel": "ch0", "channels": ["ch0"], "level": "alert", "live": "alert", "latched": False,
                    "acknowledged": False, "value": 3.1, "alert_level": 2.8, "danger_level": 4.5}]}),
]
SCHEMA_NAMES = {
    "severity": "cmsensord.Severity",
    "akf": "cmsensord.AkfTrace",
    "event": "cmsensord.Event",
    "diagnostics": "cmsensord.Diagnostics",
    "orders": "cmsensord.Orders",
    "vibration_estimate": "cmsensord.VibrationEstimate",
    "log": "foxglove.Log",
    "indicators": "cmsensord.Indicators",
    "alarms": "cmsensord.Alarms",
    "capture_waveform": "cmsensord.CaptureWaveform",
    "capture_spectrum": "cmsensord.CaptureSpectrum",
}


def as_written(value):
    """What the file holds for ``value``: a None field is left out (a missing value is an
    absent field), in nested objects too."""
    if isinstance(value, dict):
        return {k: as_written(v) for k, v in value.items() if v is not None}
    if isinstance(value, list):
        return [as_written(v) for v in value]
    return value


def check(schema: dict, value, where: str = "$") -> None:
    """Validate value against the subset of JSON Schema the schemas use."""
    types = schema.get("type")
    if types is not None:
        types = [types] if isinstance(types, str) else types
        ok = {
            "object": isinstance(value, dict),
            "array": isinstance(value, list),
            "string": isinstance(value, str),
            "boolean": isinstance(value, bool),
            "integer": isinstance(value, int) and not isinstance(value, bool),
            "number": isinstance(value, (int, float)) and not isinstance(value, bool),
            "null": value is None,
        }
        assert any(ok[t] for t in types), f"{where}: {value!r} is not {types}"
    if "enum" in schema:
        assert value in schema["enum"], f"{where}: {value!r} not in enum"
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        assert value >= schema.get("minimum", -math.inf), where
        assert value <= schema.get("maximum", math.inf), where
    if isinstance(value, dict):
        for key in schema.get("required", []):
            assert key in value, f"{where}: missing required {key!r}"
        for key, sub in schema.get("properties", {}).items():
            if key in value:
                check(sub, value[key], f"{where}.{key}")
    if isinstance(value, list) and "items" in schema:
        for i, item in enumerate(value):
            check(schema["items"], item, f"{where}[{i}]")


def write_samples(sink: McapSink, start: int = T0) -> list[tuple[str, int, dict]]:
    written = []
    for i, (topic, kind, msg) in enumerate(SAMPLES):
        stamp = start + i * 10_000_000
        sink.write(topic, kind, stamp, msg)
        written.append((topic, stamp, msg))
    return written


# --- the contract -------------------------------------------------------------


def test_schemas_have_titles_descriptions_and_describe_required_fields():
    assert set(SCHEMAS) == set(SCHEMA_NAMES)
    for kind, schema in SCHEMAS.items():
        assert schema["title"] == SCHEMA_NAMES[kind]
        assert schema["description"]
        for key in schema["required"]:
            assert key in schema["properties"], (kind, key)
        for key, prop in schema["properties"].items():
            assert prop.get("description"), (kind, key)
        if kind != "log":           # foxglove.Log is Foxglove's schema as published
            assert schema["properties"]["timestamp"]["required"] == ["sec", "nsec"]
    assert set(SCHEMAS["event"]["properties"]["kind"]["enum"]) == set(EVENT_KINDS)
    assert "salvage" in EVENT_KINDS and "link_stalled" in EVENT_KINDS


def test_sample_messages_satisfy_their_schemas():
    # guards the samples below, so the round trip checks a valid contract
    for _topic, kind, msg in SAMPLES:
        check(SCHEMAS[kind], {"timestamp": ns_to_stamp(T0), **as_written(msg)})


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_every_schema_round_trips_through_mcap_reader(tmp_path, compression):
    with McapSink(tmp_path, compression=compression, metadata={"config": "{}"}) as sink:
        written = write_samples(sink)
    assert sink.messages_written == len(SAMPLES)

    with open(sink.path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        got = list(reader.iter_messages(log_time_order=False))
        summary = reader.get_summary()
        assert [m.metadata for m in reader.iter_metadata()] == [{"config": "{}"}]
    assert len(got) == len(written)
    for (schema, channel, message), (topic, stamp, msg), (_, kind, _) in zip(got, written, SAMPLES):
        assert channel.topic == topic
        assert channel.message_encoding == "json"
        assert schema.encoding == "jsonschema"
        assert schema.name == SCHEMA_NAMES[kind]
        assert json.loads(schema.data) == SCHEMAS[kind]
        assert message.log_time == message.publish_time == stamp
        decoded = json.loads(message.data)
        assert decoded == {"timestamp": {"sec": stamp // 10**9, "nsec": stamp % 10**9}, **as_written(msg)}
        assert next(iter(decoded)) == "timestamp"
        check(SCHEMAS[kind], decoded)
    assert summary.statistics.message_count == len(SAMPLES)
    assert {c.topic for c in summary.channels.values()} == {t for t, _, _ in SAMPLES}
    assert len(summary.schemas) == len(SCHEMA_NAMES)  # one schema per kind, shared by topics


def test_file_passes_mcap_crc_checks_and_all_readers_agree(tmp_path):
    sink = McapSink(tmp_path, chunk_size=2000)  # many chunks
    for k in range(300):
        ch = f"ch{k % 3}"
        sink.write(severity_topic(ch), "severity", T0 + k * 10**9, severity_msg(ch))
        sink.write(TOPIC_EVENTS, "event", T0 + k * 10**9 + 1, event_msg())
    path = sink.close()
    with open(path, "rb") as f:
        records = list(StreamReader(f, validate_crcs=True).records)  # data-section and chunk CRCs
    assert type(records[-1]).__name__ == "Footer"
    with open(path, "rb") as f:
        linear = [(c.topic, m.log_time, m.data) for _, c, m in NonSeekingReader(f, validate_crcs=True).iter_messages()]
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        indexed = [(c.topic, m.log_time, m.data) for _, c, m in reader.iter_messages()]
        stats = reader.get_summary().statistics
        only_ch1 = list(reader.iter_messages(topics=[severity_topic("ch1")]))
    assert len(linear) == 600 and sorted(linear) == sorted(indexed)
    assert stats.chunk_count > 10 and stats.message_count == 600
    assert stats.message_start_time == T0 and stats.message_end_time == T0 + 299 * 10**9 + 1
    assert len(only_ch1) == 100
    assert read_messages(path) == read_messages(path, lenient=True)


def test_timestamp_in_message_is_kept_and_msg_not_modified(tmp_path):
    msg = {"kind": "stop", "channel": None, "message": "bye", "timestamp": {"sec": 5, "nsec": 6}}
    before = dict(msg)
    empty: dict = {}
    with McapSink(tmp_path) as sink:
        sink.write(TOPIC_EVENTS, "event", T0, msg)
        sink.write("/cm/x/orders", "orders", T0 + 1, empty)
    assert msg == before and empty == {}
    (_, t1, m1), (_, t2, m2) = read_messages(sink.path)
    assert (t1, m1["timestamp"]) == (T0, {"sec": 5, "nsec": 6})
    assert (t2, m2) == (T0 + 1, {"timestamp": ns_to_stamp(T0 + 1)})


def test_ns_to_stamp():
    assert ns_to_stamp(T0) == {"sec": 1_700_000_000, "nsec": 123_456_789}
    assert ns_to_stamp(0) == {"sec": 0, "nsec": 0}
    assert ns_to_stamp(10**9 - 1) == {"sec": 0, "nsec": 999_999_999}


# --- no NaN, numpy ------------------------------------------------------------


def test_nan_and_inf_become_absent_fields_never_invalid_json(tmp_path):
    nan, inf = float("nan"), float("inf")
    msg = akf_msg()
    msg.update(y=nan, z=-inf, x_hat=np.float64("nan"), lower=np.float32("-inf"))
    msg["details"] = {"deep": [1.0, nan, {"x": inf}], "t": (nan, 2)}
    with McapSink(tmp_path) as sink:
        sink.write(akf_topic("ch0"), "akf", T0, msg)
    assert math.isnan(msg["y"])  # the caller's dict is untouched
    with open(sink.path, "rb") as f:
        (_, _, message), = make_reader(f).iter_messages()
    raw = message.data.decode()
    assert "NaN" not in raw and "Infinity" not in raw
    decoded = json.loads(raw, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert not {"y", "z", "x_hat", "lower"} & set(decoded)
    assert decoded["details"] == {"deep": [1.0, None, {}], "t": [None, 2]}   # in an array: null
    assert decoded["x_prior"] == 0.49


def test_numpy_scalars_and_arrays_are_converted(tmp_path):
    msg = severity_msg()
    msg.update(
        level=np.int64(3),
        anomaly=np.array([1, 1, 1, 0, 0, 0, 0, 0, 0, 0], dtype=np.uint8),
        r=np.linspace(0.0166, 0.13, 10),
        failure=np.bool_(False),
        severity_index=np.float32(0.3),
        outliers=np.array([41, 33, 29, 12, 5, 3, 1, 0, 0, 0]),
    )
    with McapSink(tmp_path) as sink:
        sink.write(severity_topic("ch0"), "severity", T0, msg)
    (_, _, got), = read_messages(sink.path)
    assert got["level"] == 3 and got["failure"] is False
    assert got["anomaly"] == [1, 1, 1, 0, 0, 0, 0, 0, 0, 0]
    assert got["r"] == pytest.approx(list(np.linspace(0.0166, 0.13, 10)))
    assert got["severity_index"] == pytest.approx(0.3)
    check(SCHEMAS["severity"], got)


def test_unencodable_message_is_a_sink_error(tmp_path):
    with McapSink(tmp_path) as sink, pytest.raises(SinkError, match=r"^/cm/events: message cannot be encoded as JSON"):
        sink.write(TOPIC_EVENTS, "event", T0, {"kind": "start", "details": object()})


# --- files: names, .part -> .mcap, errors --------------------------------------


def test_part_file_renamed_on_close_and_close_idempotent(tmp_path):
    out = tmp_path / "a" / "b"  # parents are created
    sink = McapSink(out, prefix="rig1", wall_clock=lambda: 1_700_000_000.9)
    assert sink.path == out / "rig1-20231114T221320Z.mcap"
    assert sink.part_path == out / "rig1-20231114T221320Z.mcap.part"
    write_samples(sink)
    assert sink.part_path.exists() and not sink.path.exists()
    assert sink.close() == sink.path
    assert sink.path.exists() and not sink.part_path.exists()
    assert sink.close() == sink.path  # idempotent
    assert sorted(p.name for p in out.iterdir()) == ["rig1-20231114T221320Z.mcap"]
    s = summarize(sink.path)
    assert s["complete"] and not s["truncated"] and s["error"] is None
    assert s["valid_bytes"] == s["file_bytes"] == sink.path.stat().st_size


def test_default_file_name_is_utc_stamp(tmp_path):
    with McapSink(tmp_path) as sink:
        pass
    assert re.fullmatch(r"cmsensord-\d{8}T\d{6}Z\.mcap", sink.path.name)
    assert summarize(sink.path)["messages"] == 0


def test_existing_names_get_numbered_suffix(tmp_path):
    clock = lambda: 1_700_000_000.0  # noqa: E731
    first = McapSink(tmp_path, wall_clock=clock)
    second = McapSink(tmp_path, wall_clock=clock)  # while first is still a .part
    first.close()
    third = McapSink(tmp_path, wall_clock=clock)
    names = [s.close().name for s in (second, third)]
    assert first.path.name == "cmsensord-20231114T221320Z.mcap"
    assert names == ["cmsensord-20231114T221320Z-1.mcap", "cmsensord-20231114T221320Z-2.mcap"]


def test_unwritable_directory_is_one_line_sink_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(SinkError) as info:
        McapSink(blocker / "logs")
    message = str(info.value)
    assert message.startswith(f"{blocker / 'logs'}: cannot create output directory")
    assert "\n" not in message


def test_bad_arguments_and_misuse(tmp_path):
    with pytest.raises(SinkError, match="unknown MCAP compression 'gzip'"):
        McapSink(tmp_path, compression="gzip")
    with McapSink(tmp_path) as sink:
        sink.write(TOPIC_EVENTS, "event", T0, event_msg())
        with pytest.raises(SinkError, match=r"/cm/events: written with schema 'severity'"):
            sink.write(TOPIC_EVENTS, "severity", T0, severity_msg())
        with pytest.raises(SinkError, match=r"/cm/x: unknown schema 'sev'"):
            sink.write("/cm/x", "sev", T0, {})
        with pytest.raises(SinkError, match="negative timestamp"):
            sink.write(TOPIC_EVENTS, "event", -1, event_msg())
    for topic in (TOPIC_EVENTS, "/cm/new"):
        with pytest.raises(SinkError, match="write after close"):
            sink.write(topic, "event", T0, event_msg())


# --- crash safety: flush by clock, truncated files ------------------------------


def test_flush_after_flush_s_makes_data_visible_in_open_part_file(tmp_path, clock):
    sink = McapSink(tmp_path, flush_s=1.0, clock=clock)
    for k in range(5):
        sink.write(severity_topic("ch0"), "severity", T0 + k, severity_msg())
        clock.t += 0.1
    before = summarize(sink.part_path)
    assert before["messages"] == 0 and not before["complete"]
    clock.t += 0.6  # 1.1 s since the last flush
    sink.write(TOPIC_EVENTS, "event", T0 + 5, event_msg("failure"))
    after = summarize(sink.part_path)
    assert after["messages"] == 6
    assert after["topics"] == {severity_topic("ch0"): 5, TOPIC_EVENTS: 1}
    assert after["schemas"] == {severity_topic("ch0"): "cmsensord.Severity", TOPIC_EVENTS: "cmsensord.Event"}
    assert after["event_counts"] == {"failure": 1}
    assert not after["complete"] and after["error"] is None
    assert (after["start_ns"], after["end_ns"]) == (T0, T0 + 5)
    assert read_messages(sink.part_path, lenient=True)[-1][2]["kind"] == "failure"
    # the next period: nothing new on disk until flush_s has passed again
    sink.write(TOPIC_EVENTS, "event", T0 + 6, event_msg())
    assert summarize(sink.part_path)["messages"] == 6
    sink.flush()
    assert summarize(sink.part_path)["messages"] == 7
    sink.close()
    assert summarize(sink.path)["messages"] == 7


def _recorded_file(tmp_path: Path) -> Path:
    clock = FakeClock()
    sink = McapSink(tmp_path, flush_s=1.0, clock=clock, metadata={"k": "v"})
    for k in range(40):
        sink.write(severity_topic("ch0"), "severity", T0 + k * 10**9, severity_msg())
        sink.write(akf_topic("ch0"), "akf", T0 + k * 10**9 + 1, akf_msg(missing=k % 7 == 0))
        if k % 10 == 0:
            sink.write(TOPIC_EVENTS, "event", T0 + k * 10**9 + 2, event_msg("severity_change"))
        clock.t += 0.5  # a chunk every second write pair
    return sink.close()


def test_summary_of_complete_file(tmp_path):
    s = summarize(_recorded_file(tmp_path))
    assert s["complete"] and s["messages"] == 84
    assert s["topics"] == {akf_topic("ch0"): 40, TOPIC_EVENTS: 4, severity_topic("ch0"): 40}
    assert s["event_counts"] == {"severity_change": 4}
    assert [e["time_ns"] for e in s["events"]] == [T0 + k * 10**9 + 2 for k in (0, 10, 20, 30)]
    assert s["events"][0]["message"].startswith("ch0: AKF 3")
    assert s["duration_s"] == pytest.approx(39.0, abs=1e-6)
    assert s["metadata"] == {"cmsensord": {"k": "v"}}


def test_truncated_part_file_summarized_without_exception(tmp_path):
    path = _recorded_file(tmp_path)
    data = path.read_bytes()
    full = summarize(path)["messages"]
    rng = random.Random(1234)
    offsets = sorted({0, 1, 7, 8, 9, 30, len(data) - 1} | {rng.randrange(len(data)) for _ in range(300)})
    counts = []
    for cut in offsets:
        part = tmp_path / f"cut{cut}.mcap.part"
        part.write_bytes(data[:cut])
        s = summarize(part)
        assert not s["complete"] and s["truncated"] and s["error"] is None, cut
        assert s["valid_bytes"] <= cut
        assert s["messages"] == sum(s["topics"].values()) == len(read_messages(part, lenient=True))
        counts.append(s["messages"])
    assert counts == sorted(counts)  # a longer prefix never yields fewer messages
    assert 0 < counts[len(counts) // 2] < full


def test_corrupted_bytes_summarized_without_exception(tmp_path):
    path = _recorded_file(tmp_path)
    data = bytearray(path.read_bytes())
    rng = random.Random(99)
    for _ in range(200):
        damaged = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            damaged[rng.randrange(8, len(damaged))] ^= 1 << rng.randrange(8)
        part = tmp_path / "damaged.mcap.part"
        part.write_bytes(bytes(damaged[: rng.randrange(len(damaged) + 1)]))
        s = summarize(part)
        assert s["messages"] <= 84
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"not an mcap file at all")
    assert summarize(garbage)["error"] == "not an MCAP file (bad magic)"


def test_summarize_missing_file_is_sink_error(tmp_path):
    with pytest.raises(SinkError, match=r"nope.mcap: cannot read"):
        summarize(tmp_path / "nope.mcap")


# --- disk errors: a failed file is never written again --------------------------


def test_enospc_fails_the_file_and_keeps_what_was_flushed(tmp_path, clock):
    import os

    from cmsensord.sinks.mcap_sink import SinkIOError

    sink = McapSink(tmp_path, flush_s=1.0, clock=clock)
    for k in range(5):
        sink.write(TOPIC_EVENTS, "event", T0 + k, event_msg())
    sink.flush()
    full = os.open("/dev/full", os.O_WRONLY)
    os.dup2(full, sink.fileno())                 # the kernel answers ENOSPC from now on
    os.close(full)
    sink.write(TOPIC_EVENTS, "event", T0 + 5, event_msg())
    with pytest.raises(SinkIOError) as info:
        sink.flush()
    assert (info.value.op, info.value.errno) == ("write", 28) and "No space left" in str(info.value)
    assert sink.failed and sink.persisted == 5 and sink.unpersisted == 1
    with pytest.raises(SinkIOError, match="abandoned after an error"):
        sink.write(TOPIC_EVENTS, "event", T0 + 6, event_msg())
    with pytest.raises(SinkIOError, match="not finished"):
        sink.close()
    assert sink.part_path.exists() and not (tmp_path / sink.part_path.name[:-5]).exists()
    assert summarize(sink.part_path)["messages"] == 5


def test_numbering_goes_on_after_the_newest_file_of_the_same_second(tmp_path):
    clock = lambda: 1_700_000_000.0  # noqa: E731
    paths = [McapSink(tmp_path, wall_clock=clock).close() for _ in range(3)]
    paths[0].unlink()                             # retention deleted the oldest two
    paths[1].unlink()
    newest = McapSink(tmp_path, wall_clock=clock).close()
    assert newest.name == "cmsensord-20231114T221320Z-3.mcap"   # sorts after -2, not before


@pytest.mark.parametrize("n", [0, 1, 7, 500])
def test_message_index_is_the_record_the_mcap_library_builds(n):
    """The chunk writer packs each MessageIndex in one call: the same bytes as
    ``mcap.records.MessageIndex.write``."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import MessageIndex

    from cmsensord.sinks.mcap_chunks import message_index

    rnd = random.Random(n)
    records = [(rnd.randrange(1 << 63), rnd.randrange(1 << 40)) for _ in range(n)]
    builder = RecordBuilder()
    MessageIndex(channel_id=n % 65536 + 3, records=records).write(builder)
    assert message_index(n % 65536 + 3, records) == builder.end()
