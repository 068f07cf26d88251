"""MCAP rotation by time and size: every message lands in exactly one finished file."""

from __future__ import annotations

import dataclasses
import errno
import os
import re
from pathlib import Path

import pytest

from cmsensord.config import OutputConfig
from cmsensord.sinks.mcap_sink import log_files, read_messages, summarize
from cmsensord.sinks.rotating import RotatingSink
from cmsensord.sinks.schemas import TOPIC_EVENTS, schema_bytes


def event(i, kind="config"):
    return {"kind": kind, "channel": None, "message": f"message {i}"}


def test_rotation_by_time_keeps_every_message(tmp_path, clock):
    out = dataclasses.replace(OutputConfig(), dir=str(tmp_path), rotate_s=10.0)
    sink = RotatingSink(out, clock=clock)
    for i in range(100):
        sink.write("/cm/events", "event", 1_000_000_000 * (i + 1), event(i))
        clock.t += 0.5                      # 50 s of messages: a new file every 10 s
    sink.close()
    assert len(sink.paths) == 5
    assert sorted(tmp_path.glob("*.mcap")) == sorted(sink.paths)
    assert not list(tmp_path.glob("*.part"))
    got = [m["message"] for p in sink.paths for _, _, m in read_messages(p)]
    assert got == [f"message {i}" for i in range(100)]


def test_rotation_by_size(tmp_path, clock):
    out = dataclasses.replace(OutputConfig(), dir=str(tmp_path), rotate_mb=0.002, flush_s=1.0,
                              compression="none")
    sink = RotatingSink(out, clock=clock)
    for i in range(300):
        sink.write("/cm/events", "event", 1_000_000_000 * (i + 1), event(i))
        clock.t += 0.25                     # a chunk is flushed every 4 messages
    sink.close()
    assert len(sink.paths) >= 3
    schema = 2 * len(schema_bytes("event"))     # in the first chunk and the summary of each file
    assert all(p.stat().st_size < 2600 + schema for p in sink.paths)
    got = [m["message"] for p in sink.paths for _, _, m in read_messages(p)]
    assert got == [f"message {i}" for i in range(300)]


# --- durability schedule, retention, reopen, events --------------------------------


def output(tmp_path, **kw):
    """An output section writing into tmp_path, retention off unless asked for."""
    base = {"dir": str(tmp_path), "retain_mb": 0.0, "min_free_mb": 0.0}
    return dataclasses.replace(OutputConfig(), **{**base, **kw})


@pytest.fixture
def fsyncs(monkeypatch):
    """Every os.fsync call as the inode it was made on (then the real fsync runs)."""
    calls = []
    real = os.fsync

    def spy(fd):
        calls.append(os.fstat(fd).st_ino)
        return real(fd)

    monkeypatch.setattr(os, "fsync", spy)
    return calls


def test_an_event_is_fsynced_at_the_next_tick_once_per_tick(tmp_path, fsyncs, clock):
    sink = RotatingSink(output(tmp_path, fsync_s=30.0), clock=clock)
    ino, d = os.fstat(sink.current.fileno()).st_ino, tmp_path.stat().st_ino
    assert fsyncs == [d]                                 # the directory, once the file is made
    sink.write("/cm/ch0/severity", "severity", 10**18, {"severity_index": 0.1})
    clock.t += 0.1
    sink.tick()
    assert fsyncs == [d]                                 # no event, fsync_s not reached
    for i in range(3):                                   # routine events: they ride fsync_s
        sink.write(TOPIC_EVENTS, "event", 10**18 + i, event(i, "frames_lost"))
    clock.t += 0.1
    sink.tick()
    assert fsyncs == [d]
    for i in range(3):
        sink.write(TOPIC_EVENTS, "event", 10**18 + 3 + i, event(i, "failure"))
    clock.t += 0.1
    sink.tick()
    assert fsyncs == [d, ino]                            # one fsync for the three failures
    on_disk = summarize(sink.current.part_path)
    assert on_disk["event_counts"] == {"frames_lost": 3, "failure": 3} and on_disk["messages"] == 7
    clock.t += 0.1
    sink.tick()
    assert fsyncs == [d, ino]                            # nothing new: no fsync
    clock.t += 30.0
    sink.tick()
    assert fsyncs == [d, ino, ino]                       # fsync_s
    sink.close()


