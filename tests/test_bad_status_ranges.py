"""A CRC-good STATUS whose set-up is outside the protocol's ranges (mode 1 or 2, 1..8 channels, fs
1 Hz..1 MHz, block_len 1..2048 and at least a block a second) is one `decode_error` and the
previous STATUS is kept: one with fs 2^32 - 1 had the replay and the live daemon allocate 32 GiB
and die, one with 0 channels stopped the observations in silence. A RAW count past the ADC's 12
bits skips its frame with a `decode_error` (it read 4121 m/s2 on a +-196 m/s2 channel)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from cmsensord.protocol import Decoder, FrameType
from processes import run_module
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
    ({"fs": 0xFFFFFFFF}, "fs 4294967295 Hz / block_len 250: 17,179,869 blocks a second (at most 100,000)"),
    ({"fs": 0}, "fs 0 Hz, block_len 250 (each at least 1)"),
    ({"block_len": 0}, "fs 25000 Hz, block_len 0 (each at least 1)"),
    ({"c": 0}, "0 channels (the protocol's: 1..8)"),
    ({"c": 200}, "200 channels (the protocol's: 1..8)"),
    ({"mode": 3}, "mode 3 (the protocol's: 1 RMS, 2 RAW)"),
], ids=["fs_max", "fs_0", "block_0", "c_0", "c_200", "mode_3"])
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


def test_a_raw_block_longer_than_a_frame_is_out_of_range(tmp_path):
    bad, _ = rebuilt(board("raw", 12), lambda i, f: f._replace(payload=_status(f.payload, block_len=4096))
                     if f.type is FrameType.STATUS and f.t0 == 175_000 else f)
    errors = [e for e in replay(tmp_path, bad) if e.startswith("decode_error")]
    assert len(errors) == 1 and errors[0].endswith(
        "ignored: block_len 4096 in RAW mode (a frame carries at most 2048 samples): the previous STATUS is kept")


@pytest.mark.parametrize("fs, args, blocks", [
    (1_000_000, ["--mode", "rms"], 300),            # block 10000: RMS blocks are not bounded by a frame
    (100, ["--block-len", "200"], 1),                # 0.5 blocks a second: 300 samples fill one block
], ids=["1MHz_rms", "half_a_block_a_second"])
def test_every_capture_an_import_writes_is_in_range(tmp_path, fs, args, blocks):
    """The daemon's ranges are the import's: what it writes replays without a decode_error."""
    np.save(tmp_path / "x.npy", np.sin(np.arange(3 * fs) / 7.0))
    cap = tmp_path / "x.bin"
    p = run_module("cmsensord", "import", str(tmp_path / "x.npy"), "--fs", str(fs), *args, "--out", str(cap))
    assert p.returncode == 0, p.stderr
    events = replay(tmp_path, cap.read_bytes())
    assert not [e for e in events if e.startswith("decode_error")], events
    assert f"({blocks} observations, 0 missing, 0 frames lost)" in (tmp_path / "stderr.txt").read_text()


def test_an_import_the_daemon_would_refuse_is_refused(tmp_path):
    np.save(tmp_path / "x.npy", np.sin(np.arange(300_000) / 7.0))
    p = run_module("cmsensord", "import", str(tmp_path / "x.npy"), "--fs", "1000000", "--mode", "rms",
                   "--block-len", "2", "--out", str(tmp_path / "x.bin"))
    assert p.returncode == 2
    assert p.stderr == ("cmsensord import: block_len 2 at 1000000 Hz: 500,000 blocks a second, more than the daemon "
                        "takes (100,000); give --block-len 10 or more\n")
