"""A decision's messages formatted from templates (`cmsensord.sinks.json_templates`) are the
bytes of the plain JSON encoder's path (`encode_message`), or not formatted at all: on the
messages of a damaged faulty capture and on messages with every kind of deviation (further or
reordered fields, None, NaN, infinities, -0.0, bools for ints, ints for floats, numpy values,
tuples, strings needing escapes)."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from cmsensord.sinks import json_templates
from cmsensord.sinks.json_templates import TEMPLATES
from cmsensord.sinks.mcap_encoding import REPEATED, encode_message

#: values a field may take instead of the usual one
ODD = [None, math.nan, math.inf, -math.inf, 0.0, -0.0, 1.0, 0.5, 1e-300, 1e300, 3, -7, 0, True, False,
       np.float64(0.25), np.int64(4), "x", "é\n\"", [], [1], (0.5,), {"a": 1}]


def plain(topic: str, stamp: int, msg: dict, schema: str) -> bytes:
    return encode_message(topic, stamp, msg, REPEATED.get(schema))


def usual(kind: str, rnd: random.Random) -> dict:
    """A message of ``kind`` as the daemon makes it, with random values of the usual types."""
    n = rnd.choice([1, 3, 10])
    if kind == "severity":
        return {"channel": rnd.choice(["ch0", "motor \"A\"", "Lüfter"]), "severity_index": rnd.choice([0.0, 0.3, 1.0]),
                "level": rnd.randrange(11), "anomaly": [rnd.randrange(2) for _ in range(n)],
                "outliers": [rnd.randrange(60) for _ in range(n)], "f_r": rnd.choice([28.66, 30.0, 2.5]),
                "r": rnd.choice([[0.0166, 0.0292, 0.0418], [0.13], [0.5, 1.25, 2.75], [0.1] * n]),
                "failure": rnd.random() < 0.5, "missing": rnd.randrange(5), "transient": rnd.random() < 0.5}
    if kind == "indicators":
        return {"channel": rnd.choice(["ch0", "ch1"]), "mode": "rms", "interval_s": rnd.choice([1.0, 0.5, 2]),
                "missing_fraction": rnd.choice([0.0, 0.25, rnd.random()]), "accel_rms": rnd.random() * 3,
                "unavailable": rnd.choice([["accel_peak", "kurtosis"], [], ["speed"]])}
    return {"link": {"bytes_received": rnd.randrange(10**9), "frames_lost": rnd.randrange(3)},
            "queue_depth": 0, "queue_drops": 0, "lag_s": rnd.choice([0.0, 0.125]),
            "observations": rnd.randrange(10**6), "uptime_s": rnd.random() * 100}


def deviate(msg: dict, rnd: random.Random) -> dict:
    """The message with one field changed, dropped, added or moved, or an item of a list changed."""
    msg = dict(msg)
    key = rnd.choice(list(msg))
    how = rnd.randrange(6)
    if how == 0:
        msg[key] = rnd.choice(ODD)
    elif how == 1:
        del msg[key]
    elif how == 2:
        msg["extra"] = 1.5
    elif how == 3:
        msg[key] = msg.pop(key)                 # moved to the end
    elif how == 4 and isinstance(msg[key], list) and msg[key]:
        items = list(msg[key])
        items[rnd.randrange(len(items))] = rnd.choice(ODD)
        msg[key] = items
    elif how == 5 and isinstance(msg[key], dict):
        msg[key] = {**msg[key], rnd.choice(["k", 5]): rnd.choice(ODD)}
    else:
        msg[key] = tuple(msg[key]) if isinstance(msg[key], list) else rnd.choice(ODD)
    return msg


@pytest.mark.parametrize("kind", sorted(TEMPLATES))
def test_a_template_gives_the_plain_bytes_or_leaves_the_message_to_the_plain_path(kind, monkeypatch):
    for cache in ("_lists", "_float_lists", "_str_lists", "_strings", "_floats_kept"):
        monkeypatch.setattr(json_templates, cache, {})
    monkeypatch.setattr(json_templates, "_MAX_LISTS", 40)     # kept lists cleared now and then
    rnd = random.Random(kind)
    formatted = left = 0
    for k in range(6000):
        msg = usual(kind, rnd)
        for _ in range(rnd.choice([0, 0, 1, 2])):
            msg = deviate(msg, rnd)
        stamp = rnd.choice([0, 10**9 - 1, 1_790_000_000_123_456_789 + k])
        got = TEMPLATES[kind](stamp, msg)
        if got is None:
            left += 1
            continue
        formatted += 1
        assert got.encode() == plain(f"/cm/{kind}", stamp, msg, kind), msg
    assert formatted > 2500 and left > 1000      # both ways taken, many times


def test_equal_values_of_other_types_are_never_taken_from_what_is_kept(monkeypatch):
    """1 == 1.0 == True and 0.0 == -0.0: a list or a float kept is not reused for them."""
    for cache in ("_lists", "_float_lists", "_str_lists", "_strings", "_floats_kept"):
        monkeypatch.setattr(json_templates, cache, {})
    base = usual("severity", random.Random(1))
    for field, first, then in [("anomaly", [1, 0], [True, False]), ("anomaly", [1, 0], [1.0, 0]),
                               ("outliers", [0, 2], [False, 2]), ("r", [0.5, 1.5], [0.5, 1.5]),
                               ("r", [0.25, 1.0], [0.25, 1]), ("f_r", 2.5, 2.5), ("f_r", 0.0, -0.0),
                               ("f_r", 3.0, 3), ("severity_index", 0.0, -0.0)]:
        for value in (first, then):
            msg = {**base, field: value}
            got = TEMPLATES["severity"](5, msg)
            assert got is None or got.encode() == plain("/cm/ch0/severity", 5, msg, "severity"), (field, value)
    link = {"frames_lost": 1}
    diag = usual("diagnostics", random.Random(2))
    for value in (link, {"frames_lost": True}, {"frames_lost": 1.0}):
        msg = {**diag, "link": value}
        got = TEMPLATES["diagnostics"](5, msg)
        assert got is None or got.encode() == plain("/cm/diagnostics", 5, msg, "diagnostics")
    assert TEMPLATES["diagnostics"](5, {**diag, "link": {"frames_lost": True}}) is None


def test_a_damaged_faulty_capture_s_decisions_are_formatted_as_the_plain_path_encodes_them(tmp_path):
    """Every severity message, RMS indicator record and diagnostics message the Processor
    writes for a damaged faulty capture (anomalies, failures, lost frames) is formatted, and
    its bytes are the plain path's."""
    from cmsensord.config.loading import default_config
    from cmsensord.monitor.processor import Processor
    from cmsensord.source import CaptureSource
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    class Keep:
        def __init__(self) -> None:
            self.messages: list[tuple[str, str, int, dict]] = []

        def write(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> None:
            self.messages.append((topic, schema, stamp_ns, msg))

        def write_group(self, messages: list) -> None:
            self.messages += messages

    cap = tmp_path / "cap.bin"
    Board(make_scenario("faulty", n_channels=3, duration_s=90.0, seed=2), BoardConfig(n_channels=3)) \
        .write_capture(cap, 90.0)
    data = bytearray(cap.read_bytes())
    rnd = random.Random(4)
    for _ in range(15):
        data[rnd.randrange(len(data))] ^= 1 << rnd.randrange(8)
    cap.write_bytes(bytes(data))
    sink = Keep()
    source = CaptureSource(cap, batches=True)
    proc = Processor(default_config(3), sink, link_counters=source.counters.as_dict)
    with source:
        for frames in source:
            proc.handle(frames)
    proc.finish()
    seen: dict[str, int] = {}
    for topic, schema, stamp, msg in sink.messages:
        if schema in TEMPLATES:
            got = TEMPLATES[schema](stamp, msg)
            assert got is not None, msg
            assert got.encode() == plain(topic, stamp, msg, schema)
            seen[schema] = seen.get(schema, 0) + 1
    assert min(seen.values()) >= 80 and len(seen) == 3
    assert any(m["failure"] for _, s, _, m in sink.messages if s == "severity")
