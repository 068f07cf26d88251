"""Frames with a good CRC but a bad body, in a healthy stream: each is one `decode_error` event,
stamped at its own t0, and costs only itself, whatever the reads.  Guards against events that
count the bad frames of each read ("14 RAW frame(s) with a channel >= 1 ..." in a 1 MiB read,
fourteen events of one in reads of 997 bytes), and against a TACHO edge outside its block (an
offset past the block's samples) taken where it says: "tacho restored at sample 16822216",
11 minutes past the end of a 16-s stream, stamped where each read size puts it."""

from __future__ import annotations

import dataclasses
import fcntl
import os
import struct
import termios
import time
import tty

import pytest

from cmsensord.protocol import Decoder, FrameType, decode_status, encode_frame, encode_status
from cmsensord.sinks.mcap_sink import read_messages
from processes import start_daemon, stop
from test_link_faults import _opened
from test_read_size import board, by_topic, same_at_every_read_size
from test_stream_events import replay


def rebuilt(data: bytes, change) -> tuple[bytes, list]:
    """The frames of ``data`` through ``change(i, frame)`` (a frame, the same or another), numbered
    as sent; and the frames changed."""
    out, changed = bytearray(), []
    for i, f in enumerate(Decoder().feed(data)):
        g = change(i, f)
        if g is not f:
            changed.append(g)
        out += encode_frame(g.type, g.seq, g.t0, g.chan, g.flags, g.payload)
    return bytes(out), changed


def decode_errors(runs: list[dict]) -> list[str]:
    return [m["message"] for _, m in runs[0]["/cm/events"] if m["kind"] == "decode_error"]


@pytest.mark.parametrize("mode", ["raw", "rms"])
def test_data_frames_of_a_wrong_length_or_channel_are_one_event_each_at_their_t0(mode):
    """Every 77th data frame is 100 bytes short, every 101st names channel 7 (RAW; an RMS frame
    with 7 channels' values is another board, so RMS frames only get short)."""
    data_type = FrameType.RAW if mode == "raw" else FrameType.RMS

    def change(i, f):
        if f.type is data_type and i % 77 == 2:
            return f._replace(payload=f.payload[:-100] if mode == "raw" else f.payload[:2])
        if f.type is data_type and mode == "raw" and i % 101 == 4:
            return f._replace(chan=7)
        return f

    data, changed = rebuilt(board(mode, 16), change)
    runs = same_at_every_read_size(data)
    if mode == "raw":
        want = [f"RAW frame of channel {f.chan} at t0 {f.t0} skipped: "
                + ("channel >= 1" if f.chan else "400 bytes, not 500 (250 samples of 2 bytes)") for f in changed]
    else:
        want = [f"RMS frame at t0 {f.t0} dropped: 2 bytes, not 4 (1 channel(s) of 4 bytes)" for f in changed]
    assert len(changed) >= 20 and decode_errors(runs) == want
    assert [s for s, m in runs[0]["/cm/events"] if m["kind"] == "decode_error"] == [f.t0 * 40_000 for f in changed]


def test_impossible_rms_values_are_one_event_each_at_their_t0_at_any_read_size():
    """Every 97th RMS frame carries NaN, every 89th -1 m/s² (a one-channel board): each is a missing
    observation and one `decode_error` at its t0 (rms_bounds), read in any size.  Before: the NaN
    ones were missing with no word, the negative ones observations."""
    def change(i, f):
        if f.type is FrameType.RMS and i % 97 == 5:
            return f._replace(payload=struct.pack("<f", float("nan")))
        if f.type is FrameType.RMS and i % 89 == 7:
            return f._replace(payload=struct.pack("<f", -1.0))
        return f

    data, changed = rebuilt(board("rms", 16), change)
    runs = same_at_every_read_size(data)
    assert len(changed) >= 30 and [(s, m["channel"]) for s, m in runs[0]["/cm/events"]
                                   if m["kind"] == "decode_error"] == [(f.t0 * 40_000, "ch0") for f in changed]


