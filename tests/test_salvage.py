"""Salvage of leftover ``*.mcap.part`` files: complete chunks become a finished file that
mcap's readers open; truncated or damaged bytes never raise. Also ``cmsensord summary``
on truncated and non-MCAP files."""

from __future__ import annotations

import dataclasses
import errno
import io
import random
import threading
from pathlib import Path

import pytest
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

from cmsensord.config import OutputConfig
from cmsensord.sinks import disk_events, mcap_salvage
from cmsensord.sinks.mcap_file import SinkIOError
from cmsensord.sinks.mcap_sink import (
    McapSink,
    log_files,
    read_messages,
    salvage,
    salvage_leftovers,
    summarize,
)
from cmsensord.sinks.rotating import RotatingSink
from cmsensord.sinks.schemas import TOPIC_EVENTS, severity_topic
from fakes import FakeClock
from processes import cmsensord

T0 = 1_700_000_000_000_000_000
STEM = "cmsensord-20231114T221320Z"


def _part_bytes(tmp_path: Path, *, compression: str = "zstd", n: int = 16) -> tuple[bytes, bytes]:
    """(bytes of a .part as a crash leaves it, bytes of the same file finished).

    Three topics, schemas and channels registered in different chunks, metadata,
    a chunk about every third message; every chunk is flushed, so the .part
    ends after a complete record, like a file whose writer was killed between
    two flushes.
    """
    clock = FakeClock()
    sink = McapSink(tmp_path / "src", compression=compression, clock=clock, flush_s=1.0,
                    metadata={"scenario": "test"}, wall_clock=lambda: 1_700_000_000.0)
    for k in range(n):
        sink.write(severity_topic("ch0"), "severity", T0 + k * 10**9, {"severity_index": k / n})
        if k % 4 == 1:
            sink.write(TOPIC_EVENTS, "event", T0 + k * 10**9 + 1,
                       {"kind": "config", "channel": None, "message": f"event {k}"})
        if k >= 6:
            sink.write("/cm/diagnostics", "diagnostics", T0 + k * 10**9 + 2, {"observations": k})
        clock.t += 0.5
    sink.flush()
    part = sink.part_path.read_bytes()
    return part, sink.close().read_bytes()


def _chunks_of(finished: bytes) -> list[tuple[int, list[tuple[str, int, bytes]]]]:
    """(end offset of the chunk record, its messages) per chunk, with mcap's own code:
    the summary's chunk indexes, each chunk parsed and broken up by mcap."""
    reader = make_reader(io.BytesIO(finished))
    summary = reader.get_summary()
    topics = {cid: ch.topic for cid, ch in summary.channels.items()}
    out = []
    for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        raw = finished[ci.chunk_start_offset: ci.chunk_start_offset + ci.chunk_length]
        chunk = next(iter(StreamReader(io.BytesIO(raw), skip_magic=True, emit_chunks=True).records))
        assert isinstance(chunk, Chunk)
        msgs = [(topics[r.channel_id], r.log_time, r.data) for r in breakup_chunk(chunk)
                if isinstance(r, Message)]
        out.append((ci.chunk_start_offset + ci.chunk_length, msgs))
    return out


def _read_all(path: Path) -> list[tuple[str, int, bytes]]:
    """Every message through mcap's seeking reader (CRCs checked) and its streaming reader;
    the two must agree."""
    with open(path, "rb") as f:
        seeking = [(c.topic, m.log_time, m.data)
                   for _s, c, m in make_reader(f, validate_crcs=True).iter_messages(log_time_order=False)]
    with open(path, "rb") as f:
        streaming = [(c.topic, m.log_time, m.data)
                     for _s, c, m in NonSeekingReader(f, validate_crcs=True).iter_messages()]
    assert seeking == streaming
    return seeking


