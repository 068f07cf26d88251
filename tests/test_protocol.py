"""Specification tests for cmsensord.protocol (docs/PROTOCOL.md, receiver rules 1-5)."""

from __future__ import annotations

import random
import struct
import tracemalloc
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from cmsensord.protocol import (
    FLAG_CLIPPED,
    FLAG_OVERRUN,
    MAX_FRAME,
    MODE_RAW,
    MODE_RMS,
    OVERHEAD,
    SYNC,
    Decoder,
    Frame,
    FrameType,
    LinkCounters,
    ProtocolError,
    Status,
    decode_raw,
    decode_rms,
    decode_rms_rows,
    decode_status,
    decode_tacho,
    encode_frame,
    encode_raw,
    encode_rms,
    encode_status,
    encode_tacho,
    iter_frames,
)
from fuzz import examples

# The three docs/PROTOCOL.md test vectors.
VEC_RMS = bytes.fromhex(
    "a5 5a 01 02 07 00 d6 06 00 00 02 00 08 00 00 00 00 3f 00 00 a0 3f 30 54 1b de")
VEC_RAW = bytes.fromhex(
    "a5 5a 01 03 08 00 e8 03 00 00 00 00 08 00 00 08 34 08 cc 07 00 08 cb d2 cb 61")
VEC_TACHO = bytes.fromhex(
    "a5 5a 01 04 09 00 e8 03 00 00 00 00 06 00 01 00 80 0c 00 00 f3 d7 77 4e")


def raw_frame(version: int, ftype: int, seq: int, t0: int, chan: int, flags: int,
              payload: bytes, length: int | None = None) -> bytes:
    """A frame with any header values (encode_frame refuses bad ones), valid CRC."""
    ln = len(payload) if length is None else length
    body = struct.pack("<BBHIBBH", version, ftype, seq, t0, chan, flags, ln) + payload
    return SYNC + body + struct.pack("<I", zlib.crc32(body))


def good_bytes(frames: list[Frame]) -> int:
    return sum(OVERHEAD + len(f.payload) for f in frames)


def assert_accounting(dec: Decoder, frames: list[Frame]) -> None:
    c = dec.counters
    assert c.bytes_received == good_bytes(frames) + c.bytes_discarded + dec.buffered()


def make_status(c: int = 4) -> Status:
    return Status(
        fw_version=(1 << 8) | 3, mode=MODE_RMS, n_channels=c, fs=25000, block_len=250,
        tacho_inputs=1, tacho_ppr=2, overruns=17, uptime_s=3600,
        scale=tuple((k + 1) / 64 for k in range(c)),  # exact in f32
        offset=tuple(2048.0 + k for k in range(c)),
    )


# --- 1. test vectors ------------------------------------------------------

def test_vectors_decode_to_the_stated_values():
    frames, counters = iter_frames(VEC_RMS + VEC_RAW + VEC_TACHO)
    assert [f.type for f in frames] == [FrameType.RMS, FrameType.RAW, FrameType.TACHO]
    assert [f.seq for f in frames] == [7, 8, 9]
    assert [f.t0 for f in frames] == [1750, 1000, 1000]
    assert [f.chan for f in frames] == [2, 0, 0]
    assert [f.offset for f in frames] == [0, len(VEC_RMS), len(VEC_RMS) + len(VEC_RAW)]
    assert decode_rms(frames[0]).tolist() == [0.5, 1.25]
    assert decode_rms(frames[0]).dtype == np.float32
    rows = decode_rms_rows([frames[0], frames[0]], 2)
    assert rows.dtype == np.float32 and rows.tolist() == [[0.5, 1.25], [0.5, 1.25]]
    with pytest.raises(ProtocolError, match="expected 12 bytes"):
        decode_rms_rows([frames[0]], 3)
    assert decode_raw(frames[1].payload).tolist() == [2048, 2100, 1996, 2048]
    assert decode_tacho(frames[2].payload).tolist() == [3200]  # 12.5 * 256
    assert counters.frames == {"status": 0, "rms": 1, "raw": 1, "tacho": 1}
    assert counters.frames_lost == 0 and counters.bytes_discarded == 0