def test_rms_frames_disagreeing_with_the_status_are_counted_alike_at_any_read_size():
    """From 13 s on the board's STATUS says 2 channels while its RMS frames carry 1: each 100 of them
    in a row is one `decode_error` at its first frame's t0, however the stream was read."""
    def change(i, f):
        if f.type is FrameType.STATUS and f.t0 >= 325_000:
            st = decode_status(f.payload)
            two = dataclasses.replace(st, n_channels=2, scale=st.scale * 2, offset=st.offset * 2)
            return f._replace(payload=encode_status(f.seq, f.t0, two)[14:-4])
        return f

    data, _ = rebuilt(board("rms", 16), change)
    runs = same_at_every_read_size(data)
    told = [(s, m["message"]) for s, m in runs[0]["/cm/events"] if m["kind"] == "decode_error"]
    assert told == [((325_000 + k * 25_000) * 40_000, "100 RMS frame(s) of 1 channel(s) dropped: the board's "
                     "STATUS says 2 channel(s)") for k in range(3)]


def edge_outside(i, f):
    """Every 40th TACHO frame with one more edge, after its own, past its block: at 250 samples
    and 5/256 (the next block's first instant) or at 2^32 - 1 (11 minutes on)."""
    if f.type is FrameType.TACHO and i % 40 == 3:
        (n,) = struct.unpack_from("<H", f.payload)
        outside = 250 * 256 + 5 if i % 80 == 3 else 2**32 - 1
        return f._replace(payload=struct.pack("<H", n + 1) + f.payload[2:] + struct.pack("<I", outside))
    return f


@pytest.mark.parametrize("mode", ["raw", "rms"])
def test_a_tacho_edge_outside_its_block_is_dropped_with_one_event_at_its_t0(mode):
    """:func:`edge_outside`: the edges inside are taken: the shaft speed and the orders are the
    stream's (1720 rpm), no tacho event."""
    data, changed = rebuilt(board(mode, 16), edge_outside)
    runs = same_at_every_read_size(data)
    assert len(changed) >= 30 and decode_errors(runs) == [
        f"TACHO frame at t0 {f.t0}: 1 edge(s) outside its block (offsets of 250 samples or more) dropped"
        for f in changed]
    assert not [m for _, m in runs[0]["/cm/events"] if m["kind"].startswith("tacho_")]
    if mode == "raw":
        orders = [m["speed_rpm"] for _, m in runs[0]["/cm/ch0/orders"] if m["valid"]]
        assert len(orders) >= 140 and all(abs(v - 1720) < 20 for v in orders)


def test_a_replay_tells_each_bad_frame(tmp_path):
    """`cmsensord replay` of a RAW capture with TACHO edges outside their blocks and RAW frames
    100 bytes short: one event each, in the log, and nothing else goes wrong."""
    def change(i, f):                   # about two a second: under the events' rate limit
        if f.type is FrameType.RAW and i % 277 == 2:
            return f._replace(payload=f.payload[:-100])
        return edge_outside(i, f) if i % 80 == 3 else f

    data, changed = rebuilt(board("raw", 8), change)
    events = replay(tmp_path, data)
    assert [e for e in events if e.startswith("decode_error")] == [
        f"decode_error | RAW frame of channel 0 at t0 {f.t0} skipped: 400 bytes, not 500 (250 samples of 2 bytes)"
        if f.type is FrameType.RAW else
        f"decode_error | TACHO frame at t0 {f.t0}: 1 edge(s) outside its block (offsets of 250 samples or more) "
        "dropped" for f in sorted(changed, key=lambda f: (f.t0, f.type))]
    assert not [e for e in events if e.startswith(("tacho_", "frames_", "time_base"))]
    assert f"decode_error {len(changed)}" in (tmp_path / "stderr.txt").read_text()