def test_salvage_at_every_byte_offset_recovers_exactly_the_complete_chunks(tmp_path):
    data, finished = _part_bytes(tmp_path)
    chunks = _chunks_of(finished)
    assert len(chunks) >= 7 and finished.startswith(data)   # same data section
    ends = {end for end, _msgs in chunks}
    # mcap's readers check the salvaged file around every chunk end and at random cuts;
    # every cut is salvaged and its message count checked
    check = {c for end in ends for c in (end - 1, end)} | set(random.Random(5).sample(
        range(len(data) + 1), 60))
    part = tmp_path / f"{STEM}.mcap.part"
    seen = set()
    for cut in range(len(data) + 1):
        part.write_bytes(data[:cut])
        result = salvage(part, durable=False)
        expected = [m for end, msgs in chunks if end <= cut for m in msgs]
        assert not part.exists(), cut
        assert result.messages == len(expected), cut
        assert result.chunks == sum(end <= cut for end in ends), cut
        assert not result.damaged, cut
        if expected:
            assert result.action == "salvaged" and result.path == tmp_path / f"{STEM}.salvaged.mcap"
            if cut not in check:
                result.path.unlink()
                continue
            assert _read_all(result.path) == expected, cut
            s = summarize(result.path)
            assert s["complete"] and s["error"] is None and s["messages"] == len(expected)
            assert s["metadata"]["cmsensord"] == {"scenario": "test"}
            assert s["metadata"]["cmsensord.salvage"]["messages"] == str(len(expected))
            result.path.unlink()
        else:
            assert result.action == "removed" and result.path is None
        seen.add(result.chunks)
    assert seen == set(range(len(chunks) + 1))                # every prefix length was seen
    assert not list(tmp_path.glob("*.tmp"))


