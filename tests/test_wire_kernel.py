"""The compiled wire kernel (cmsensord/_wirekernel.c, the decoder's scan in one call) equals the
Python receiver: the plain frame-by-frame loop (``Decoder(runs=False)``, the reference) and the
numpy runs (``kernel=False``, the fallback without a compiler) give, read for read, the same
frames (types, payloads, byte offsets, seq gaps, unwrapped t0), the same counters and the same
bytes left buffered, on random, corrupt, truncated and hostile byte streams split at random
read boundaries; its CRC-32 is zlib's; and ``cmsensord replay`` of a noisy capture writes the
same messages and link counters with and without it."""

from __future__ import annotations

import random
import struct
import subprocess
import sys
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import cmsensord.protocol as protocol
from cmsensord import wire_scan
from cmsensord.frame_batch import FrameBatch
from cmsensord.protocol import MAX_FRAME, SYNC, Decoder, Frame, FrameType, encode_frame
from cmsensord.sinks.mcap_sink import read_messages
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from fuzz import examples
from messages import comparable
from processes import ENV
from test_decoder_runs import random_stream

pytestmark = pytest.mark.skipif(not wire_scan.have_kernel(), reason="cmsensord._wirekernel is not built")


def hostile_stream(rnd: random.Random) -> bytes:
    """Bytes built to hurt a receiver: sync storms (``A5 5A A5 5A ...``, ``A5 A5 5A``), plausible
    headers claiming 4096-byte payloads, frames inside the payloads of frames with a bad CRC,
    every bit of a frame flipped in turn, lone trailing ``A5`` bytes, random noise."""
    out = bytearray()
    seq = rnd.randrange(65536)
    t0 = rnd.randrange(2**32)
    for _ in range(rnd.randrange(5, 60)):
        kind = rnd.randrange(8)
        good = encode_frame(rnd.choice(list(FrameType)), seq, t0, rnd.randrange(4), rnd.randrange(4),
                            rnd.randbytes(rnd.choice([0, 2, 16, 500])))
        seq, t0 = (seq + rnd.choice([1, 1, 2, 70000])) & 0xFFFF, (t0 + rnd.choice([250, 2**31, 2**32 - 1])) % 2**32
        if kind == 0:
            out += SYNC * rnd.randrange(1, 40)
        elif kind == 1:
            out += b"\xa5" * rnd.randrange(1, 5) + b"\x5a" + good
        elif kind == 2:                             # a header that claims a long frame, then a frame
            out += SYNC + struct.pack("<BBHIBBH", 1, rnd.randrange(1, 5), seq, t0, 0, 0, 4096) + good
        elif kind == 3:                             # a good frame in the payload of a bad-CRC frame
            outer = bytearray(encode_frame(FrameType.RAW, seq, t0, 0, 0, good + rnd.randbytes(2)))
            outer[-1] ^= 0xFF
            out += outer
        elif kind == 4:                             # one bit flipped anywhere (CRC bytes included)
            bad = bytearray(good)
            bad[rnd.randrange(len(bad))] ^= 1 << rnd.randrange(8)
            out += bad
        elif kind == 5:
            out += rnd.randbytes(rnd.randrange(1, 300))
        elif kind == 6:
            out += good[:rnd.randrange(1, len(good))]      # cut short, then the next frame
        else:
            out += good
    if rnd.random() < 0.5:
        out += b"\xa5"
    return bytes(out)


def reads_of(rnd: random.Random, n: int) -> list[int]:
    """Random read sizes covering ``n`` bytes: single bytes, a frame's worth, big reads."""
    sizes = []
    while sum(sizes) < n:
        sizes.append(rnd.choice([1, 2, 13, 17, 518, 4096, 20_000, 65536, 200_000]))
    return sizes


def decoders(max_buffer: int) -> dict[str, Decoder]:
    return {"kernel": Decoder(max_buffer=max_buffer, kernel=True),
            "reference": Decoder(max_buffer=max_buffer, runs=False),
            "numpy": Decoder(max_buffer=max_buffer, kernel=False)}


def same_read_by_read(data: bytes, reads: list[int], max_buffer: int, batches: bool) -> protocol.LinkCounters:
    """Feed ``data`` in ``reads`` (then the rest, then flush) to the three decoders in step; after every read
    each returns the same frames and holds the same counters and buffered bytes.  The
    reference's counters."""
    decs = decoders(max_buffer)
    assert decs["kernel"]._kernel is not None and decs["numpy"]._kernel is None
    at = 0
    for size in [*reads, len(data), None]:         # the reads, the rest, the flush
        got = {}
        for name, dec in decs.items():
            if size is None:
                got[name] = dec.flush_batch() if batches else dec.flush()
            else:
                got[name] = (dec.feed_batch if batches else dec.feed)(data[at:at + size])
        at += size or 0
        ref = list(got["reference"])
        for name in ("kernel", "numpy"):
            frames = list(got[name])
            assert frames == ref, name
            assert [(type(f), type(f.type)) for f in frames] == [(Frame, FrameType)] * len(ref)
            assert decs[name].counters == decs["reference"].counters, name
            assert decs[name].buffered() == decs["reference"].buffered() <= max_buffer, name
            if batches:
                assert type(got[name]) is FrameBatch
                code, t0, lost = got[name].columns()
                assert code.tolist() == [int(f.type) for f in ref]
                assert t0.tolist() == [f.t0_unwrapped for f in ref]
                assert lost.tolist() == [f.lost_before > 0 or f.flags > 0xFF for f in ref]
    c = decs["reference"].counters
    assert decs["reference"].buffered() == 0 and c.bytes_received == len(data)
    return c