def test_an_event_queued_between_ticks_is_fsynced_by_the_first_tick(tmp_path, fsyncs, clock):
    sink = RotatingSink(output(tmp_path, fsync_s=30.0), clock=clock)
    ino, d = os.fstat(sink.current.fileno()).st_ino, tmp_path.stat().st_ino
    sink.on_event = lambda kind, message, **fields: sink.write(
        TOPIC_EVENTS, "event", 10**18, {"kind": kind, "channel": None, "message": message})
    sink.emit("disk_error", "old.mcap.part: cannot read: Input/output error; left for the next start")
    clock.t += 0.1                                       # as the salvage thread does
    sink.tick()
    assert fsyncs == [d, ino]                            # the directory once the file was made
    assert summarize(sink.current.part_path)["event_counts"] == {"disk_error": 1}
    sink.close()


def test_ticks_every_100_ms_keep_everything_older_than_flush_s_in_the_file(tmp_path, clock):
    sink = RotatingSink(output(tmp_path, flush_s=1.0), clock=clock)
    written = []                                         # clock time of each message
    flushes = 0
    for k in range(80):
        for _ in range(3):                               # 3 messages per loop iteration
            sink.write("/cm/ch0/severity", "severity", 10**18 + len(written),
                       {"severity_index": 0.1})
            written.append(clock.t)
        clock.t += 0.1
        sink.tick()
        on_disk = summarize(sink.current.part_path)["messages"]
        assert on_disk >= sum(t <= clock.t - 1.0 for t in written), k
        flushes += on_disk == len(written)
    assert 8 <= flushes <= 9                             # 8 s: about one flush a second
    sink.close()


@pytest.mark.parametrize("tick_s", [(0.1,), (0.1, 0.006), (0.1, 0.1, 0.1, 0.006, 0.3)])
def test_a_held_stream_and_uneven_ticks_keep_everything_older_than_flush_s(tmp_path, clock, tick_s):
    """A board at 10x (1 s of stamps per 0.1 s) whose first event came 1.3 s of stamps late:
    the reorder window holds every message ~0.13 s; the live loop's ticks alternate long
    and short, with a late one now and then."""
    sink = RotatingSink(output(tmp_path, flush_s=1.0), clock=clock)
    written = []                                         # clock time of each message
    stamp = 10**18
    sink.write(TOPIC_EVENTS, "event", stamp + 2 * 10**9, {"kind": "start", "message": "x"})
    sink.write(TOPIC_EVENTS, "event", stamp + 7 * 10**8, {"kind": "config", "message": "late"})
    written += [clock.t, clock.t]
    for k in range(150):
        dt = tick_s[k % len(tick_s)]
        for _ in range(3):
            stamp += int(dt * 10**10 / 3)                # 10x: dt of wall is 10 dt of stamps
            sink.write("/cm/ch0/severity", "severity", stamp + 2 * 10**9, {"severity_index": 0.1})
            written.append(clock.t)
        clock.t += dt                                    # a kill just before the tick
        on_disk = summarize(sink.current.part_path)["messages"]
        assert on_disk >= sum(t <= clock.t - 1.0 for t in written), k
        sink.tick()
    sink.close()


