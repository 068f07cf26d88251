"""The decoder's one-pass path for runs of back-to-back frames (cmsensord/frame_runs.py)
equals the plain frame-by-frame receiver (``Decoder(runs=False)``, the reference) on random
streams of valid and invalid frames: the same frames, offsets, seq gaps, unwrapped t0 and
counters, whatever the reads.  The numpy runs are the path without the compiled wire
kernel (``kernel=False``); tests/test_wire_kernel.py holds the kernel to the same reference."""

from __future__ import annotations

import random
import struct

import numpy as np
import pytest

import cmsensord.protocol as protocol
from cmsensord.frame_runs import FrameRuns
from cmsensord.protocol import SYNC, Decoder, FrameType, encode_frame
from fakes import tacho_payload

LENGTHS = {FrameType.STATUS: lambda r: 20 + 8 * r.randrange(1, 9), FrameType.RMS: lambda r: 4 * r.randrange(1, 9),
           FrameType.RAW: lambda r: 2 * r.choice([0, 1, 250, 250, 700, 2048]),
           FrameType.TACHO: lambda r: 2 + 4 * r.randrange(0, 5)}


def random_stream(rnd: random.Random, n: int) -> bytes:
    """n frames of random types, seq gaps and t0 jumps (wraps included), with errors: flipped
    bytes, dropped and inserted bytes, fake syncs with plausible headers, frames sent twice, a
    truncated tail."""
    out = bytearray()
    seq, t0 = rnd.choice([0, 65500]), rnd.choice([0, 2**32 - 3000])
    for _ in range(n):
        ftype = rnd.choice(list(FrameType))
        payload = rnd.randbytes(LENGTHS[ftype](rnd))
        w = bytearray(encode_frame(ftype, seq, t0, rnd.randrange(4), rnd.choice([0, 0, 1, 2, 3]), payload))
        seq += 1 if rnd.random() < 0.95 else rnd.randrange(2, 300)
        t0 += rnd.choice([250, 250, 250, 0, 100_000, 2**31 + 5])
        e = rnd.random()
        if e < 0.04:
            w[rnd.randrange(len(w))] ^= 1 << rnd.randrange(8)          # a flipped bit: bad CRC or header
        elif e < 0.06:
            del w[rnd.randrange(len(w))]                               # a dropped byte
        elif e < 0.08:
            out += rnd.randbytes(rnd.randrange(1, 6))                  # junk between frames
        elif e < 0.10:                                                 # a fake sync and header
            head = struct.pack("<BBHIBBH", rnd.choice([1, 1, 2]), rnd.choice([1, 2, 3, 4, 9]), 0, 0, 2, 0,
                               rnd.choice([0, 8, 300, 4096, 4097]))
            out += SYNC + head + rnd.randbytes(rnd.randrange(0, 40))
        elif e < 0.12:
            out += w                                                   # a frame sent twice
        out += w
    if rnd.random() < 0.5:
        out += encode_frame(FrameType.RAW, seq, t0, 0, 0, bytes(500))[:rnd.randrange(1, 500)]
    return bytes(out)


def decode(data: bytes, runs: bool, reads: list[int], max_buffer: int = 65536, kernel: bool = False):
    dec = Decoder(max_buffer=max_buffer, runs=runs, kernel=kernel)
    frames, at = [], 0
    for size in reads:
        frames += dec.feed(data[at:at + size])
        at += size
    frames += dec.feed(data[at:])
    frames += dec.flush()
    return frames, dec.counters, dec.buffered()


