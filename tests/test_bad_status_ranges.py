"""A CRC-good STATUS whose set-up is outside the protocol's ranges (mode 1 or 2, 1..8 channels, fs
1 Hz..1 MHz, block_len 1..2048 and at least a block a second) is one `decode_error` and the
previous STATUS is kept: one with fs 2^32 - 1 had the replay and the live daemon allocate 32 GiB
and die, one with 0 channels stopped the observations in silence. A RAW count past the ADC's 12
bits skips its frame with a `decode_error` (it read 4121 m/s2 on a +-196 m/s2 channel)."""

from __future__ import annotations

import struct

import pytest

from cmsensord.protocol import Decoder, FrameType
from test_bad_frames import rebuilt
from test_read_size import board
from test_stream_events import replay

#: fw, mode, channels, fs, block_len, tacho inputs, ppr, overruns, uptime
_HEAD = struct.Struct("<HBBIHBBII")


def _status(payload: bytes, **change) -> bytes:
    fields = dict(zip(("fw", "mode", "c", "fs", "block_len", "tacho", "ppr", "overruns", "uptime"),
                      _HEAD.unpack_from(payload)))
    fields.update(change)
    per_channel = payload[_HEAD.size:_HEAD.size + 8] * fields["c"]
    return _HEAD.pack(*fields.values()) + per_channel


@pytest.mark.parametrize("mode", ["raw", "rms"])
@pytest.mark.parametrize("change, said", [
    ({"fs": 0xFFFFFFFF}, "fs 4294967295 Hz (1..1,000,000 Hz)"),
    ({"fs": 0}, "fs 0 Hz (1..1,000,000 Hz)"),
    ({"c": 0}, "0 channels (the protocol's: 1..8)"),
    ({"c": 200}, "200 channels (the protocol's: 1..8)"),
    ({"mode": 3}, "mode 3 (the protocol's: 1 RMS, 2 RAW)"),
    ({"block_len": 65535}, "block_len 65535 (1..2048 samples, at least one block a second)"),
    ({"fs": 100}, "block_len 250 (1..2048 samples, at least one block a second)"),
], ids=["fs_max", "fs_0", "c_0", "c_200", "mode_3", "block_65535", "block_over_fs"])
def test_a_status_out_of_range_is_one_event_and_the_setup_stays(tmp_path, mode, change, said):
    clean = board(mode, 12)
    bad, changed = rebuilt(clean, lambda i, f: f._replace(payload=_status(f.payload, **change))
                           if f.type is FrameType.STATUS and f.t0 == 175_000 else f)
    assert len(changed) == 1
    offset = next(f.offset for f in Decoder().feed(bad) if f.type is FrameType.STATUS and f.t0 == 175_000)
    events = replay(tmp_path, bad)
    errors = [e for e in events if e.startswith("decode_error")]
    assert errors == [f"decode_error | STATUS at byte {offset} ignored: {said}: the previous STATUS is kept"]
    summary = (tmp_path / "stderr.txt").read_text()
    assert "12.0 s of ADC time" in summary and "0 missing, 0 frames lost" in summary, summary


def test_raw_counts_past_12_bits_skip_their_frame(tmp_path):
    def change(i, f):
        if f.type is FrameType.RAW and f.t0 in (100_000, 175_000, 250_000):
            return f._replace(payload=bytes([0xFF, 0xF0]) + f.payload[2:])
        return f

    bad, changed = rebuilt(board("raw", 12), change)
    assert len(changed) == 3
    events = replay(tmp_path, bad)
    assert [e for e in events if e.startswith("decode_error")] == [
        f"decode_error | RAW frame of channel 0 at t0 {t0} skipped: count 61695 past the ADC's 12 bits (0..4095)"
        for t0 in (100_000, 175_000, 250_000)]
    summary = (tmp_path / "stderr.txt").read_text()
    assert "(1197 observations, 3 missing, 0 frames lost)" in summary, summary
