"""A capture is whole or absent after a crash: its three messages go into one chunk of the log
(McapSink.write_group), whatever the chunk size and the reorder window, and a file cut at any byte
of that chunk holds all three or none (read with the lenient reader, as salvage and report do)."""

from __future__ import annotations

from pathlib import Path

from mcap.records import Channel, Chunk, Message
from mcap.stream_reader import breakup_chunk

from cmsensord.sinks.mcap_file import McapSink
from cmsensord.sinks.mcap_read import RecordWalker, iter_messages_lenient, parse_record, read_messages
from cmsensord.sinks.memory import ListSink

CAPTURE = ("/cm/ch0/capture_waveform", "/cm/ch0/capture_spectrum", "/cm/ch0/capture_envelope")
S = 1_000_000_000


def chunk_topics(path: Path) -> list[tuple[int, int, list[str]]]:
    """(start, end, topics of its messages) of every chunk of the file."""
    topics: dict[int, str] = {}
    out = []
    with open(path, "rb") as f:
        for offset, _, raw in RecordWalker(f).records():
            rec = parse_record(raw)
            if not isinstance(rec, Chunk):
                continue
            names = []
            for r in breakup_chunk(rec):
                if isinstance(r, Channel):
                    topics[r.id] = r.topic
                elif isinstance(r, Message):
                    names.append(topics[r.channel_id])
            out.append((offset, offset + len(raw), names))
    return out


def _group(stamp: int) -> list[tuple[str, str, int, dict]]:
    head = {"channel": "ch0", "trigger": {"kind": "periodic", "message": "every 5 s"}}
    wave = {**head, "source": "raw", "sample_rate_hz": 100.0, "first_sample": 0, "pre_s": 1.0, "post_s": 1.0,
            "unit": "m/s^2", "missing": 0, "samples": [round(0.001 * k, 6) for k in range(200)]}
    spec = {**head, "kind": "spectrum", "freq_start_hz": 0.0, "freq_step_hz": 0.5, "unit": "m/s^2",
            "amplitude": [0.5] * 101}
    env = {**spec, "kind": "envelope", "band_hz": [10.0, 40.0]}
    return [(CAPTURE[0], "capture_waveform", stamp, wave), (CAPTURE[1], "capture_spectrum", stamp, spec),
            (CAPTURE[2], "capture_spectrum", stamp, env)]


def _log(tmp: Path, grouped: bool) -> Path:
    """Events around a capture stamped 3 s back (held by the reorder window), with chunks of 300 bytes."""
    sink = McapSink(tmp, compression="zstd", flush_s=1e9, chunk_size=300, clock=lambda: 0.0)
    sink.reorder.horizon_ns = 5 * S
    for k in range(10):
        sink.write("/cm/events", "event", k * S, {"kind": "capture", "channel": "ch0", "message": f"e{k}"})
    if grouped:
        sink.write_group(_group(7 * S))
    else:
        for m in _group(7 * S):
            sink.write(*m)
    for k in range(10, 20):
        sink.write("/cm/events", "event", k * S, {"kind": "capture", "channel": "ch0", "message": f"e{k}"})
    return sink.close()


def test_a_group_is_one_chunk_of_its_own_in_log_time_order(tmp_path):
    path = _log(tmp_path / "g", grouped=True)
    holding = [names for _, _, names in chunk_topics(path) if set(names) & set(CAPTURE)]
    assert holding == [list(CAPTURE)]                  # one chunk, the three alone, beyond chunk_size
    msgs = read_messages(path)                         # mcap's own reader: a valid, ordered file
    assert [t for t, _, _ in msgs].count("/cm/events") == 20
    stamps = [s for _, s, _ in msgs]
    assert stamps == sorted(stamps) and [t for t, _, _ in msgs][8:11] == list(CAPTURE)   # after e0..e7
    # the same messages written one by one are split by chunk_size: what the group prevents
    split = [names for _, _, names in chunk_topics(_log(tmp_path / "s", grouped=False)) if set(names) & set(CAPTURE)]
    assert len(split) > 1


def test_a_cut_anywhere_in_the_group_chunk_leaves_all_three_or_none(tmp_path):
    path = _log(tmp_path / "g", grouped=True)
    data = path.read_bytes()
    start, end, _ = next(c for c in chunk_topics(path) if CAPTURE[0] in c[2])
    cut = tmp_path / "cut.mcap.part"
    seen = set()
    for n in range(start, end + 1):
        cut.write_bytes(data[:n])
        got = sum(t in CAPTURE for t, _, _ in iter_messages_lenient(cut))
        assert got in (0, 3), n
        seen.add(got)
    assert seen == {0, 3}                              # the last cut (the whole chunk) holds them


def test_list_sink_takes_a_group_as_its_messages():
    sink = ListSink()
    sink.write_group(_group(5))
    assert [(t, s) for t, s, _ in sink.messages] == [(t, 5) for t in CAPTURE]