def test_retention_keeps_the_newest_files_under_the_cap_and_only_ours(tmp_path, clock):
    (tmp_path / "other-20200101T000000Z.mcap").write_bytes(b"x" * 50_000)    # not our prefix
    (tmp_path / "cmsensord-20200101T000000Z.mcap.part").write_bytes(b"")    # a leftover: salvaged
    events = []
    rotated = []
    # files of ~6 kB (the severity schema alone is ~3 kB of each), a cap of ~30 kB
    sink = RotatingSink(output(tmp_path, rotate_mb=0.006, retain_mb=0.03, compression="none"),
                        clock=clock, on_event=lambda kind, message, **f: events.append((kind, f)),
                        on_rotate=rotated.append)
    pad = "p" * 300
    for i in range(200):
        sink.write("/cm/ch0/severity", "severity", 10**18 + i, {"severity_index": 0.1, "i": i,
                                                                  "pad": pad})
        clock.t += 0.25
        finished, parts = log_files(tmp_path, "cmsensord")
        assert sum(p.stat().st_size for p in finished + parts) <= 30_000 + 7_000   # + one flush
    sink.close()
    finished, parts = log_files(tmp_path, "cmsensord")
    assert parts == [] and (tmp_path / "other-20200101T000000Z.mcap").exists()
    kept = [m["i"] for p in finished for _, _, m in read_messages(p)]
    assert kept == list(range(200 - len(kept), 200)) and len(kept) > 15  # the newest, in order
    retention = [f for kind, f in events if kind == "retention"]
    assert retention and all(f["details"]["action"] == "retention" for f in retention)
    assert "disk_error" not in [kind for kind, _ in events]
    deleted = [name for f in retention for name in f["details"]["files"]]
    assert sorted(deleted + [p.name for p in finished]) == sorted(
        p.name for p in rotated + [sink.paths[-1]])      # every finished file: kept or deleted once
    assert sorted(sink.paths) == sorted(finished)        # paths lists only what is left


UNLINK = Path.unlink


def three_logs_refusing(tmp_path, clock, monkeypatch, code: int = errno.EACCES) -> tuple[list[Path], set[Path]]:
    """Three finished logs in tmp_path, oldest first, and the set of paths whose unlinking fails
    with ``code`` (EACCES: the directory's permission) from now on (the oldest; the caller may
    change it)."""
    refused: set[Path] = set()
    for k in range(3):
        RotatingSink(output(tmp_path), clock=clock, wall_clock=lambda k=k: 1_577_836_800.0 + 60 * k).close()

    def refuse(path, *a, **kw):
        if path in refused:
            raise OSError(code, os.strerror(code), str(path))
        return UNLINK(path, *a, **kw)

    monkeypatch.setattr(Path, "unlink", refuse)
    files = sorted(tmp_path.glob("*.mcap"))
    refused.add(files[0])
    return files, refused


def capped_sink(tmp_path, clock, files: list[Path]) -> tuple[RotatingSink, float, list]:
    """A sink whose cap the oldest two of ``files`` are over (its start's retention pass would
    delete them): (the sink, the cap in MB, the events it emits)."""
    cap_mb = 1.5 * files[0].stat().st_size / 1e6
    events: list = []
    sink = RotatingSink(output(tmp_path, retain_mb=cap_mb, rotate_mb=cap_mb), clock=clock,
                        on_event=lambda kind, message, **f: events.append((kind, message, f)))
    return sink, cap_mb, events


def test_a_file_retention_cannot_delete_is_one_event_and_ends_the_pass(tmp_path, clock, monkeypatch):
    files, refused = three_logs_refusing(tmp_path, clock, monkeypatch)
    sink, cap_mb, events = capped_sink(tmp_path, clock, files)
    assert [p.exists() for p in files] == [True, True, True]      # the pass ended at the first
    assert [(k, m, f["details"]) for k, m, f in events] == [(
        "disk_error", f"{files[0]}: retention cannot delete: Permission denied",
        {"action": "retention_failed", "errno": "EACCES", "file": str(files[0])})]
    assert sink.disk_errors == 1
    refused.clear()
    events.clear()
    sink.rotate()                                        # the next pass deletes, oldest first
    sink.close()
    assert not files[0].exists() and not files[1].exists()
    assert len(events) == 1 and events[0][2]["details"]["files"][:2] == [files[0].name, files[1].name]
    a, b = (re.escape(p.name) for p in files[:2])
    assert re.fullmatch(rf"deleted the \d oldest log file\(s\) \([0-9.]+ MB: {a}, {b}.*\) to keep "
                        rf"this prefix's files under retain_mb = {cap_mb:g} MB \(now [0-9.]+ MB\)",
                        events[0][1]), events[0][1]