@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_damaged_bytes_never_raise_and_salvage_only_original_messages(tmp_path, compression):
    data, finished = _part_bytes(tmp_path, compression=compression)
    original = [m for _end, msgs in _chunks_of(finished) for m in msgs]
    rng = random.Random(2024)
    part = tmp_path / f"{STEM}.mcap.part"
    outcomes = {}
    for _ in range(300):
        damaged = bytearray(data)
        for _ in range(rng.randint(1, 3)):
            damaged[rng.randrange(len(damaged))] ^= 1 << rng.randrange(8)
        part.write_bytes(bytes(damaged[: rng.randrange(len(damaged) // 2, len(damaged) + 1)]))
        result = salvage(part, durable=False)
        outcomes[result.action] = outcomes.get(result.action, 0) + 1
        if result.action == "salvaged":
            got = _read_all(result.path)
            it = iter(original)              # an in-order subsequence of what was written
            assert all(any(m == o for o in it) for m in got)
            result.path.unlink()
        elif result.action == "set_aside":
            assert result.path.name == part.name + ".unreadable" and result.path.exists()
            result.path.unlink()
        assert not part.exists()
    assert outcomes.get("salvaged", 0) > 100   # most damage leaves a salvageable prefix


def test_what_is_not_recoverable(tmp_path):
    data, _ = _part_bytes(tmp_path)
    part = tmp_path / f"{STEM}.mcap.part"
    part.write_bytes(b"")                          # killed right after creating it
    r = salvage(part)
    assert r.action == "removed" and not part.exists()
    assert "nothing recoverable" in r.message() and "removed" in r.message()
    part.write_bytes(b"this is not MCAP, but it is named like ours")
    r = salvage(part)
    assert r.action == "set_aside" and r.damaged and "not an MCAP file" in r.reason
    assert not part.exists() and (tmp_path / f"{STEM}.mcap.part.unreadable").exists()
    assert "kept as" in r.message()
    chunks = _chunks_of(_part_bytes(tmp_path / "b")[1])
    first_chunk = chunks[0][0]
    bad = bytearray(data)
    bad[first_chunk - 20] ^= 0xFF                  # inside the first chunk's data: CRC fails
    part.write_bytes(bytes(bad))
    r = salvage(part)
    # the later chunks are kept, but for the messages on the channels chunk 1 defined
    lost_topics = {topic for topic, _t, _d in chunks[0][1]}
    later = [m for _end, msgs in chunks[1:] for m in msgs]
    expected = [m for m in later if m[0] not in lost_topics]
    assert r.action == "salvaged" and r.damaged and r.lost_chunks == 1
    assert r.messages == len(expected) > 0 and _read_all(r.path) == expected
    assert r.lost_messages == len(chunks[0][1]) + len(later) - len(expected)
    assert not part.exists() and r.kept == tmp_path / f"{STEM}.mcap.part.damaged"
    assert r.kept.read_bytes() == bytes(bad)


@pytest.mark.parametrize("where", ["length", "past_end", "opcode", "data"])
def test_after_a_damaged_chunk_every_intact_chunk_is_kept(tmp_path, where):
    data, finished = _part_bytes(tmp_path, compression="none")
    chunks = _chunks_of(finished)
    start = max(s for s in _chunk_starts(finished) if s < chunks[3][0])
    bad = bytearray(data)
    if where == "length":                          # its length claims far too much
        bad[start + 1 + 6] ^= 0x40
    elif where == "past_end":                      # ... or 16 MiB more than the file holds
        bad[start + 1 + 3] ^= 0x01
    elif where == "opcode":                        # no longer a chunk record at all
        bad[start] = 0x7F
    else:                                          # its content fails the CRC
        bad[chunks[3][0] - 20] ^= 0x01
    part = tmp_path / f"{STEM}.mcap.part"
    part.write_bytes(bytes(bad))
    r = salvage(part, durable=False)
    lost = chunks[3][1]
    earlier = {topic for _end, msgs in chunks[:3] for topic, _t, _d in msgs}
    undefined = {topic for topic, _t, _d in lost} - earlier      # channels chunk 4 defined
    later = [m for _end, msgs in chunks[4:] for m in msgs]
    expected = [m for _end, msgs in chunks[:3] for m in msgs] + [
        m for m in later if m[0] not in undefined]
    assert undefined and len(expected) < len(later) + sum(len(m) for _e, m in chunks[:3])
    assert r.action == "salvaged" and r.damaged and _read_all(r.path) == expected
    assert r.messages == len(expected) and r.chunks == len(chunks) - 1
    assert r.lost_chunks == (where == "data")      # a chunk that failed its checks
    on_undefined = len(later) - len(expected) + sum(len(m) for _e, m in chunks[:3])
    # the damaged chunk's own messages are known from its message index when its length held
    assert r.lost_messages == on_undefined + (len(lost) if where == "data" else 0)
    assert r.kept is not None and r.kept.read_bytes() == bytes(bad) and not part.exists()
    assert r.damage == {
        "length": f"record at byte {start} claims {int.from_bytes(bad[start + 1:start + 9], 'little')}"
                  " bytes",
        "past_end": f"a record at byte {start} claims more bytes than the file holds",
        "opcode": f"unknown opcode 0x7f at byte {start}",
        "data": f"damaged chunk at byte {start}: chunk CRC mismatch"}[where]


def _chunk_starts(finished: bytes) -> list[int]:
    reader = make_reader(io.BytesIO(finished))
    return sorted(ci.chunk_start_offset for ci in reader.get_summary().chunk_indexes)


def test_a_finished_but_not_renamed_file_is_salvaged_whole(tmp_path):
    _, finished = _part_bytes(tmp_path)
    part = tmp_path / f"{STEM}.mcap.part"
    part.write_bytes(finished)                     # crash between the footer and the rename
    r = salvage(part)
    expected = [m for _end, msgs in _chunks_of(finished) for m in msgs]
    assert r.action == "salvaged" and r.dropped_bytes == 0 and r.reason == "a finished file"
    assert _read_all(r.path) == expected


def test_leftovers_of_our_prefix_only_and_never_a_file_being_written(tmp_path):
    data, _ = _part_bytes(tmp_path)
    d = tmp_path / "logs"
    d.mkdir()
    ours = d / f"{STEM}.mcap.part"
    ours_too = d / "cmsensord-20231114T221321Z-1.mcap.part"
    others = [d / "other-20231114T221320Z.mcap.part", d / "cmsensord-rig2-20231114T221320Z.mcap.part",
              d / "notes.mcap.part"]
    for p in [ours, ours_too, *others]:
        p.write_bytes(data)
    live = McapSink(d, wall_clock=lambda: 1_700_000_100.0)   # open: flock'ed by this writer
    live.write(TOPIC_EVENTS, "event", T0, {"kind": "start", "channel": None, "message": "x"})
    live.flush()
    results = salvage_leftovers(d, "cmsensord")
    by_source = {r.source.name: r for r in results}
    assert by_source[live.part_path.name].action == "busy" and live.part_path.exists()
    assert by_source[ours.name].action == "salvaged" and by_source[ours_too.name].action == "salvaged"
    assert all(p.exists() for p in others)
    assert len(results) == 3
    live.close()
    finished, parts = log_files(d, "cmsensord")
    assert [p.name for p in finished] == sorted([f"{STEM}.salvaged.mcap", live.path.name,
                                                 "cmsensord-20231114T221321Z-1.salvaged.mcap"])
    assert parts == []


def test_rotating_sink_salvages_at_start_and_queues_the_event_until_routed(tmp_path):
    data, finished = _part_bytes(tmp_path)
    n_complete = len([m for end, msgs in _chunks_of(finished) if end <= len(data) - 7 for m in msgs])
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / f"{STEM}.mcap.part").write_bytes(data[:-7])          # the last chunk cut short
    (logs / "cmsensord-20231114T221400Z.mcap.part").write_bytes(data[:20])   # header only
    out = dataclasses.replace(OutputConfig(), dir=str(logs))
    sink = RotatingSink(out)
    assert [k for k, _m, _f in sink.pending_events] == ["salvage", "salvage"]
    got = []
    sink.on_event = lambda kind, message, **fields: (
        got.append((kind, message, fields)),
        sink.write(TOPIC_EVENTS, "event", T0, {"kind": kind, "channel": None, "message": message,
                                               **fields}))
    assert sink.pending_events == []
    (_k1, m1, f1), (_k2, m2, f2) = got
    assert f1["count"] == n_complete > 0 and f1["details"]["action"] == "salvaged"
    assert f"salvaged {n_complete} message(s)" in m1 and f"{STEM}.salvaged.mcap" in m1
    assert f2["count"] == 0 and "nothing recoverable" in m2
    path = sink.close()
    events = [m for t, _, m in read_messages(path) if t == TOPIC_EVENTS]
    assert [e["kind"] for e in events] == ["salvage", "salvage"]
    assert len(_read_all(logs / f"{STEM}.salvaged.mcap")) == n_complete
    assert not list(logs.glob("*.part"))



def test_a_background_salvage_s_results_are_counted_and_said_by_the_writing_thread(tmp_path, monkeypatch):
    """The daemon's salvage thread hands every result over: a leftover it cannot read (EACCES)
    is counted in ``disk_errors`` and said by the thread that writes (no count lost to a
    read-modify-write racing the writer's), its one line as before."""
    logs = tmp_path / "logs"
    logs.mkdir()
    part = logs / f"{STEM}.mcap.part"
    part.write_bytes(_part_bytes(tmp_path)[0])

    real_open = mcap_salvage._open_regular

    def unreadable(path, result):                # the leftover only: the open file is busy, skipped
        if path == part:
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_open(path, result)

    monkeypatch.setattr(mcap_salvage, "_open_regular", unreadable)
    said_by = []
    real = disk_events.salvage_result
    def said(sink, result):
        if isinstance(result, SinkIOError):
            said_by.append((threading.current_thread().name, result.path))
        real(sink, result)

    monkeypatch.setattr(disk_events, "salvage_result", said)
    sink = RotatingSink(dataclasses.replace(OutputConfig(), dir=str(logs)), background_salvage=True)
    assert sink._salvager is not None
    sink._salvager.join()
    sink.tick()
    assert said_by == [("MainThread", part)] and sink.disk_errors == 1
    assert [(k, m, f["details"]["action"]) for k, m, f in sink.pending_events] == [
        ("disk_error", f"{part}: cannot read: Permission denied; left for the next start", "salvage_failed")]
    sink.close()
    assert part.exists() and said_by == [("MainThread", part)] and sink.disk_errors == 1

# --- cmsensord summary ------------------------------------------------------------


def _cli(*args):
    return cmsensord(*args, timeout=60)


def test_summary_of_truncated_files_and_of_a_file_that_is_not_mcap(tmp_path):
    data, finished = _part_bytes(tmp_path)
    first_chunk_end = _chunks_of(finished)[0][0]    # a cut past it keeps the first chunk's messages
    counts = []
    for cut in [0, 5, 40, first_chunk_end + 1, len(data) - 1]:
        part = tmp_path / f"cut{cut}.mcap.part"
        part.write_bytes(data[:cut])
        p = _cli("summary", str(part))
        assert p.returncode == 0, p.stderr
        assert "Traceback" not in p.stderr
        expected = summarize(part)["messages"]
        assert f"messages: {expected}\n" in p.stdout and "truncated: True" in p.stdout
        counts.append(expected)
    assert counts[0] == 0 and 0 < counts[3] < counts[4]
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"GIF89a not a log at all")
    p = _cli("summary", str(junk))
    assert p.returncode == 2 and p.stdout == ""
    assert p.stderr.strip().splitlines() == [f"cmsensord: {junk}: not an MCAP file (bad magic)"]