@pytest.mark.parametrize("seed", range(24))
def test_the_kernel_equals_the_python_receiver_read_by_read(seed, monkeypatch):
    rnd = random.Random(seed)
    parts = [random_stream(rnd, rnd.choice([20, 300, 1200])), hostile_stream(rnd), rnd.randbytes(rnd.randrange(3000))]
    rnd.shuffle(parts)
    data = b"".join(parts)
    if seed % 2:
        monkeypatch.setattr(protocol, "MIN_BYTES", 0)         # the numpy runs on every buffer too
    c = same_read_by_read(data, reads_of(rnd, len(data)), rnd.choice([MAX_FRAME, 20_000, 65536]),
                          batches=seed % 3 == 0)
    # the streams had what a careless kernel would get wrong: bad CRCs (a kernel that skipped
    # the check would return those frames), bad headers, lost frames, junk
    assert c.crc_failures > 0 and c.header_rejects > 0 and c.frames_lost > 0 and c.bytes_discarded > 0
    assert sum(c.frames.values()) >= 10


_PIECE = st.one_of(
    st.binary(max_size=40),
    st.just(SYNC),
    st.builds(lambda t, seq, t0, n, cut: encode_frame(t, seq, t0, 0, 1, bytes(n))[:cut],
              st.sampled_from(list(FrameType)), st.integers(0, 65535), st.integers(0, 2**32 - 1),
              st.integers(0, 600), st.integers(0, 700)),
    st.builds(lambda ver, code, ln: SYNC + struct.pack("<BBHIBBH", ver, code, 0, 0, 0, 0, ln),
              st.integers(0, 2), st.integers(0, 6), st.sampled_from([0, 4, 4096, 4097, 65535])),
)


@settings(max_examples=examples(200), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_PIECE, max_size=30), st.lists(st.integers(1, 5000), max_size=20), st.booleans())
def test_fuzz_the_kernel_equals_the_python_receiver(pieces, reads, batches):
    same_read_by_read(b"".join(pieces), reads, MAX_FRAME, batches)


def test_a_bad_crc_drops_only_the_first_sync_byte_and_finds_the_frame_inside():
    """docs/PROTOCOL.md rule 2 in the kernel: an outer frame whose CRC fails is not skipped by
    its length; the good frame in its payload is found, at its own stream offset."""
    inner = encode_frame(FrameType.RMS, 5, 1000, 1, 0, struct.pack("<f", 0.5))
    outer = bytearray(encode_frame(FrameType.RAW, 4, 750, 0, 0, bytes(6) + inner + bytes(4)))
    outer[-2] ^= 0x10
    dec = Decoder(kernel=True)
    frames = dec.feed(bytes(outer)) + dec.flush()
    assert [(f.type, f.seq, f.t0, f.offset) for f in frames] == [(FrameType.RMS, 5, 1000, 14 + 6)]
    c = dec.counters
    assert c.crc_failures == 1 and c.bytes_discarded == len(outer) - len(inner)


def test_a_stall_gives_up_incomplete_candidates_alike_on_every_path():
    """Decoder.give_up (a stalled link): a noise header claiming 4000 bytes, another inside the
    frames behind it, and half a header at the end: both candidates are CRC failures and the frames
    behind them come out, the same on the three paths; the half header waits (the rest may come).
    Before there was no way to have them but more bytes or the end of the stream."""
    noise = b"\xa5\x5a\x01\x02\x00\x00\x00\x00\x00\x00\x02\x00" + struct.pack("<H", 4000)
    frames = [encode_frame(FrameType.RMS, k, 250 * k, 1, 0, struct.pack("<f", 0.5)) for k in range(6)]
    data = frames[0] + noise + b"".join(frames[1:3]) + noise + b"".join(frames[3:]) + noise[:5]
    got = {}
    for name, dec in decoders(65536).items():
        assert [f.seq for f in dec.feed(data)] == [0]
        got[name] = ([(f.seq, f.offset) for f in dec.give_up()], dec.counters.as_dict(), dec.buffered())
    assert got["kernel"] == got["reference"] == got["numpy"]
    seqs, c, left = got["reference"]
    assert [s for s, _ in seqs] == [1, 2, 3, 4, 5] and left == 5
    assert (c["crc_failures"], c["bytes_discarded"]) == (2, 2 * len(noise))