def test_a_file_retention_keeps_failing_on_is_told_once_and_its_repeats_when_it_goes(tmp_path, clock,
                                                                                     monkeypatch):
    files, refused = three_logs_refusing(tmp_path, clock, monkeypatch)
    sink, _, events = capped_sink(tmp_path, clock, files)
    sink.rotate()
    sink.rotate()                                        # three passes refused the same way
    assert [f["details"]["action"] for _, _, f in events] == ["retention_failed"]
    assert sink.disk_errors == 3 and files[0].exists()
    refused.clear()
    sink.rotate()                                        # the fourth deletes it, and says what came before
    sink.close()
    assert not files[0].exists()
    assert [(k, f["details"]["action"]) for k, _, f in events] == [("disk_error", "retention_failed"),
                                                                   ("retention", "retention")]
    assert events[1][1].endswith("; the 3 pass(es) before this one failed (told once)"), events[1][1]


def test_another_file_retention_cannot_delete_is_a_new_event(tmp_path, clock, monkeypatch):
    files, refused = three_logs_refusing(tmp_path, clock, monkeypatch)
    sink, _, events = capped_sink(tmp_path, clock, files)
    refused.add(files[1])
    UNLINK(files[0])                                     # gone by hand: the next oldest refuses
    sink.rotate()
    sink.close()
    assert [(f["details"]["action"], f["details"]["file"]) for _, _, f in events] == [
        ("retention_failed", str(files[0])), ("retention_failed", str(files[1]))]


def small_capped_sink(tmp_path, clock, files: list[Path]) -> tuple[RotatingSink, list]:
    """A sink whose cap the oldest of ``files`` alone is over, so that every pass tries it
    first: (the sink, the events it emits)."""
    events: list = []
    cap_mb = 0.5 * files[0].stat().st_size / 1e6
    sink = RotatingSink(output(tmp_path, retain_mb=cap_mb, rotate_mb=cap_mb), clock=clock,
                        on_event=lambda kind, message, **f: events.append((kind, message, f)))
    return sink, events


def test_a_file_refused_for_a_reason_of_its_own_is_passed_over_and_told_once(tmp_path, clock, monkeypatch):
    """An immutable oldest log larger than the cap: the next oldest, itself over the cap, goes
    instead; the newer logs are not deleted to make room for it (it is left out of the cap's
    count), and each pass that meets it again says nothing more."""
    files, _ = three_logs_refusing(tmp_path, clock, monkeypatch, code=errno.EPERM)
    for path, kb in ((files[0], 100), (files[1], 80)):
        with path.open("ab") as f:
            f.write(bytes(kb * 1000))
    events: list = []
    sink = RotatingSink(output(tmp_path, retain_mb=0.05, rotate_mb=0.05), clock=clock,
                        on_event=lambda kind, message, **f: events.append((kind, message, f)))
    assert [p.exists() for p in files] == [True, False, True]
    assert [(m, f["details"]) for _, m, f in events[:1]] == [(
        f"{files[0]}: retention cannot delete: Operation not permitted",
        {"action": "retention_failed", "errno": "EPERM", "file": str(files[0])})]
    assert [f["details"]["files"] for _, _, f in events[1:]] == [[files[1].name]]
    rotated = [sink.rotate() for _ in range(3)]          # each pass meets the same refusal first
    sink.close()
    assert [(k, f["details"]["action"]) for k, _, f in events] == [("disk_error", "retention_failed"),
                                                                   ("retention", "retention")]
    assert sink.disk_errors == 4 and files[0].exists() and files[2].exists()
    assert all(p is not None and p.exists() for p in rotated), rotated