def test_encoders_reproduce_the_vectors_byte_for_byte():
    assert encode_rms(7, 1750, [0.5, 1.25]) == VEC_RMS
    assert encode_raw(8, 1000, 0, np.array([2048, 2100, 1996, 2048])) == VEC_RAW
    assert encode_tacho(9, 1000, 0, [int(12.5 * 256)]) == VEC_TACHO
    assert encode_frame(FrameType.RMS, 7, 1750, 2, 0, VEC_RMS[14:-4]) == VEC_RMS


def test_encode_frame_masks_seq_and_t0_and_limits_payload():
    f = encode_frame(FrameType.RAW, 65536 + 5, 2**32 + 9, 1, FLAG_CLIPPED, b"\x00\x01")
    (frame,), _ = iter_frames(f)
    assert (frame.seq, frame.t0, frame.flags) == (5, 9, FLAG_CLIPPED)
    assert len(encode_frame(FrameType.RAW, 0, 0, 0, 0, bytes(4096))) == MAX_FRAME
    with pytest.raises(ValueError, match="4097"):
        encode_frame(FrameType.RAW, 0, 0, 0, 0, bytes(4097))


# --- 2. STATUS --------------------------------------------------------------

@pytest.mark.parametrize("c", [1, 4, 8])
def test_status_round_trip(c):
    st_in = make_status(c)
    wire = encode_status(3, 123456, st_in)
    assert len(wire) == OVERHEAD + 20 + 8 * c
    (frame,), _ = iter_frames(wire)
    assert frame.type is FrameType.STATUS and frame.chan == 0
    assert decode_status(frame.payload) == st_in


def test_status_raw_mode_and_wrong_length():
    st_in = Status(0x0102, MODE_RAW, 2, 25000, 250, 0, 1, 0, 5, (0.5, 0.25), (2047.5, 2048.0))
    payload = iter_frames(encode_status(0, 0, st_in))[0][0].payload
    assert decode_status(payload) == st_in
    with pytest.raises(ProtocolError, match="expected 36 bytes .*got 35"):
        decode_status(payload[:-1])


# --- 3. chunk-split invariance -----------------------------------------------

def mixed_stream(n: int = 50, seed: int = 1) -> bytes:
    """~n mixed frames with some garbage, a fake header and a seq gap in between."""
    rng = random.Random(seed)
    parts = []
    seq, t0 = 65530, 2**32 - 1000  # both wrap inside the stream
    for k in range(n):
        kind = k % 4
        flags = FLAG_OVERRUN if k % 7 == 3 else 0
        if kind == 0:
            parts.append(encode_status(seq, t0, make_status(3), flags))
        elif kind == 1:
            parts.append(encode_rms(seq, t0, [rng.random() for _ in range(4)], flags))
        elif kind == 2:
            counts = np.array([rng.randrange(4096) for _ in range(rng.randrange(0, 300))])
            parts.append(encode_raw(seq, t0, rng.randrange(4), counts, flags))
        else:
            parts.append(encode_tacho(seq, t0, 0, [rng.randrange(64000) for _ in range(3)]))
        if k % 11 == 5:
            parts.append(bytes([0xA5, 0x00, 0xA5, 0xA5, 0x5A, 0x01]))  # garbage with a fake sync
        if k % 13 == 6:
            parts.append(raw_frame(1, 2, 0, 0, 1, 0, b"", length=300)[:20])  # fake header
        seq += 2 if k == 20 else 1  # one lost frame
        t0 = (t0 + 250) % 2**32
    return b"".join(parts)


MIXED = mixed_stream()


def _decode_in_chunks(data: bytes, cuts: list[int]) -> tuple[list[Frame], dict, list]:
    dec = Decoder()
    frames: list[Frame] = []
    bounds = [0, *sorted(cuts), len(data)]
    for a, b in zip(bounds, bounds[1:]):
        frames += dec.feed(data[a:b])
        assert_accounting(dec, frames)
    tail = dec.flush()
    return frames, dec.counters.as_dict(), tail


