"""`cmsensord summary` and `cmsensord report` of a log whose ``cmsensord`` metadata (a replay's
recording timeline and capture path) is damaged or made hostile: a timeline that is not one is
not read (the log is drawn on its own time, as a board's), never a traceback."""

from __future__ import annotations

import json

import pytest
from mcap.writer import Writer

from processes import cmsensord

pytestmark = pytest.mark.process

S = 1_000_000_000
T0 = 1_796_132_784
GOOD = {"start_s": [0], "source_time_s": [0], "board_zero_ns": T0 * S}
#: (id, the ``recording_timeline`` text, the ``source``)
CASES = [
    ("zero-past-an-int", json.dumps(GOOD).replace(str(T0 * S), "1e999"), "/r.bin"),
    ("repaired-text", json.dumps({**GOOD, "repaired": "x"}), "/r.bin"),
    ("nested-past-the-parser", "[" * 100_000 + "]" * 100_000, "/r.bin"),
    ("nul-in-source", json.dumps(GOOD), "/a\0b.bin"),
]
IDS = [c[0] for c in CASES]


def _write(path, timeline: str, source: str) -> None:
    """A log of two events a second apart, its head metadata a replay's with ``timeline`` and ``source``."""
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="test")
        w.add_metadata("cmsensord", {"source": source, "recording_timeline": timeline})
        schema = w.register_schema(name="x", encoding="jsonschema", data=b"{}")
        channel = w.register_channel(topic="/cm/events", message_encoding="json", schema_id=schema)
        for i in range(2):
            data = json.dumps({"kind": "config", "message": "board firmware 1.0",
                               "timestamp": {"sec": T0 + i, "nsec": 0}}, separators=(",", ":")).encode()
            w.add_message(channel, log_time=(T0 + i) * S, publish_time=(T0 + i) * S, data=data)
        w.finish()


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    work = tmp_path_factory.mktemp("hostile_metadata")
    for name, timeline, source in CASES:
        _write(work / f"{name}.mcap", timeline, source)
    return work


def test_summary_reads_each_log_on_its_own_time(logs):
    """One summary of every log: exit 0, each log's events counted, its timeline not read."""
    p = cmsensord("summary", *(f"{name}.mcap" for name in IDS), cwd=logs)
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert p.stdout.count("event_counts:\n  config: 2\n") == len(CASES), p.stdout


@pytest.mark.parametrize("name", IDS)
def test_report_draws_the_log(logs, name):
    pytest.importorskip("matplotlib", reason="the report extra")
    p = cmsensord("report", f"{name}.mcap", "--out", f"{name}.html", cwd=logs)
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert p.stderr.splitlines()[-1] == f"report: {name}.html (0 figures, 2 messages from 1 file(s))", p.stderr
