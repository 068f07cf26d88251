"""The chunk writer keeps one zstd compressor for all its chunks: each chunk's compressed
bytes are what a compressor of its own (``zstandard.compress``) makes of that chunk alone, so
the file is the same byte for byte whatever chunks came before (no state carried over)."""

from __future__ import annotations

import io
import random

import zstandard
from mcap.records import Chunk
from mcap.stream_reader import StreamReader

from cmsensord.sinks.mcap_chunks import ChunkWriter


def test_each_chunk_is_compressed_as_on_its_own():
    rng = random.Random(3)
    out = io.BytesIO()
    w = ChunkWriter(out, "zstd", 1 << 20)
    w.start("test")
    sid = w.register_schema("s", "jsonschema", b"{}")
    cid = w.register_channel("/t", "json", sid)
    t = 0
    for size in (1, 40, 3, 200, 7, 1000, 2, 60):       # chunks of very different sizes
        for _ in range(size):
            t += 10_000_000
            body = b'{"v": %.9f, "pad": "%s"}' % (rng.random(), b"x" * rng.randrange(0, 300))
            w.add_message(cid, t, body)
        w.finish_chunk()
    w.finish()
    out.seek(0)
    chunks = [r for r in StreamReader(out, emit_chunks=True).records if isinstance(r, Chunk)]
    assert len(chunks) == 8
    for chunk in chunks:
        assert chunk.compression == "zstd"
        raw = zstandard.ZstdDecompressor().decompress(chunk.data)
        assert len(raw) == chunk.uncompressed_size
        assert chunk.data == zstandard.compress(raw)