def test_mixed_stream_reference_values():
    frames, counters, tail = _decode_in_chunks(MIXED, [])
    frames += tail
    assert [f.seq for f in frames] == [(65530 + k + (k > 20)) % 65536 for k in range(50)]
    assert counters["frames_lost"] == 1
    assert counters["frames_status"] == counters["frames_rms"] == 13
    assert counters["overruns"] == sum(1 for f in frames if f.flags & FLAG_OVERRUN) > 0
    assert counters["header_rejects"] > 0 and counters["bytes_discarded"] > 0
    unwrapped = [f.t0_unwrapped for f in frames]
    assert unwrapped == sorted(unwrapped) and unwrapped[-1] > 2**32


@settings(max_examples=100, deadline=None)
@given(st.lists(st.integers(0, len(MIXED)), max_size=40))
def test_chunk_split_invariance(cuts):
    assert _decode_in_chunks(MIXED, cuts) == _decode_in_chunks(MIXED, [])


def test_byte_at_a_time_equals_one_feed():
    assert _decode_in_chunks(MIXED, list(range(len(MIXED)))) == _decode_in_chunks(MIXED, [])


# --- 4. fuzz ------------------------------------------------------------------

PAYLOAD_LEN = {  # type -> strategy of a payload length valid for that type
    FrameType.STATUS: st.integers(1, 8).map(lambda c: 20 + 8 * c),
    FrameType.RMS: st.integers(1, 8).map(lambda c: 4 * c),
    FrameType.RAW: st.one_of(st.integers(0, 300), st.just(2048)).map(lambda k: 2 * k),
    FrameType.TACHO: st.integers(0, 8).map(lambda k: 2 + 4 * k),
}


@st.composite
def sent_frames(draw):
    n = draw(st.integers(1, 30))
    seq0 = draw(st.sampled_from([0, 1000, 65530]))
    t = draw(st.sampled_from([0, 2**32 - 600, 123456]))
    rnd = random.Random(draw(st.integers(0, 2**32)))
    frames = []
    for k in range(n):
        ftype = draw(st.sampled_from(list(FrameType)))
        ln = draw(PAYLOAD_LEN[ftype])
        payload = bytearray(rnd.randbytes(ln))
        if ln >= 20 and draw(st.booleans()):  # a plausible header inside a real payload
            at = rnd.randrange(ln - 14)
            payload[at:at + 14] = raw_frame(1, 2, 0, 0, 1, 0, b"", length=rnd.randrange(4097))[:14]
        frames.append((ftype, (seq0 + k) & 0xFFFF, t & 0xFFFFFFFF, rnd.randrange(256),
                       rnd.randrange(4), bytes(payload)))
        t += draw(st.sampled_from([250, 250, 0, 100_000]))
    return frames


@st.composite
def injections(draw, size, starts):
    """Sorted errors (position in the clean stream, kind, bytes); positions are
    uniform or right at a frame start (where a fake header overlaps a real one)."""
    rnd = random.Random(draw(st.integers(0, 2**32)))
    out = []
    for _ in range(draw(st.integers(0, 12))):
        pos = draw(st.one_of(st.integers(0, size), st.sampled_from(starts)))
        kind = draw(st.sampled_from(["flip", "drop", "insert", "fake"]))
        if kind in ("flip", "drop") and pos == size:
            pos = size - 1
        if kind == "flip":
            data = bytes([1 << rnd.randrange(8)])
        elif kind == "drop":
            data = b""
        elif kind == "insert":
            data = rnd.randbytes(rnd.randrange(1, 6))
        else:  # a fake sync + header with a plausible or implausible length, then junk
            ln = draw(st.sampled_from([0, 8, 300, 4096, 4097, 5000, 65535]))
            head = struct.pack("<BBHIBBH", draw(st.sampled_from([1, 1, 2])),
                               draw(st.sampled_from([1, 2, 3, 4, 9])), 0, 0, 2, 0, ln)
            data = SYNC + head + rnd.randbytes(rnd.randrange(0, 40))
            if draw(st.booleans()):  # cut short: the header read runs into what follows
                data = data[:rnd.randrange(2, 14)]
        out.append((pos, kind, data))
    out.sort(key=lambda e: (e[0], e[1] in ("flip", "drop")))  # inserts first at a position
    return out


