"""The MCAP sink's encoding of flat messages from cached key and list JSON (issue 13) writes
the bytes of the JSON encoder's path (``_fast_body`` off: the reference), on random messages
of every value kind a message holds: floats (-0.0, tiny, huge, NaN, inf), ints, bools, None,
strings (non-ASCII, quotes, the word null), lists of each and mixed, nested dicts, numpy
scalars and arrays, tuples, and the same list again (cached) with 0.0 and -0.0, 1 and 1.0."""

from __future__ import annotations

import enum
import random

import numpy as np
import pytest

import cmsensord.sinks.mcap_encoding as encoding
from cmsensord.errors import SinkError


class Kind(enum.IntEnum):
    A = 2


def a_list(rnd: random.Random, depth: int) -> list:
    n = rnd.randrange(0, 12)
    kind = rnd.randrange(5)
    if kind == 0:
        return [rnd.choice([0.0, -0.0, 0.0166, 0.041800000000000004, 1e-9]) for _ in range(n)]
    if kind == 1:
        return [rnd.randrange(3) for _ in range(n)]
    if kind == 2:
        return [rnd.choice(["accel_peak", "kurtosis", "null", "ü"]) for _ in range(n)]
    return [value(rnd, depth + 1) for _ in range(n)]


VALUES = [
    lambda r, d: r.choice([0.0, -0.0, 1e-310, 1e300, 0.1, 2.5, -3.75, float("nan"), float("inf"), 28.66]),
    lambda r, d: r.uniform(-1e3, 1e3),
    lambda r, d: r.choice([0, 1, -7, 2**63, 10**30]),
    lambda r, d: r.choice([True, False]),
    lambda r, d: None if r.random() < 0.3 else "x",
    lambda r, d: r.choice(["ch0", "é ünï", 'q"uote\\', "null", "a\nb", "", "\u2603"]),
    lambda r, d: np.float64(r.choice([0.5, -0.0, 1e-5])),
    lambda r, d: np.int64(r.randrange(-5, 5)),
    lambda r, d: Kind.A,
    lambda r, d: r.choice([[0.0, 1.0], [-0.0, 1.0], [0, 1], [False, True], [1, 1.0], [], ["a", "b"]]),
    # containers (not below depth 2)
    a_list,
    lambda r, d: tuple(value(r, d + 1) for _ in range(r.randrange(4))),
    lambda r, d: np.array([r.random() for _ in range(r.randrange(4))]),
    lambda r, d: {r.choice(["a", "b", "link", "ü"]): value(r, d + 1) for _ in range(r.randrange(4))},
]


def value(rnd: random.Random, depth: int = 0):
    return VALUES[rnd.randrange(len(VALUES) if depth < 2 else 10)](rnd, depth)


def reference(topic: str, stamp: int, msg: dict, monkeypatch) -> bytes | str:
    with monkeypatch.context() as m:
        m.setattr(encoding, "_fast_body", lambda msg: None)
        try:
            return encoding.encode_message(topic, stamp, msg)
        except SinkError as exc:
            return str(exc)


@pytest.mark.parametrize("seed", range(6))
def test_fast_encoding_writes_the_encoders_bytes(seed, monkeypatch):
    rnd = random.Random(seed)
    fast = 0
    for _ in range(1500):
        msg = {rnd.choice(["channel", "r", "level", "anomaly", "f_r", "x", "é", "timestamp"]): value(rnd)
               for _ in range(rnd.randrange(0, 8))}
        stamp = rnd.randrange(0, 2**62)
        ref = reference("/t", stamp, msg, monkeypatch)
        try:
            got: bytes | str = encoding.encode_message("/t", stamp, msg)
        except SinkError as exc:
            got = str(exc)
        assert got == ref, msg
        fast += encoding._fast_body(msg) is not None
    assert fast > 300                   # many took the fast path, the rest the encoder's


def test_a_cached_list_is_not_taken_for_an_equal_list_of_other_values(monkeypatch):
    for first, second in (([0.0, 1.0], [-0.0, 1.0]), ([1, 0], [1.0, 0.0]), ([1, 0], [True, False])):
        for lst in (first, second, first):
            msg = {"r": lst}
            assert encoding.encode_message("/t", 5, msg) == reference("/t", 5, msg, monkeypatch)
    assert encoding.encode_message("/t", 5, {"r": [-0.0, 1.0]}).endswith(b'"r":[-0.0,1.0]}')