@pytest.mark.parametrize("mode", ["raw", "rms"])
def test_a_malformed_tacho_payload_is_one_event_at_its_t0(mode):
    """Every 90th TACHO frame has a byte too many: its edges are not read (one `decode_error`
    naming its byte and the lengths, stamped at its t0), the same at every read size."""
    data, changed = rebuilt(board(mode, 16), lambda i, f: f._replace(payload=f.payload + b"\x01")
                            if f.type is FrameType.TACHO and i % 90 == 3 else f)
    runs = same_at_every_read_size(data)
    errors = [(s, m["message"]) for s, m in runs[0]["/cm/events"] if m["kind"] == "decode_error"]
    sent = Decoder().feed(data)
    at = {f.t0: f.offset for f in sent if f.type is FrameType.TACHO}
    assert len(changed) >= 15 and errors == [
        (f.t0 * 40_000, f"bad TACHO payload at byte {at[f.t0]}: TACHO payload: expected {len(f.payload) - 1} bytes "
                        f"(2 + 4 x N={(len(f.payload) - 3) // 4} edges), got {len(f.payload)}") for f in changed]


@pytest.mark.parametrize(("first", "count", "dropped"), [(700, 30, 30), (700, 300, 99)])
def test_rms_frames_of_another_channel_count_in_a_row_are_dropped_alike_at_any_read_size(first, count, dropped):
    """``count`` RMS frames in a row with two channels' values in a one-channel stream (no STATUS
    says so): fewer than 100 are odd frames, dropped, one `channels` event for the run at its
    first frame; from the 100th on the board has changed and they are taken.  Guards against an event
    counting the odd frames of each read, and a read holding the 100th taking the 99 before it too
    (a large read taking all 300, reads of 997 bytes dropping 99)."""
    rms = [i for i, f in enumerate(Decoder().feed(board("rms", 16))) if f.type is FrameType.RMS]
    two = set(rms[first:first + count])
    data, changed = rebuilt(board("rms", 16), lambda i, f: f._replace(chan=2, payload=f.payload * 2)
                            if i in two else f)
    runs = same_at_every_read_size(data)
    told = [(s, m["message"]) for s, m in runs[0]["/cm/events"] if m["kind"] == "channels"]
    assert told[0] == (changed[0].t0 * 40_000, f"{dropped} RMS frame(s) of 2 channel(s) in a 1-channel stream "
                                               f"dropped ({dropped} in all)")


@pytest.mark.parametrize("mode", ["raw", "rms"])
def test_a_bad_status_is_one_event_at_its_t0(mode):
    """The STATUS frames at 4 s and 10 s are 3 bytes short, the one at 7 s names a NaN scale: each
    is one `decode_error` stamped at its t0 (not where the read has got to), the board's set-up
    stays."""
    def change(i, f):
        if f.type is FrameType.STATUS and f.t0 in (100_000, 250_000):
            return f._replace(payload=f.payload[:-3])
        if f.type is FrameType.STATUS and f.t0 == 175_000:
            return f._replace(payload=f.payload[:20] + struct.pack("<2f", float("nan"), 2048.0))
        return f

    data, changed = rebuilt(board(mode, 16), change)
    runs = same_at_every_read_size(data)
    errors = [(s, m["message"]) for s, m in runs[0]["/cm/events"] if m["kind"] == "decode_error"]
    assert [s for s, _ in errors] == [4_000_000_000, 7_000_000_000, 10_000_000_000]
    assert errors[0][1].endswith("STATUS payload: expected 28 bytes (20 + 8 x 1 channels), got 25")
    assert errors[1][1].endswith("with scale/offset nan/2048, not finite (and a scale not 0): the previous STATUS "
                                 "is kept")


