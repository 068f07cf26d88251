"""RMS frames whose values or channel count the board cannot send: each fed by one small capture
built with the protocol encoder and replayed by a real ``cmsensord replay`` process, whose
events and exit summary say what was dropped.

* An RMS value that is not finite, negative or above what the 12-bit ADC gives at the channel's
  STATUS scale and offset is a missing observation and one ``decode_error`` at its frame's t0.
* RMS frames that keep their channel count after a STATUS announced another are dropped, one
  ``decode_error`` for each 100 in a row, as RMS frames of a board in RAW mode are.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from cmsensord.protocol import MODE_RMS, Status, encode_rms, encode_status
from test_stream_events import replay, summary_observations

pytestmark = pytest.mark.process

FS, L = 25000, 250
#: two channels of 0.01 m/s² per count about 2048: an RMS of at most 20.48 m/s²
STATUS = Status(0x0100, MODE_RMS, 2, FS, L, 0, 0, 0, 0, (0.01, -0.01), (2048.0, 2048.0))


def rms_capture(values: dict[int, tuple[float, float]], blocks: int = 300, status: Status = STATUS) -> bytes:
    """A STATUS each second, then one RMS frame per block: 0.5 and 0.7 m/s², ``values`` at those blocks."""
    out, seq = bytearray(), 0
    for k in range(blocks):
        if k % 100 == 0:
            out += encode_status(seq, k * L, status)
            seq += 1
        out += encode_rms(seq, k * L, np.array(values.get(k, (0.5, 0.7)), dtype=np.float32))
        seq += 1
    return bytes(out)


@pytest.fixture
def impossible_values() -> bytes:
    """NaN, +inf, a negative RMS, 3e38 and 21 m/s² (past 20.48); 20.48 itself is possible."""
    nan, inf = float("nan"), float("inf")
    return rms_capture({50: (nan, 0.7), 100: (0.5, inf), 150: (-5.0, 0.7), 200: (0.5, 3e38),
                        230: (21.0, 0.7), 260: (20.48, 20.48)})


def test_impossible_rms_values_are_missing_observations_with_a_decode_error_each(tmp_path, impossible_values):
    events = replay(tmp_path, impossible_values)
    past = "the most 12-bit counts give at its STATUS scale and offset"
    assert [e for e in events if e.startswith("decode_error")] == [
        f"decode_error | RMS frame at t0 {50 * L}: ch0's value nan m/s² is impossible (not finite): a missing "
        "observation",
        f"decode_error | RMS frame at t0 {100 * L}: ch1's value inf m/s² is impossible (not finite): a missing "
        "observation",
        f"decode_error | RMS frame at t0 {150 * L}: ch0's value -5 m/s² is impossible (negative): a missing "
        "observation",
        f"decode_error | RMS frame at t0 {200 * L}: ch1's value 3e+38 m/s² is impossible (above 20.482 m/s², {past}): "
        "a missing observation",
        f"decode_error | RMS frame at t0 {230 * L}: ch0's value 21 m/s² is impossible (above 20.482 m/s², {past}): "
        "a missing observation"]
    assert summary_observations(tmp_path) == (595, 5)
    summary = (tmp_path / "stderr.txt").read_text()
    said = re.findall(r"^  ch\d: \d+ RMS value.*$", summary, re.M)
    tail = ("RMS value(s) the board cannot send (not finite, negative or past its ADC's range): missing "
            "observations, see the decode_error events")
    assert said == [f"  ch0: 3 {tail}", f"  ch1: 2 {tail}"], summary
    assert "  events: config 1, decode_error 5" in summary.splitlines(), summary


@pytest.fixture
def status_says_3_frames_carry_2() -> bytes:
    """3 s of two channels, a STATUS saying 3 channels at 1 s and each second on, the RMS frames still of 2."""
    three = dataclasses.replace(STATUS, n_channels=3, scale=STATUS.scale + (0.01,), offset=STATUS.offset + (2048.0,))
    out, seq = bytearray(), 0
    for k in range(300):
        if k % 100 == 0:
            out += encode_status(seq, k * L, STATUS if k == 0 else three)
            seq += 1
        out += encode_rms(seq, k * L, np.array((0.5, 0.7), dtype=np.float32))
        seq += 1
    return bytes(out)


def test_rms_frames_disagreeing_with_the_status_channel_count_are_dropped_with_a_decode_error(
        tmp_path, status_says_3_frames_carry_2):
    events = replay(tmp_path, status_says_3_frames_carry_2)
    assert [e for e in events if e.startswith("decode_error")] == [
        "decode_error | 100 RMS frame(s) of 2 channel(s) dropped: the board's STATUS says 3 channel(s)"] * 2
    assert summary_observations(tmp_path) == (200, 0)      # the first second's two channels