@pytest.mark.parametrize("seed", range(30))
def test_runs_equal_the_frame_by_frame_decoder_on_random_valid_and_invalid_frames(seed, monkeypatch):
    rnd = random.Random(seed)
    data = random_stream(rnd, rnd.choice([50, 400, 1500]))
    taken = []
    take = FrameRuns.take

    def counting(self, start):
        r = take(self, start)
        taken.append(0 if r is None else len(r.pos))
        return r

    monkeypatch.setattr(FrameRuns, "take", counting)
    reads = [rnd.choice([1, 17, 600, 4096, 65536, 100_000]) for _ in range(rnd.randrange(0, 12))]
    max_buffer = rnd.choice([protocol.MAX_FRAME, 20_000, 65536])
    small = seed % 2 == 0 or max_buffer < protocol.MIN_BYTES
    if small:
        monkeypatch.setattr(protocol, "MIN_BYTES", 0)         # every buffer through the runs
    ref = decode(data, False, reads, max_buffer)
    assert not taken
    got = decode(data, True, reads, max_buffer)
    assert sum(taken) > 0 or not small                         # the runs did decode frames
    assert got[0] == ref[0]                                    # frames (offsets, gaps, unwrapped t0) ...
    assert [type(f.type) for f in got[0]] == [FrameType] * len(ref[0])
    assert got[1] == ref[1]                                    # ... counters ...
    assert got[2] == ref[2] == 0                               # ... and nothing left
    assert ref[1].crc_failures + ref[1].header_rejects > 0     # the stream had bad frames


def test_a_capture_in_replay_reads_decodes_mostly_in_runs():
    rnd = random.Random(1)
    frames = [encode_frame(FrameType.RMS, k, 250 * k, 4, 0, rnd.randbytes(16)) for k in range(5000)]
    data = b"".join(frames)
    taken = []
    dec = Decoder(kernel=False)
    runs_take = FrameRuns.take

    class Counting(FrameRuns):
        def take(self, start):
            r = runs_take(self, start)
            taken.append(0 if r is None else len(r.pos))
            return r

    protocol_runs = protocol.FrameRuns
    protocol.FrameRuns = Counting
    try:
        got = []
        for a in range(0, len(data), 65536):
            got += dec.feed(data[a:a + 65536])
        got += dec.flush()
    finally:
        protocol.FrameRuns = protocol_runs
    assert len(got) == 5000 and dec.counters.frames["rms"] == 5000
    reads = len(data) // 65536 + 1
    # all but the frame cut by each read's end (finished in a few bytes, frame by frame)
    assert 5000 - reads <= sum(taken) <= 5000 and len(taken) <= 2 * reads


@pytest.mark.parametrize("seed", range(5))
def test_tacho_payloads_in_one_pass_equal_decode_tacho_one_by_one(seed):
    rnd = random.Random(seed)
    payloads = []
    for _ in range(400):
        n = rnd.choice([0, 0, 1, 1, 2, 4])
        p = struct.pack("<H", n) + b"".join(struct.pack("<I", rnd.randrange(2**32)) for _ in range(n))
        e = rnd.random()
        if e < 0.05:
            p = p[:rnd.randrange(len(p))]                 # short, even empty or a lone byte
        elif e < 0.1:
            p += rnd.randbytes(rnd.randrange(1, 5))       # too long for its N
        payloads.append(p)
    counts, offsets, bad = protocol.decode_tacho_many(payloads)
    want_edges, want_bad = [], []
    for i, p in enumerate(payloads):
        try:
            want_edges.append(protocol.decode_tacho(p))
        except protocol.ProtocolError as exc:
            want_bad.append((i, str(exc)))
            want_edges.append(protocol.decode_tacho(b"\0\0"))
    assert bad == want_bad and len(bad) > 5
    assert counts.tolist() == [len(e) for e in want_edges]
    assert offsets.dtype == "uint32" and offsets.tolist() == [int(x) for e in want_edges for x in e]
    assert protocol.decode_tacho_many([])[0].size == 0


def decode_batches(data: bytes, reads: list[int], kernel: bool):
    dec = Decoder(kernel=kernel)
    batches, at = [], 0
    for size in reads:
        batches.append(dec.feed_batch(data[at:at + size]))
        at += size
    batches.append(dec.feed_batch(data[at:]))
    batches.append(dec.flush_batch())
    return batches, dec.counters, dec.buffered()