def written_one_by_one(stamps: list[int]) -> tuple[list[int], list[int]]:
    """The events' rate limit, plainly (docs: at most 5 of a kind in 1 s of event time from the
    first): of events at ``stamps``, the stamps of those written one by one, and the summaries'
    counts."""
    written, summaries, since, n = [], [], None, 0
    for s in sorted(stamps):
        if since is None or s - since >= 1_000_000_000:
            if n > 5:
                summaries.append(n - 5)
            since, n = s, 0
        n += 1
        if n <= 5:
            written.append(s)
    if n > 5:
        summaries.append(n - 5)
    return written, summaries


def flood(mode: str) -> tuple[bytes, list]:
    """From 2 s to 12 s of a 16-s stream a third of the data frames come short and a quarter of
    the TACHO frames with a byte too many: ~40 bad frames a second, reported by the frames' path
    and the tacho's, which run at different points of a read."""
    data_type = FrameType.RAW if mode == "raw" else FrameType.RMS

    def change(i, f):
        if not 50_000 <= f.t0 < 300_000:
            return f
        if f.type is data_type and i % 3 == 1:
            return f._replace(payload=f.payload[:-100] if mode == "raw" else f.payload[:2])
        if f.type is FrameType.TACHO and i % 4 == 3:
            return f._replace(payload=f.payload + b"\x01")
        return f

    return rebuilt(board(mode, 16), change)


@pytest.mark.parametrize("mode", ["raw", "rms"])
def test_a_flood_of_bad_frames_is_summarised_alike_at_any_read_size(mode):
    """:func:`flood`: the events written one by one are the first five of each second by stamp,
    the rest summarised, at every read size (guards against which ones and how many summaries
    following the reads, 63 / 105 / 99 records)."""
    data, changed = flood(mode)
    runs = same_at_every_read_size(data)
    errors = [(s, m) for s, m in runs[0]["/cm/events"] if m["kind"] == "decode_error"]
    want, summaries = written_one_by_one([f.t0 * 40_000 for f in changed])
    assert len(changed) >= 300 and len(summaries) >= 9
    assert [s for s, m in errors if "summarised" not in m] == want
    assert [m["summarised"] for _, m in errors if "summarised" in m] == summaries
    assert sum(m.get("summarised", 1) for _, m in errors) == len(changed)


def test_a_flood_of_bad_frames_on_a_pty_is_summarised_as_its_replay(tmp_path):
    """:func:`flood` (RAW) written to a pty in 997-byte pieces, the daemon on it: its /cm/events
    are those of `cmsensord replay` of its capture, and of the Processor at every read size."""
    data, changed = flood("raw")
    master, slave = os.openpty()
    tty.setraw(slave)
    d = start_daemon(tmp_path, os.ttyname(slave), "--capture", str(tmp_path / "cap.bin"))
    try:
        assert _opened(d, os.ttyname(slave), 30.0), "the daemon did not open the port"
        time.sleep(0.2)                     # pyserial discards what waits at its open
        for i in range(0, len(data), 997):
            os.write(master, data[i:i + 997])
            time.sleep(0.002)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and _unread(slave):
            time.sleep(0.05)
        time.sleep(1.5)
    finally:
        err = stop(d)
        os.close(master)
        os.close(slave)
    assert d.returncode == 0 and "Traceback" not in err, err
    assert (tmp_path / "cap.bin").read_bytes() == data
    live = [m for f in sorted((tmp_path / "logs").glob("*.mcap")) for t, _, m in read_messages(f) if t == "/cm/events"]
    errors = [f"{m['kind']} | {m['message']}" for m in live if m["kind"] == "decode_error"]
    assert sum(m.get("summarised", 1) for m in live if m["kind"] == "decode_error") == len(changed)
    (tmp_path / "replay").mkdir()
    assert errors == [e for e in replay(tmp_path / "replay", data) if e.startswith("decode_error")]
    assert errors == [f"decode_error | {m['message']}" for _, m in by_topic(data, 997)["/cm/events"]
                      if m["kind"] == "decode_error"]


def _unread(fd: int) -> int:
    """Bytes in the tty's input not read yet (by anyone with it open)."""
    return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0"))[0]