def test_every_flipped_bit_of_a_frame_is_caught():
    """One bit flipped anywhere after the sync (header, payload or CRC): never a frame with the
    wrong bytes; a CRC failure, or a header reject when the header turns invalid (or, a length
    grown past the stream's end, a candidate dropped at the flush); the next frame comes through."""
    frame = encode_frame(FrameType.TACHO, 9, 1000, 0, 0, struct.pack("<HII", 2, 3200, 40000))
    nxt = encode_frame(FrameType.RMS, 10, 1250, 1, 0, struct.pack("<f", 1.0))
    caught: dict[tuple[int, int], int] = {}
    for i in range(2 * 8, 8 * len(frame)):
        bad = bytearray(frame)
        bad[i // 8] ^= 1 << (i % 8)
        dec = Decoder(kernel=True)
        got = dec.feed(bytes(bad) + nxt) + dec.flush()
        c = dec.counters
        assert [f.seq for f in got] == [10] and c.crc_failures + c.header_rejects <= 1, i
        assert c.bytes_discarded == len(frame)
        caught[c.crc_failures, c.header_rejects] = caught.get((c.crc_failures, c.header_rejects), 0) + 1
    assert caught[1, 0] > 8 * len(frame) - 60 and caught[0, 1] >= 8          # the version, the type


@given(st.binary(max_size=5000))
def test_the_kernels_crc_is_zlibs(data):
    from cmsensord import _wirekernel

    assert _wirekernel.crc32(data) == zlib.crc32(data)
    assert _wirekernel.crc32(memoryview(data)[1:]) == zlib.crc32(data[1:])


def test_the_kernel_refuses_rows_too_small_for_the_buffer():
    from cmsensord import _wirekernel

    buf = bytearray(encode_frame(FrameType.RMS, 0, 0, 1, 0, bytes(4)) * 10)
    rows = np.empty((10, len(buf) // 18 - 1), dtype=np.int64)
    with pytest.raises(ValueError, match="out holds"):
        _wirekernel.scan(buf, False, 1, 4, 4096, 0, -1, 0, 0, rows, None, None)


def test_decoder_kernel_true_without_the_kernel_raises(monkeypatch):
    monkeypatch.setattr(wire_scan, "_wirekernel", None)
    with pytest.raises(ImportError, match="_wirekernel is not built"):
        Decoder(kernel=True)
    assert Decoder()._kernel is None                           # None: the Python receiver


#: `cmsensord replay` with the wire kernel unimportable (as without a compiler) when asked
REPLAY = """
import sys
if sys.argv[1] == "off":
    sys.modules["cmsensord._wirekernel"] = None
from cmsensord import wire_scan
from cmsensord.cli import main
assert wire_scan.have_kernel() == (sys.argv[1] == "on")
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.process
def test_replay_of_a_noisy_capture_is_the_same_with_and_without_the_kernel(tmp_path):
    clean = tmp_path / "clean.bin"
    sc = make_scenario("faulty", n_channels=2, duration_s=8, seed=3)
    Board(sc, BoardConfig(n_channels=2, mode="raw", tacho=True)).write_capture(clean, 8)
    rnd = random.Random(3)
    data = bytearray(clean.read_bytes())
    for _ in range(150):                            # bit flips, dropped and inserted bytes
        at = rnd.randrange(len(data))
        e = rnd.random()
        if e < 0.5:
            data[at] ^= 1 << rnd.randrange(8)
        elif e < 0.75:
            del data[at:at + rnd.randrange(1, 40)]
        else:
            data[at:at] = rnd.choice([SYNC, rnd.randbytes(7), SYNC + b"\x01\x03"])
    (tmp_path / "noisy.bin").write_bytes(bytes(data))
    out = {}
    for kernel in ("on", "off"):
        p = subprocess.run([sys.executable, "-c", REPLAY, kernel, "replay", str(tmp_path / "noisy.bin"),
                            "--out", str(tmp_path / kernel)], capture_output=True, text=True, env=ENV, timeout=300)
        assert p.returncode == 0, p.stderr
        messages = read_messages(next((tmp_path / kernel).glob("*.mcap")))
        links = [m["link"] for t, _, m in messages if t == "/cm/diagnostics"]
        summary = [line for line in p.stdout.splitlines() if " wall " not in line and "MCAP log" not in line]
        out[kernel] = (comparable(messages), links, summary)
    assert out["on"] == out["off"]
    link = out["on"][1][-1]
    assert link["crc_failures"] > 50 and link["header_rejects"] > 0 and link["frames_lost"] > 50
    events = [m["kind"] for t, _, m in out["on"][0] if t == "/cm/events"]
    assert "frames_lost" in events
