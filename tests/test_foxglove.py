"""The MCAP logs as Foxglove reads them: schemas its JSON-schema reader accepts, messages that fit
them, events on Foxglove's Log panel, files in log-time order, no empty file, the layout.

The logs are those of real runs: ``cmsensord --simulate`` in RMS mode (two channels, the AKF
trace), in RAW mode with a tacho (close_orders) and with a microphone (degrading_mic: the
vibration estimate), and ``cmsensord replay`` of a RAW whirl capture (orders lagging seconds
behind the decisions).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader

from cmsensord.config import default_config
from cmsensord.service.simulate import RUNUP_ORDERS
from cmsensord.sinks.rotating import RotatingSink
from cmsensord.sinks.schemas import SCHEMAS, schema_bytes
from fakes import FakeClock
from foxglove_schema import message_problems, schema_problems
from mcap_doctor import doctor
from processes import ROOT, cmsensord, run_module


def _read(path: Path):
    """(topic, schema name, schema dict, log_time, publish_time, message) of every message."""
    with open(path, "rb") as f:
        for schema, channel, m in make_reader(f).iter_messages(log_time_order=False):
            yield (channel.topic, schema.name, json.loads(schema.data), m.log_time, m.publish_time,
                   json.loads(m.data))


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, list[Path]]:
    """name -> the finished MCAP files of that run."""
    base = tmp_path_factory.mktemp("foxglove")
    out: dict[str, list[Path]] = {}
    r = cmsensord("--simulate", "--scenario", "degrading", "--duration", "60", "--speed", "30",
                  "--channels", "2", "--akf-trace", "--out", str(base / "rms"))
    assert r.returncode == 0, r.stderr
    r = cmsensord("--simulate", "--scenario", "close_orders", "--duration", "10", "--out", str(base / "raw"))
    assert r.returncode == 0, r.stderr
    r = cmsensord("--simulate", "--scenario", "degrading_mic", "--duration", "30", "--out", str(base / "mic"))
    assert r.returncode == 0, r.stderr
    cap = base / "whirl.bin"
    r = run_module("firmware_sim", "--scenario", "whirl", "--mode", "raw", "--tacho", "--duration", "40",
                   "--out", str(cap))
    assert r.returncode == 0, r.stderr
    cfg = base / "whirl.yaml"
    cfg.write_text(json.dumps({"orders": RUNUP_ORDERS["whirl"]}))       # JSON is YAML
    r = cmsensord("replay", str(cap), "--config", str(cfg), "--out", str(base / "replay"))
    assert r.returncode == 0, r.stderr
    for name in ("rms", "raw", "replay", "mic"):
        out[name] = sorted((base / name).glob("*.mcap"))
        assert out[name], name
    return out


def test_every_schema_is_one_foxglove_reads():
    for kind, schema in SCHEMAS.items():
        assert schema_problems(schema) == [], kind
        assert b"null" not in schema_bytes(kind), kind


def test_the_checker_refuses_what_foxglove_refuses():
    """The restricted checker is not a yes-man: the forms Foxglove's reader rejects fail it."""
    base = {"type": "object", "properties": {}}
    assert schema_problems({**base, "properties": {"a": {"type": ["number", "null"]}}}) == [
        "a: unsupported type ['number', 'null']"]
    assert schema_problems({**base, "properties": {"d": {"type": "object"}}}) == [
        'd: an object without "properties"']
    assert schema_problems({**base, "properties": {"e": {"oneOf": [{"const": "x"}]}}}) == [
        "e: oneOf alternatives must have number values"]
    assert schema_problems({**base, "properties": {"m": {"type": "array", "items": {"type": "array"}}}}) == [
        "m[]: unsupported type 'array' for array item"]
    schema = {**base, "properties": {"x": {"type": "number"}}, "required": ["x"]}
    assert message_problems({"x": None, "y": 1}, schema) == [
        "x: null (a missing value must be an absent field)", "y: not declared in the schema"]
    assert message_problems({}, schema) == ["<root>: required field 'x' absent"]


@pytest.mark.parametrize("run", ["rms", "raw", "replay", "mic"])
def test_every_topic_and_message_fits_a_schema_foxglove_reads(runs, run):
    topics: dict[str, int] = {}
    problems: list[str] = []
    for path in runs[run]:
        for topic, name, schema, _, _, msg in _read(path):
            if topic not in topics:
                problems += [f"{topic} schema {name}: {p}" for p in schema_problems(schema)]
            topics[topic] = topics.get(topic, 0) + 1
            problems += [f"{topic}: {p}" for p in message_problems(msg, schema)]
    assert problems[:10] == []
    expected = {"/cm/events", "/cm/log", "/cm/diagnostics", "/cm/ch0/severity"}
    if run == "rms":
        expected |= {"/cm/ch0/akf", "/cm/ch1/akf", "/cm/ch1/severity"}
    elif run == "mic":          # the microphone beside the accelerometer: its vibration estimate
        expected.add(next(t for t in topics if t.endswith("/vibration_estimate")))
    else:
        expected.add("/cm/ch0/orders")
    assert expected <= set(topics), topics


