"""A RAW stream with a tacho gives the same messages however it is read: reads of 997 bytes,
64 kB and 1 MiB give every topic's messages alike (not /cm/diagnostics, which tells how the
stream was read), and every indicator interval its shaft speed.  Each stream holds what makes the
chains wait for the speed or start again: a link loss of a minute, a board clock jumping a minute,
board resets, a change of rate, a board slower than 25 kHz (one read then holds more board seconds
than the 10 s a wait for the speed lasts).  Before, a large read let the waits end before the
TACHO frames in front of them were fed: intervals and orders without a speed, or with one that
decayed towards zero, and decisions on the configured f_r."""

from __future__ import annotations

import pytest

from cmsensord.config import config_from_dict
from cmsensord.protocol import Decoder
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from stream import run_processor

READS = (997, 65_536, 1 << 20)
#: frames a second of a 1-channel RAW board with a tacho: a RAW and a TACHO frame a block, a STATUS
FRAMES_PER_S = 201


def board(seconds: float, *, fs: int = 25_000, t0: int = 0, seq: int = 0) -> bytes:
    """A healthy motor at 1720 rpm on a 1-channel RAW board with a tacho."""
    sc = make_scenario("healthy", n_channels=1, duration_s=seconds, seed=1, fs=fs)
    cfg = BoardConfig(mode="raw", n_channels=1, fs=fs, t0_start=t0, seq_start=seq & 0xFFFF, tacho=True)
    return Board(sc, cfg).generate(seconds)


def frames(data: bytes) -> int:
    return len(Decoder().feed(data))


def link_loss() -> bytes:
    first = board(6)
    return first + board(6, t0=150_000 + 60 * 25_000, seq=frames(first) + 60 * FRAMES_PER_S)


def clock_jump() -> bytes:
    first = board(6)
    return first + board(6, t0=150_000 + 60 * 25_000, seq=frames(first))


def resets() -> bytes:
    return board(14) * 3


def rate_change() -> bytes:
    first = board(6)
    return first + board(12, fs=12_500, t0=150_000, seq=frames(first))


def slow_board() -> bytes:
    return board(24, fs=12_500)


def by_topic(data: bytes, read: int) -> dict[str, list]:
    topics: dict[str, list] = {}
    for topic, stamp, msg in run_processor(data, config_from_dict({}), chunk=read)[0].messages:
        if topic != "/cm/diagnostics":
            topics.setdefault(topic, []).append((stamp, msg))
    return topics


@pytest.mark.parametrize("make", [link_loss, clock_jump, resets, rate_change, slow_board])
def test_the_messages_do_not_depend_on_the_read_size(make):
    data = make()
    runs = [by_topic(data, read) for read in READS]
    for topic in runs[0]:
        assert runs[1][topic] == runs[0][topic], (topic, READS[1])
        assert runs[2][topic] == runs[0][topic], (topic, READS[2])
    assert runs[1].keys() == runs[0].keys() == runs[2].keys()
    speeds = [m.get("speed_rpm") for _, m in runs[0]["/cm/ch0/indicators"]]
    assert len(speeds) >= 12 and all(v is not None and abs(v - 1720) < 20 for v in speeds), speeds
    orders = [m["speed_rpm"] for _, m in runs[0]["/cm/ch0/orders"] if m["valid"]]
    assert len(orders) >= 100 and all(abs(v - 1720) < 20 for v in orders)
