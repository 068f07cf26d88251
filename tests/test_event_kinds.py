"""Every event the daemon can write fits the ``cmsensord.Event`` schema stored in its log.

A consumer that validates strictly (``jsonschema``) refuses a record whose ``kind`` is not in
the schema's enum. The source is read for every kind and extra field the code can give an
event (:mod:`event_kinds_scan`), and the replays that make the rare kinds are validated
message by message against the schema stored in the file they wrote.
"""

from __future__ import annotations

import collections
import json
from pathlib import Path

import pytest
from mcap.reader import make_reader

from cmsensord.alarms.manager import KIND as ALARM_KINDS
from cmsensord.config.capture import TRIGGER_KINDS
from cmsensord.monitor.events import LOG_LEVEL, UNLIMITED, WALL_KINDS
from cmsensord.report.marks import EVENT_STYLES
from cmsensord.sinks.event_schema import EVENT_KINDS
from cmsensord.sinks.schemas import SCHEMAS
from event_kinds_scan import scan
from foxglove_schema import message_problems
from processes import cmsensord, run_module


def test_every_kind_and_field_the_code_gives_an_event_is_in_the_schema():
    kinds, fields, problems = scan()
    assert problems == []
    # the scan sees each way of making one: Event(), proc.event(), the sink's and the link's
    # own, a constant of another module, the alarm manager's table
    assert {"decision_rule", "anomaly_held", "channels", "disk_error", "salvage", "link_lost",
            "tacho_missed_pulse", "alarm_danger", "mqtt_queue", "start"} <= set(kinds)
    assert sorted(set(kinds) - set(EVENT_KINDS)) == []
    declared = SCHEMAS["event"]["properties"]
    assert {"n_channels", "filters", "count", "details"} <= set(fields)
    assert sorted(set(fields) - set(declared)) == []


def test_the_kinds_other_modules_name_are_event_kinds():
    named = set(LOG_LEVEL) | UNLIMITED | WALL_KINDS | set(ALARM_KINDS.values()) | set(EVENT_STYLES)
    assert sorted(named - set(EVENT_KINDS)) == []
    assert sorted(set(TRIGGER_KINDS) - set(EVENT_KINDS)) == ["manual"]     # cmsensord capture-now


def _validate(path: Path) -> tuple[list[str], collections.Counter]:
    """Problems of each message against the schema stored in the file (a strict jsonschema
    validator and the Foxglove subset checker), and the kinds of its events."""
    import jsonschema

    problems: list[str] = []
    kinds: collections.Counter = collections.Counter()
    validators: dict[int, jsonschema.Draft202012Validator] = {}
    with open(path, "rb") as f:
        for schema, channel, m in make_reader(f).iter_messages(log_time_order=False):
            if schema.id not in validators:
                validators[schema.id] = jsonschema.Draft202012Validator(json.loads(schema.data))
            msg = json.loads(m.data)
            problems += [f"{channel.topic}: {e.message}" for e in validators[schema.id].iter_errors(msg)]
            problems += [f"{channel.topic}: {p}" for p in message_problems(msg, json.loads(schema.data))]
            if channel.topic == "/cm/events":
                kinds[msg["kind"]] += 1
    return problems, kinds


#: name -> (firmware_sim arguments of each capture, concatenated), the events of the rare kinds
RUNS = {
    # the tacho's f_r reaches the observations per decision on the run-up
    "whirl": ([["--scenario", "whirl", "--mode", "raw", "--tacho"]], {"decision_rule": 1}),
    # a flag held by the hysteresis alone for 60 decisions
    "faulty": ([["--scenario", "faulty", "--duration", "400"]], {"anomaly_held": 4}),
    # a board of 2 channels, then one of 1
    "two_then_one": ([["--scenario", "healthy", "--duration", "20", "--channels", "2"],
                      ["--scenario", "healthy", "--duration", "20", "--channels", "1", "--seed", "3"]],
                     {"channels": 1}),
}


@pytest.mark.parametrize("name", list(RUNS))
def test_replays_write_only_events_the_stored_schema_allows(tmp_path, name):
    captures, rare = RUNS[name]
    data = b""
    for i, args in enumerate(captures):
        part = tmp_path / f"{i}.bin"
        r = run_module("firmware_sim", *args, "--out", str(part))
        assert r.returncode == 0, r.stderr
        data += part.read_bytes()
    (tmp_path / "capture.bin").write_bytes(data)
    r = cmsensord("replay", str(tmp_path / "capture.bin"), "--out", str(tmp_path / "logs"))
    assert r.returncode == 0, r.stderr
    (log,) = (tmp_path / "logs").glob("*.mcap")
    problems, kinds = _validate(log)
    assert problems == []
    assert {k: kinds[k] for k in rare} == rare