@pytest.mark.parametrize("kernel", [False, True], ids=["numpy", "kernel"])
@pytest.mark.parametrize("seed", range(12))
def test_batches_equal_the_frame_by_frame_decoder(seed, kernel):
    """``Decoder.feed_batch`` (frames as columns, what a replay reads) gives the frames of the
    plain receiver: indexed, iterated, sliced, and its columns and RMS values read as arrays
    are those of the frames; with the numpy runs and with the compiled wire kernel."""
    from cmsensord.frame_batch import FrameBatch, Pending, rms_fields
    from cmsensord.protocol import decode_rms_rows

    rnd = random.Random(seed)
    data = random_stream(rnd, 3000)
    reads = [rnd.choice([1, 7, 100, 5000, 20000, 70000]) for _ in range(rnd.randrange(0, 8))]
    ref, ref_counters, ref_left = decode(data, runs=False, reads=reads)
    batches, counters, left = decode_batches(data, reads, kernel)
    assert all(type(b) is FrameBatch for b in batches)
    got = [f for b in batches for f in b]
    assert got == ref and len(ref) > 2000
    assert counters == ref_counters and left == ref_left
    whole = FrameBatch.join(batches)
    assert len(whole) == len(ref) and whole == ref
    for i in (0, 1, len(ref) // 2, -1):
        assert whole[i] == ref[i]
    a, b = sorted(rnd.sample(range(len(ref)), 2))
    view = whole[a:b]
    assert list(view) == ref[a:b] and view == ref[a:b] and view[1:4] == ref[a:b][1:4]
    pending = Pending()                                     # the Processor's waiting batch
    for lo, hi in ((a, b), (b, b + 5), (b + 7, b + 9)):
        pending.extend(whole[lo:hi])
    assert pending.joined() == ref[a:b] + ref[b:b + 5] + ref[b + 7:b + 9]
    assert type(pending.joined()) is FrameBatch and len(pending) == len(pending.joined())
    code, t0, lost = view.columns()
    assert code.tolist() == [int(f.type) for f in ref[a:b]]
    assert t0.tolist() == [f.t0_unwrapped for f in ref[a:b]]
    assert lost.tolist() == [f.lost_before > 0 or f.flags > 0xFF for f in ref[a:b]]   # a seq gap, repeats dropped
    rms = [i for i, f in enumerate(ref) if f.type == FrameType.RMS and len(f.payload) == 4 * f.chan]
    by_c = [i for i in rms if ref[i].chan == ref[rms[0]].chan]
    sel = whole.cols.take(np.array(by_c))
    batch = FrameBatch(sel, whole.data, whole._make)
    C = ref[by_c[0]].chan
    assert np.array_equal(decode_rms_rows(batch, C).view(np.uint32),
                          decode_rms_rows([ref[i] for i in by_c], C).view(np.uint32))
    for x, y in zip(rms_fields(batch), rms_fields([ref[i] for i in by_c])):
        assert x.tolist() == y.tolist()


@pytest.mark.parametrize("seed", range(5))
def test_a_few_tacho_payloads_one_by_one_equal_the_one_pass(seed):
    """The Shaft reads a live call's ten or so TACHO payloads into Python lists (monitor/shaft.py's
    decode_tacho_lists: struct, or the compiled step): the same counts, offsets and messages as
    decode_tacho_many's array code."""
    from cmsensord.monitor.shaft import FEW_TACHO, decode_tacho_lists

    rnd = random.Random(50 + seed)
    for _ in range(200):
        payloads = []
        for _ in range(rnd.randrange(FEW_TACHO + 1)):
            payloads.append(tacho_payload(rnd, [0, 0, 1, 1, 2, 4], 0.05, 0.05))
        got, want = decode_tacho_lists(payloads), protocol.decode_tacho_many(payloads)
        assert got[0] == want[0].tolist() and got[1] == want[1].tolist()
        assert got[2] == want[2]