def equal_run(clean: bytes, pos: int) -> tuple[int, int]:
    """The first and last index of the run of bytes equal to ``clean[pos]`` around it: dropping
    any byte of it gives the same stream, so the drop may have cost any frame the run touches
    (the last CRC byte of a frame equal to the first sync byte of the next: either frame)."""
    lo = hi = pos
    while lo > 0 and clean[lo - 1] == clean[pos]:
        lo -= 1
    while hi + 1 < len(clean) and clean[hi + 1] == clean[pos]:
        hi += 1
    return lo, hi


def test_a_drop_in_a_run_of_equal_bytes_costs_one_frame_of_the_run():
    """The fuzz test's counterexample: a frame whose last CRC byte is 0xA5, the next frame's
    first sync byte. Dropping it is dropping the sync byte: the first frame is read whole, the
    second is lost, the third is read; the run of equal bytes counts both as touched."""
    sent = [(FrameType.TACHO, 65530, 123456, 215, 0, bytes.fromhex("cd072cd8be6f9f62ac4c09c2e7e3")),
            (FrameType.RMS, 65531, 123706, 248, 3, b":^HB"),
            (FrameType.RMS, 65532, 123956, 155, 3, bytes.fromhex("b36711eb"))]
    wires = [encode_frame(*f) for f in sent]
    clean = b"".join(wires)
    assert clean[31] == clean[32] == SYNC[0] and len(wires[0]) == 32
    spans = [(0, 32), (32, 54), (54, 76)]
    stream, untouched = apply_injections(clean, spans, [(31, "drop", b"")])
    assert untouched == [2] and equal_run(clean, 31) == (31, 32)
    assert [f.seq for f in Decoder().feed(stream)] == [65530, 65532]


def apply_injections(clean: bytes, spans, errors):
    """The corrupted stream, and the indices of frames no error touched."""
    out = bytearray()
    touched = set()
    prev = 0
    flip_or_drop_at = {}
    for pos, kind, data in errors:
        out += clean[prev:pos]
        prev = pos
        if kind in ("flip", "drop"):
            if pos in flip_or_drop_at:  # at most one flip/drop per byte
                continue
            flip_or_drop_at[pos] = kind
            if kind == "flip":
                out.append(clean[pos] ^ data[0])
            prev = pos + 1
            lo, hi = (pos, pos) if kind == "flip" else equal_run(clean, pos)
            for k, (a, b) in enumerate(spans):
                if a <= hi and lo < b:
                    touched.add(k)
        else:
            out += data
            for k, (a, b) in enumerate(spans):
                if a < pos < b:  # inserted strictly inside the frame
                    touched.add(k)
    out += clean[prev:]
    return bytes(out), [k for k in range(len(spans)) if k not in touched]