def test_two_files_passed_over_are_told_once_each_and_their_repeats_when_they_go(tmp_path, clock,
                                                                                monkeypatch):
    files, refused = three_logs_refusing(tmp_path, clock, monkeypatch, code=errno.EISDIR)
    refused.add(files[1])
    sink, events = small_capped_sink(tmp_path, clock, files)
    sink.rotate()
    sink.rotate()                                        # three passes refused both
    told = [f["details"]["file"] for _, _, f in events if f["details"]["action"] == "retention_failed"]
    assert told == [str(files[0]), str(files[1])] and sink.disk_errors == 6
    assert files[0].exists() and files[1].exists() and not files[2].exists()
    refused.clear()
    events.clear()
    sink.rotate()                                        # both go, and the pass says what came before
    sink.close()
    assert not files[0].exists() and not files[1].exists()
    [(_, message, fields)] = events
    assert fields["details"]["files"][:2] == [files[0].name, files[1].name]
    assert message.endswith("; the 3 pass(es) before this one failed (told once)"), message


def test_an_unreachable_free_space_floor_deletes_nothing_and_says_so(tmp_path, clock):
    old = tmp_path / "cmsensord-20200101T000000Z.mcap"
    RotatingSink(output(tmp_path), clock=clock, wall_clock=lambda: 1_577_836_800.0).close()
    assert old.exists()
    events = []
    huge = 1e12                                          # never reachable by deleting logs
    sink = RotatingSink(output(tmp_path, min_free_mb=huge), clock=clock,
                        on_event=lambda kind, message, **f: events.append((kind, message, f)))
    assert old.exists()                                  # the history is kept
    for i in range(3):
        sink.write("/cm/ch0/severity", "severity", 10**18 + i, {"severity_index": 0.1})
        done = sink.rotate()
        assert done.exists() and sink.current.part_path.exists()
    kinds = [(k, f["details"]["action"]) for k, _m, f in events]
    assert kinds == [("disk_error", "low_space")]        # said once, nothing deleted
    assert re.fullmatch(
        rf"{re.escape(str(tmp_path))}: [0-9.]+ MB free, below min_free_mb = 1e\+12 MB, which "
        r"deleting the 0 older finished log\(s\) of prefix 'cmsensord' \(0.0 MB; never the "
        r"newest\) cannot reach: none deleted for it", events[0][1])
    sink.close()


def test_a_reachable_free_space_floor_deletes_the_oldest_but_never_the_newest(
        tmp_path, clock, monkeypatch):
    import cmsensord.sinks.retention as retention
    for k in range(4):
        RotatingSink(output(tmp_path), clock=clock,
                     wall_clock=lambda k=k: 1_577_836_800.0 + 60 * k).close()
    files = sorted(tmp_path.glob("*.mcap"))
    size = files[0].stat().st_size
    state = {"free": 0}

    def free_bytes(_path):                               # freed only by what retention deletes
        return state["free"] + sum(size for p in files if not p.exists())

    monkeypatch.setattr(retention, "free_bytes", free_bytes)
    floor_mb = 2.5 * size / 1e6                          # reached after three deletions
    events = []
    sink = RotatingSink(output(tmp_path, min_free_mb=floor_mb), clock=clock,
                        on_event=lambda kind, message, **f: events.append(f["details"]))
    assert [p.exists() for p in files] == [False, False, False, True]
    assert [d["action"] for d in events] == ["retention"] and len(events[0]["files"]) == 3
    sink.close()
    state["free"] = -10 * size                           # now beyond reach: nothing more goes
    events.clear()
    RotatingSink(output(tmp_path, min_free_mb=floor_mb), clock=clock,
                 on_event=lambda kind, message, **f: events.append(f["details"])).close()
    assert files[3].exists() and [d["action"] for d in events] == ["low_space"]


def test_a_free_space_floor_out_of_reach_past_a_refused_log_deletes_nothing(tmp_path, clock, monkeypatch):
    """The floor reachable by deleting the three older logs, but the oldest is immutable: the
    two others cannot reach it, so they are kept and low_space says so."""
    import cmsensord.sinks.retention as retention
    files, _ = three_logs_refusing(tmp_path, clock, monkeypatch, code=errno.EPERM)
    RotatingSink(output(tmp_path), clock=clock, wall_clock=lambda: 1_577_836_800.0 + 180).close()
    files = sorted(tmp_path.glob("*.mcap"))
    size = files[0].stat().st_size
    monkeypatch.setattr(retention, "free_bytes", lambda _path: sum(size for p in files if not p.exists()))
    events = []
    RotatingSink(output(tmp_path, min_free_mb=2.5 * size / 1e6), clock=clock,
                 on_event=lambda kind, message, **f: events.append(f["details"]["action"])).close()
    assert [p.exists() for p in files] == [True, True, True, True]
    assert events == ["retention_failed", "low_space"]