@pytest.mark.parametrize("run", ["rms", "raw", "replay", "mic"])
def test_files_are_in_log_time_order_as_mcap_doctor_checks(runs, run):
    for path in runs[run]:
        assert doctor(path) == [], path
    if run in ("raw", "replay"):    # the orders come seconds behind the decisions: held, not clamped
        orders = [(lt, pt) for p in runs[run] for t, _, _, lt, pt, _ in _read(p) if t == "/cm/ch0/orders"]
        assert len(orders) > 50
        assert all(lt == pt for lt, pt in orders)


def test_events_are_also_on_the_log_panel_topic(runs):
    events = [(lt, m) for p in runs["rms"] for t, _, _, lt, _, m in _read(p) if t == "/cm/events"]
    logs = {(lt, m["message"]): (n, m) for p in runs["rms"] for t, n, _, lt, _, m in _read(p)
            if t == "/cm/log"}
    assert len(logs) == len(events) > 20
    levels = {}
    for lt, ev in events:
        name, log = logs[(lt, f"{ev['kind']}: {ev['message']}")]
        assert name == "foxglove.Log"
        assert log["name"] == ev.get("channel", "cmsensord")
        assert log["timestamp"] == ev["timestamp"]
        levels[ev["kind"]] = log["level"]
    assert levels["failure"] == 3 and levels["severity_change"] == 2          # WARNING, INFO
    assert levels["anomaly_onset"] == 1 and levels["start"] == 2              # DEBUG, INFO


def test_a_rotation_leaves_no_empty_file(tmp_path):
    """A file opened by a rotation that nothing is written to is not left behind."""
    import dataclasses
    clock = FakeClock()
    output = dataclasses.replace(default_config(1).output, dir=str(tmp_path), rotate_s=10.0)
    sink = RotatingSink(output, clock=clock, wall_clock=lambda: 1.8e9 + clock())
    for k in range(5):
        sink.write("/cm/diagnostics", "diagnostics", 10**18 + k * 10**9, {"link": {}})
    clock.t += 10.0
    sink.tick()                          # rotation by time: a second file is open
    sink.close()
    files = sorted(tmp_path.glob("*.mcap*"))
    assert [f.suffix for f in files] == [".mcap"]
    assert sum(1 for _ in _read(files[0])) == 5


def test_the_layout_shows_existing_topics(runs):
    layout = json.loads((ROOT / "docs" / "foxglove-layout.json").read_text())
    text = json.dumps(layout)
    topics = {t for p in runs["rms"] + runs["raw"] for t, *_ in _read(p)}
    kinds = {key.split("!")[0] for key in layout["configById"]}
    assert {"Plot", "Log", "RawMessages"} <= kinds
    for topic in ("/cm/ch0/severity.severity_index", "/cm/ch0/orders.orders[0].rms",
                  "/cm/ch0/orders.speed_rpm"):
        assert topic in text, topic
    for key, panel in layout["configById"].items():
        if key.startswith("Log!"):
            assert panel["topicToRender"] == "/cm/log"
        for series in panel.get("paths", []):
            assert series["value"].split(".")[0] in topics, series
    assert layout["configById"][next(k for k in layout["configById"] if k.startswith("RawMessages!"))][
        "topicPath"] == "/cm/diagnostics"


def test_vkf_writes_its_batch_orders_in_log_time_order(tmp_path):
    """``cmsensord vkf`` adds the batch orders of the whole run after it: the file is still in
    log-time order, each batch message at its own stamp (none clamped)."""
    cap = tmp_path / "co.bin"
    r = run_module("firmware_sim", "--scenario", "close_orders", "--mode", "raw", "--tacho", "--out", str(cap))
    assert r.returncode == 0, r.stderr
    r = cmsensord("vkf", str(cap), "--out", str(tmp_path / "logs"))
    assert r.returncode == 0, r.stderr
    path, = (tmp_path / "logs").glob("*.mcap")
    assert doctor(path) == []
    batch = [(lt, pt) for t, _, _, lt, pt, m in _read(path) if t.endswith("/orders") and m["method"] == "batch"]
    assert len(batch) > 20 and all(lt == pt for lt, pt in batch)