@settings(max_examples=examples(200), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_fuzz_recovers_every_untouched_frame(data):
    sent = data.draw(sent_frames())
    wires = [encode_frame(*f) for f in sent]
    spans, at = [], 0
    for w in wires:
        spans.append((at, at + len(w)))
        at += len(w)
    clean = b"".join(wires)
    errors = data.draw(injections(len(clean), [a for a, _ in spans]))
    stream, untouched = apply_injections(clean, spans, errors)
    max_buffer = data.draw(st.sampled_from([MAX_FRAME, 5000, 65536]))
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))

    dec = Decoder(max_buffer=max_buffer)
    got: list[Frame] = []
    for a, b in zip([0, *cuts], [*cuts, len(stream)]):
        got += dec.feed(stream[a:b])
        assert dec.buffered() <= max_buffer
        assert_accounting(dec, got)
    got += dec.flush()
    assert dec.buffered() == 0
    assert_accounting(dec, got)
    c = dec.counters
    event(f"errors injected: {min(len(errors), 3)}+")
    event(f"frames untouched: {'all' if len(untouched) == len(sent) else 'some' if untouched else 'none'}")
    event(f"crc failures: {c.crc_failures > 0}, header rejects: {c.header_rejects > 0}")

    keys = [(f.type, f.seq, f.t0, f.chan, f.flags, f.payload) for f in got]
    sent_index = {f: k for k, f in enumerate(sent)}
    # Nothing reported that was not sent (the CRC sees to that), each at most once.
    assert all(k in sent_index for k in keys)
    order = [sent_index[k] for k in keys]
    assert order == sorted(set(order))
    # Every frame no error touched is recovered exactly.
    assert set(untouched) <= set(order)
    # frames_lost is the seq gaps among recovered frames (sent seqs are contiguous).
    gaps = [(b.seq - a.seq - 1) % 65536 for a, b in zip(got, got[1:])]
    assert [f.lost_before for f in got[1:]] == gaps
    assert dec.counters.frames_lost == sum(gaps)
    if order:
        assert dec.counters.frames_lost == order[-1] - order[0] + 1 - len(order)
        assert got[0].lost_before == 0


def test_fuzz_never_raises_on_random_bytes():
    rnd = random.Random(7)
    blob = bytearray(rnd.randbytes(200_000))
    for _ in range(2000):  # sprinkle sync bytes so headers are tried often
        at = rnd.randrange(len(blob) - 2)
        blob[at:at + 3] = b"\xa5\x5a\x01"
    dec = Decoder(max_buffer=MAX_FRAME)
    got = []
    for a in range(0, len(blob), 997):
        got += dec.feed(blob[a:a + 997])
        assert dec.buffered() <= MAX_FRAME
    got += dec.flush()
    assert got == []  # (a 2^-32 chance per candidate of a chance CRC match)
    assert dec.counters.bytes_discarded == len(blob)
    assert dec.counters.header_rejects > 0 and dec.counters.crc_failures > 0


# --- 5. wraps -------------------------------------------------------------------

def test_seq_wrap_is_not_a_gap():
    wire = b"".join(encode_rms(s, 250 * k, [1.0]) for k, s in enumerate([65534, 65535, 0, 1]))
    frames, c = iter_frames(wire)
    assert [f.seq for f in frames] == [65534, 65535, 0, 1]
    assert c.frames_lost == 0 and all(f.lost_before == 0 for f in frames)


def test_seq_gap_across_wrap_counts_lost_frames():
    wire = b"".join(encode_rms(s, 250 * k, [1.0]) for k, s in enumerate([65533, 2, 3, 10]))
    frames, c = iter_frames(wire)
    assert [f.lost_before for f in frames] == [0, 4, 0, 6]
    assert c.frames_lost == 10


def test_t0_wrap_unwraps_monotonically():
    t0s = [2**32 - 750, 2**32 - 500, 2**32 - 250, 0, 250, 500]
    wire = b"".join(encode_rms(k, t, [1.0]) for k, t in enumerate(t0s))
    frames, _ = iter_frames(wire)
    assert [f.t0 for f in frames] == t0s
    assert [f.t0_unwrapped for f in frames] == [2**32 - 750 + 250 * k for k in range(6)]


def test_t0_unwrap_survives_several_wraps_and_small_steps_back():
    step = 2**31 - 1  # largest forward step that is still read as forward
    raw = [(k * step) % 2**32 for k in range(10)] + [(9 * step - 5) % 2**32]
    frames, _ = iter_frames(b"".join(encode_rms(k, t, [0.0]) for k, t in enumerate(raw)))
    assert [f.t0_unwrapped for f in frames] == [k * step for k in range(10)] + [9 * step - 5]