def test_reopen_finishes_the_file_and_continues_in_a_new_one(tmp_path, clock):
    sink = RotatingSink(output(tmp_path), clock=clock)
    sink.write(TOPIC_EVENTS, "event", 10**18, event(0))
    first = sink.path
    assert sink.reopen() == first and first.exists()
    sink.write(TOPIC_EVENTS, "event", 10**18 + 1, event(1))
    second = sink.close()
    assert second != first and sink.paths == [first, second]
    assert [m["message"] for p in sink.paths for _, _, m in read_messages(p)] == ["message 0",
                                                                                  "message 1"]


def test_a_failed_directory_fsync_after_a_new_file_is_one_event_and_the_file_goes_on(tmp_path, clock,
                                                                                     monkeypatch):
    """The directory fsync after creating a ``.part`` fails (EIO; no real file system here fails
    it on demand): a ``disk_error`` event (action dir_fsync_failed) naming the file, counted
    as a failed operation; the file is written and finished as any other."""
    from cmsensord.sinks import mcap_file

    real, failures = mcap_file.fsync_dir, [OSError(errno.EIO, "Input/output error")]

    def fsync_dir(path):
        if failures:
            raise failures.pop()
        real(path)

    monkeypatch.setattr(mcap_file, "fsync_dir", fsync_dir)
    sink = RotatingSink(output(tmp_path), clock=clock)
    part = sink.current.part_path
    assert sink.pending_events == [("disk_error", f"{tmp_path}: directory fsync failed after creating "
                                    f"{part.name}: Input/output error", {"details": {
                                        "action": "dir_fsync_failed", "op": "fsync", "errno": "EIO",
                                        "file": str(part)}})]
    assert sink.disk_errors == 1
    sink.write(TOPIC_EVENTS, "event", 10**18, event(0))
    assert sink.close() == tmp_path / part.name.removesuffix(".part")
    assert [m["message"] for _, _, m in read_messages(sink.paths[0])] == ["message 0"]
    assert sink.disk_errors == 1 and len(sink.pending_events) == 1


def test_events_wait_for_the_callback_and_arrive_in_order(tmp_path):
    for k in range(3):
        (tmp_path / f"cmsensord-2020010{k + 1}T000000Z.mcap.part").write_bytes(b"")
    sink = RotatingSink(output(tmp_path))
    queued = sink.pending_events
    assert [m.split(":")[0] for _k, m, _f in queued] == [
        f"cmsensord-2020010{k + 1}T000000Z.mcap.part" for k in range(3)]
    got = []
    sink.on_event = lambda kind, message, **f: got.append(message)
    assert got == [m for _k, m, _f in queued] and sink.pending_events == []
    sink.close()


def test_retention_settings_are_validated():
    from cmsensord.config import config_from_dict
    from cmsensord.errors import ConfigError

    with pytest.raises(ConfigError, match=r"output.retain_mb: must be 0 \(no cap\) or >= rotate_mb"):
        config_from_dict({"output": {"retain_mb": 100, "rotate_mb": 256}}, source="x.yaml")
    with pytest.raises(ConfigError, match=r"output.min_free_mb: must be >= 0"):
        config_from_dict({"output": {"min_free_mb": -1}}, source="x.yaml")
    with pytest.raises(ConfigError, match=r"output.retry_s: must be > 0"):
        config_from_dict({"output": {"retry_s": 0}}, source="x.yaml")
    cfg = config_from_dict({"output": {"retain_mb": 0, "min_free_mb": 0}}, source="x.yaml")
    assert (cfg.output.retain_mb, cfg.output.min_free_mb, cfg.output.retry_s) == (0.0, 0.0, 10.0)
