"""`cmsensord report` of logs on cmsensord's topics whose messages have a field the report draws of
another type than cmsensord writes (another program's MCAP, an edited or damaged log): each such
message is left out and counted in its file's line, and the report draws the rest. One report
over a log a case (one process: the report's start costs more than its drawing)."""

from __future__ import annotations

import json

import pytest
from mcap.writer import Writer

from processes import cmsensord

pytestmark = pytest.mark.process
pytest.importorskip("matplotlib", reason="the report extra")

S = 1_000_000_000
T0 = 1_796_132_784
WAVEFORM = {"channel": "ch0", "trigger": {"kind": "periodic", "message": "every 60 s"}, "source": "raw",
            "sample_rate_hz": 100.0, "pre_s": 0.1, "unit": "m/s^2", "samples": [0.0, 1.0, 0.0, -1.0] * 5}
#: a message cmsensord writes on each topic (the fields the report draws)
VALID = {
    "/cm/events": {"kind": "config", "message": "board firmware 1.0"},
    "/cm/diagnostics": {"link": {"bytes_received": 100, "crc_failures": 0}, "queue_depth": 0, "queue_drops": 0,
                        "lag_s": 0.01, "uptime_s": 1.0},
    "/cm/ch0/severity": {"channel": "ch0", "severity_index": 0.2, "anomaly": [0, 0], "level": 0},
    "/cm/ch0/indicators": {"channel": "ch0", "accel_rms": 1.5, "zone_boundaries_mm_s": [1.4, 2.8, 4.5]},
    "/cm/ch0/orders": {"channel": "ch0", "valid": True, "speed_rpm": 1500.0,
                       "orders": [{"name": "1x", "rms": 0.3, "freq_hz": 25.0}]},
    "/cm/alarms": {"alarms": [{"rule": "vel", "indicator": "velocity_rms_mm_s", "channel": "ch0",
                               "alert_level": 4.5}]},
    "/cm/ch0/capture_waveform": WAVEFORM,
}
#: (topic, field, its value of a wrong type)
CASES = [
    ("/cm/events", "message", {"a": 1}),
    ("/cm/diagnostics", "link", "x"),
    ("/cm/ch0/capture_waveform", "samples", "x"),
    ("/cm/ch0/severity", "severity_index", "x"),
    ("/cm/ch0/severity", "severity_index", None),
    ("/cm/ch0/severity", "severity_index", float("nan")),
    ("/cm/ch0/indicators", "zone_boundaries_mm_s", ["a", "b", "c"]),
    ("/cm/ch0/orders", "orders", [5]),
    ("/cm/alarms", "alarms", 5),
]
IDS = [f"{t.rsplit('/', 1)[1]}-{f}-{type(v).__name__}" for t, f, v in CASES]


def _write(path, topic: str, field: str, value) -> None:
    """A log of an event, two messages of ``topic`` as cmsensord writes them, and one whose
    ``field`` is ``value``, a second apart (compact JSON, as cmsensord's)."""
    messages = [("/cm/events", VALID["/cm/events"]), (topic, VALID[topic]), (topic, VALID[topic]),
                (topic, {**VALID[topic], field: value})]
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="test")
        schema = w.register_schema(name="x", encoding="jsonschema", data=b"{}")
        channels: dict[str, int] = {}
        for i, (name, msg) in enumerate(messages):
            if name not in channels:
                channels[name] = w.register_channel(topic=name, message_encoding="json", schema_id=schema)
            data = json.dumps({**msg, "timestamp": {"sec": T0 + i, "nsec": 0}}, separators=(",", ":")).encode()
            w.add_message(channels[name], log_time=(T0 + i) * S, publish_time=(T0 + i) * S, data=data)
        w.finish()


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """The report of a log a case: (the process, the work directory)."""
    work = tmp_path_factory.mktemp("hostile_fields")
    for name, case in zip(IDS, CASES):
        _write(work / f"{name}.mcap", *case)
    p = cmsensord("report", *(f"{name}.mcap" for name in IDS), "--out", "r.html", cwd=work)
    return p, work


def test_the_report_draws_the_rest(report):
    """Exit 0; of the messages as cmsensord writes them the figures (ch0's severity, indicators,
    orders, two captures) and the events (all but one); each file's messages left out in its row."""
    p, work = report
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines()[-1] == f"report: r.html (5 figures, {4 * len(CASES)} messages from 9 file(s))"
    page = (work / "r.html").read_text(encoding="utf-8")
    assert page.count("<td>board firmware 1.0</td>") == len(CASES) + 2      # the events' log: 3
    assert page.count("messages left out: 1 on cmsensord&#x27;s topics that are not its JSON objects; ") == len(CASES)


@pytest.mark.parametrize("name", IDS)
def test_a_message_with_a_field_of_a_wrong_type_is_left_out_and_counted(report, name):
    p, _ = report
    assert (f"cmsensord: report: {name}.mcap: of its 4 message(s), 1 on cmsensord's topics that are not its JSON "
            "objects: left out") in p.stderr.splitlines()