def test_hand_built_frame_defaults():
    f = Frame(FrameType.RMS, 1, 1234, 2, 0, b"")
    assert (f.t0_unwrapped, f.offset, f.lost_before) == (1234, -1, 0)


# --- 6. header rejects and CRC failures -------------------------------------------

def test_invalid_headers_are_skipped_and_counted():
    good = [encode_rms(k, 250 * k, [0.5, 1.25]) for k in range(4)]
    wire = (good[0]
            + raw_frame(2, 2, 1, 250, 2, 0, bytes(8))       # version 2
            + good[1]
            + raw_frame(1, 9, 2, 500, 2, 0, bytes(8))       # unknown type 9
            + good[2]
            + raw_frame(1, 3, 3, 750, 0, 0, b"", length=5000)  # len > 4096
            + good[3])
    frames, c = iter_frames(wire)
    assert [f.seq for f in frames] == [0, 1, 2, 3]
    assert c.header_rejects == 3 and c.crc_failures == 0
    rejected = 2 * (OVERHEAD + 8) + 14 + 4
    assert c.bytes_discarded == rejected
    assert c.bytes_received == 4 * len(good[0]) + rejected


def test_corrupted_len_is_not_skipped_over():
    victim = bytearray(encode_raw(5, 0, 0, np.arange(100)))
    victim[12:14] = struct.pack("<H", 4000)  # len now spans the next frames
    nxt = [encode_rms(6 + k, 250 * k, [1.0, 2.0]) for k in range(3)]
    dec = Decoder()
    frames = dec.feed(bytes(victim) + b"".join(nxt))
    assert frames == []  # still waiting for 4000 bytes: the candidate may be real
    frames += dec.flush()
    assert [f.seq for f in frames] == [6, 7, 8]
    assert frames[0].offset == len(victim)
    assert dec.counters.crc_failures == 0 and dec.counters.bytes_discarded == len(victim)
    # Given enough bytes, the bad CRC costs one byte and the frames after it are found.
    dec = Decoder()
    frames = dec.feed(bytes(victim) + b"".join(nxt) + bytes(4000))
    assert [f.seq for f in frames] == [6, 7, 8]
    assert dec.counters.crc_failures == 1


def test_bad_crc_drops_one_byte_and_finds_an_embedded_frame():
    inner = encode_rms(42, 0, [3.0])
    outer = bytearray(encode_raw(41, 0, 0, np.zeros(40, dtype=np.uint16)))
    outer[20:20 + len(inner)] = inner  # a whole frame inside a corrupted frame's payload
    frames, c = iter_frames(bytes(outer))
    assert [(f.seq, f.offset) for f in frames] == [(42, 20)]
    assert c.crc_failures == 1


def test_frame_embedded_in_a_good_payload_is_not_reported():
    inner = encode_rms(42, 0, [3.0])
    payload = bytes(10) + inner + bytes(10)
    frames, c = iter_frames(encode_frame(FrameType.RAW, 41, 0, 0, 0, payload))
    assert [f.seq for f in frames] == [41] and c.bytes_discarded == 0


# --- buffering and flush ---------------------------------------------------------

def test_garbage_keeps_at_most_a_trailing_a5():
    dec = Decoder(max_buffer=MAX_FRAME)
    assert dec.feed(bytes(100_000)) == [] and dec.buffered() == 0
    assert dec.feed(b"\x11\x22\xa5") == [] and dec.buffered() == 1
    frame = encode_rms(1, 0, [1.0])
    (f,) = dec.feed(frame[1:])  # the kept A5 completes the sync
    assert f.offset == 100_002 and dec.counters.bytes_discarded == 100_002
    assert_accounting(dec, [f])


def test_large_feed_into_small_buffer():
    frames_in = [encode_raw(k, 250 * k, 0, np.full(2048, k, dtype=np.uint16)) for k in range(40)]
    dec = Decoder(max_buffer=MAX_FRAME)
    frames = dec.feed(b"".join(frames_in))
    assert [f.seq for f in frames] == list(range(40)) and dec.buffered() == 0
    with pytest.raises(ValueError, match="max_buffer"):
        Decoder(max_buffer=MAX_FRAME - 1)


