"""The open file's chunk index is what grows while a file is written: one entry per chunk, a
chunk per ``flush_s`` of wall time (3600 an hour, 86,400 at daily rotation). Each entry is
kept as the bytes of its summary record (~190 bytes for 11 channels), and the file is the
one mcap's own Writer makes of the same messages."""

from __future__ import annotations

import io
import tracemalloc

from mcap.reader import make_reader

from cmsensord.sinks.mcap_chunks import ChunkWriter

CHUNKS = 2000
CHANNELS = 11          # a 4-channel RMS daemon's second: severity, indicators per channel, ...


def _writer(fh) -> tuple[ChunkWriter, list[int]]:
    w = ChunkWriter(fh, "zstd", 1 << 20)
    w.start(library="test")
    ids = [w.register_channel(f"/t{i}", "json", w.register_schema(f"s{i}", "jsonschema", b"{}"))
           for i in range(CHANNELS)]
    return w, ids


class _Null:
    def write(self, data: bytes) -> int:
        return len(data)


def test_the_chunk_index_keeps_at_most_250_bytes_a_chunk():
    w, ids = _writer(_Null())
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        for k in range(CHUNKS):
            for c in ids:
                w.add_message(c, k * 10**9 + c, b'{"x": 1}' * 20)
            w.finish_chunk()
        kept = tracemalloc.get_traced_memory()[0] - base
    finally:
        tracemalloc.stop()
    assert kept / CHUNKS < 250, f"{kept / CHUNKS:.0f} bytes a chunk"


def test_the_summary_indexes_every_chunk_and_its_messages():
    fh = io.BytesIO()
    w, ids = _writer(fh)
    for k in range(50):
        for c in ids[: 1 + k % CHANNELS]:
            w.add_message(c, k * 10**9 + c, b'{"x": %d}' % k)
        w.finish_chunk()
    w.finish()
    summary = make_reader(io.BytesIO(fh.getvalue()), validate_crcs=True).get_summary()
    assert summary is not None and summary.statistics is not None
    assert len(summary.chunk_indexes) == summary.statistics.chunk_count == 50
    assert [len(ci.message_index_offsets) for ci in summary.chunk_indexes] == [1 + k % CHANNELS for k in range(50)]
    got = [(m.channel_id, m.log_time) for _s, _c, m in
           make_reader(io.BytesIO(fh.getvalue())).iter_messages(log_time_order=False)]
    assert got == [(c, k * 10**9 + c) for k in range(50) for c in ids[: 1 + k % CHANNELS]]