def test_buffer_stays_bounded_inside_one_large_feed():
    garbage = bytes(4_000_000)  # allocated before tracing starts
    dec = Decoder(max_buffer=MAX_FRAME)
    tracemalloc.start()
    try:
        dec.feed(garbage)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 200_000  # the decoder never copied the 4 MB into its buffer


def test_flush_recovers_frames_after_a_fake_header_at_the_end():
    fake = raw_frame(1, 3, 0, 0, 0, 0, b"", length=4096)[:14]
    tail = [encode_tacho(k, 0, 0, [k]) for k in range(3)]
    dec = Decoder()
    assert dec.feed(encode_rms(100, 0, [1.0]) + fake + b"".join(tail) + SYNC + b"\x01")
    assert dec.buffered() == len(fake) + sum(map(len, tail)) + 3
    frames = dec.flush()
    assert [f.seq for f in frames] == [0, 1, 2]
    assert dec.buffered() == 0 and dec.counters.bytes_discarded == 14 + 3
    # The decoder stays usable, keeping its seq/t0 history.
    (f,) = dec.feed(encode_rms(5, 250, [1.0]))
    assert f.lost_before == 2 and dec.counters.frames_lost == 65535 - 100 + 2


def test_memoryview_and_bytearray_input():
    dec = Decoder()
    frames = dec.feed(memoryview(bytearray(VEC_RMS)))
    frames += dec.feed(bytearray(VEC_RAW))
    assert [f.seq for f in frames] == [7, 8]
    assert dec.counters.bytes_received == len(VEC_RMS) + len(VEC_RAW)


def test_counters_as_dict_is_flat():
    _, c = iter_frames(VEC_RMS + encode_rms(9, 0, [1.0], flags=FLAG_OVERRUN))
    assert c.as_dict() == {
        "bytes_received": 2 * len(VEC_RMS) - 4, "bytes_discarded": 0, "crc_failures": 0,
        "header_rejects": 0, "frames_status": 0, "frames_rms": 2, "frames_raw": 0,
        "frames_tacho": 0, "frames_lost": 1, "overruns": 1, "frames_repeated": 0,
    }
    assert LinkCounters().frames == {"status": 0, "rms": 0, "raw": 0, "tacho": 0}


# --- 7. malformed payloads ----------------------------------------------------------

def test_rms_with_wrong_length_raises():
    frame = Frame(FrameType.RMS, 0, 0, 3, 0, bytes(8))
    with pytest.raises(ProtocolError, match=r"RMS payload: expected 12 bytes .*got 8"):
        decode_rms(frame)


def test_tacho_with_wrong_count_raises():
    payload = struct.pack("<H", 3) + bytes(8)
    with pytest.raises(ProtocolError, match=r"TACHO payload: expected 14 bytes .*got 10"):
        decode_tacho(payload)
    with pytest.raises(ProtocolError, match="at least 2 bytes"):
        decode_tacho(b"\x00")


def test_raw_with_odd_length_raises():
    with pytest.raises(ProtocolError, match="got 5"):
        decode_raw(bytes(5))


def test_status_too_short_raises():
    with pytest.raises(ProtocolError, match="at least 20 bytes, got 19"):
        decode_status(bytes(19))


def test_encoders_reject_unencodable_values():
    with pytest.raises(ProtocolError, match="u16"):
        encode_raw(0, 0, 0, np.array([70000]))
    with pytest.raises(ProtocolError, match="integers"):
        encode_raw(0, 0, 0, np.array([1.5]))
    with pytest.raises(ProtocolError, match="scale"):
        encode_status(0, 0, Status(1, MODE_RMS, 2, 25000, 250, 0, 1, 0, 0, (1.0,), (0.0,)))
    with pytest.raises(ValueError):
        encode_frame(9, 0, 0, 0, 0, b"")
