"""A full or failing disk: the sink never raises, abandons the file, says so once, drops and
counts what cannot be written, retries, and resumes when the disk takes data again.

Real errors only: a small tmpfs filled up (skipped where mounting is not allowed),
/dev/full (ENOSPC on every write) and /dev/null (fsync fails with EINVAL) put under the
file descriptor the sink writes to, and the whole daemon on a tmpfs.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from cmsensord.config import OutputConfig
from cmsensord.errors import SinkError
from cmsensord.sinks.mcap_sink import McapSink, log_files, read_messages, summarize
from cmsensord.sinks.rotating import RotatingSink
from cmsensord.sinks.schemas import TOPIC_EVENTS
from fakes import FakeClock
from processes import ENV, spawn

T0 = 1_700_000_000_000_000_000
PAD = "v" * 400


def output(path, **kw):
    base = {"dir": str(path), "retain_mb": 0.0, "min_free_mb": 0.0, "compression": "none",
            "retry_s": 10.0}
    return dataclasses.replace(OutputConfig(), **{**base, **kw})


def fill(fs: Path, leave: int) -> Path:
    """A file taking all but ``leave`` bytes of the file system."""
    st = os.statvfs(fs)
    filler = fs / "filler"
    with open(filler, "wb") as f:
        f.write(b"\0" * max(0, st.f_bavail * st.f_frsize - leave))
    return filler


class Recorder:
    """on_event like the daemon's: keeps the event and writes it into the same sink."""

    def __init__(self, sink: RotatingSink, clock: FakeClock) -> None:
        self.sink, self.clock, self.events = sink, clock, []
        sink.on_event = self

    def __call__(self, kind, message, **fields):
        self.events.append((kind, message, fields))
        self.sink.write(TOPIC_EVENTS, "event", T0, {"kind": kind, "channel": None,
                                                    "message": message, **fields})

    def actions(self):
        return [f.get("details", {}).get("action") for _k, _m, f in self.events]


def test_a_disk_back_with_nothing_to_log_is_not_fsynced_at_every_tick(small_fs, clock, monkeypatch):
    """Space back while nothing comes to be logged (the board gone too): the new file takes its
    header and is fsynced once, not at every tick until a message comes (an SD card's wear: one
    fsync per loop turn for as long as the board is gone); logging resumes, said once, with the
    first message fsynced on it."""
    logs = small_fs / "logs"
    events: list = []
    sink = RotatingSink(output(logs, flush_s=1.0, fsync_s=30.0, retry_s=1.0), clock=clock,
                        on_event=lambda kind, message, **fields: events.append(fields.get("details", {})))
    filler = fill(small_fs, leave=24 * 1024)
    n = 0
    while sink.current is not None:
        sink.write("/cm/ch0/severity", "severity", T0 + n, {"severity_index": 0.1, "i": n, "pad": PAD})
        n += 1
        clock.t += 0.25
        sink.tick()
        assert n < 500, "the disk never filled up"
    filler.unlink()
    calls = []
    real = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: (calls.append(fd), real(fd))[1])
    for _ in range(100):                         # 10 s of loop turns, nothing to log
        clock.t += 0.1
        sink.tick()
    assert sink.current is not None and not sink.logging
    assert len(calls) <= 3, len(calls)           # the new file and its directory
    sink.write("/cm/ch0/severity", "severity", T0 + n, {"severity_index": 0.1, "i": n, "pad": PAD})
    clock.t += 0.1
    sink.tick()
    assert sink.logging and [e.get("action") for e in events].count("resumed") == 1
    sink.close()


def logged(paths):
    """(severity indices i, events) in the finished files, read with mcap's reader (CRCs checked)."""
    ii, events = [], []
    for p in paths:
        with open(p, "rb") as f:
            for _s, channel, message in make_reader(f, validate_crcs=True).iter_messages(
                    log_time_order=False):
                doc = json.loads(message.data)
                if channel.topic == TOPIC_EVENTS:
                    events.append(doc)
                else:
                    ii.append(doc["i"])
    return ii, events


def test_full_tmpfs_drops_and_counts_then_resumes_when_space_returns(small_fs, clock):
    logs = small_fs / "logs"
    sink = RotatingSink(output(logs, flush_s=1.0), clock=clock)
    rec = Recorder(sink, clock)
    n = 0

    def put(k=1):
        nonlocal n
        for _ in range(k):
            sink.write("/cm/ch0/severity", "severity", T0 + n, {"severity_index": 0.1, "i": n,
                                                                 "pad": PAD})
            n += 1
            clock.t += 0.25                  # a chunk (~2 KB) every 4 messages
            sink.tick()

    put(8)
    filler = fill(small_fs, leave=24 * 1024)
    while "abandoned" not in rec.actions():
        put()
        assert n < 500, "the disk never filled up"
    kind, message, fields = rec.events[rec.actions().index("abandoned")]
    assert kind == "disk_error" and fields["details"]["errno"] == "ENOSPC"
    assert "No space left on device" in message and "kept as" in message
    assert sink.current is None and not sink.logging
    dropped_at_failure = sink.dropped
    assert dropped_at_failure >= 1               # the chunk that did not fit
    put(30)                                      # 7.5 s, before retry_s: nothing is tried
    assert sink.dropped == dropped_at_failure + 30
    assert rec.actions().count("abandoned") == 1  # one event per outage
    filler.unlink()                              # space returns
    put(20)                                      # past retry_s: a new file, fsynced, resumed
    assert sink.logging
    resumed = [(m, f) for _k, m, f in rec.events if f.get("details", {}).get("action") == "resumed"]
    assert len(resumed) == 1
    message, fields = resumed[0]
    assert fields["count"] == sink.dropped >= dropped_at_failure + 30
    assert "logging resumed" in message and f"{sink.dropped} message(s) could not be logged" in message
    assert "salvaged" in rec.actions()           # the abandoned file, once the disk is back
    put(10)
    sink.close()
    finished, parts = log_files(logs, "cmsensord")
    assert parts == [] and any(p.name.endswith(".salvaged.mcap") for p in finished)
    ii, events = logged(finished)
    # what is missing is one contiguous run: the chunk that failed, then the outage
    missing = sorted(set(range(n)) - set(ii))
    assert sorted(ii) == sorted(set(ii)) and missing == list(range(missing[0], missing[-1] + 1))
    lost_events = len(rec.events) - len(events)
    assert len(missing) + lost_events == sink.dropped
    assert sink.messages_written - sink.dropped == len(ii) + len(events)
    assert [e["details"]["action"] for e in events if e["kind"] == "disk_error"][-1] == "resumed"


def test_starting_on_a_full_disk_runs_without_a_file_and_retries(small_fs, clock):
    logs = small_fs / "logs"
    logs.mkdir()
    filler = fill(small_fs, leave=0)
    sink = RotatingSink(output(logs, retry_s=5.0), clock=clock)   # does not raise
    assert sink.current is None and sink.disk_errors >= 1
    rec = Recorder(sink, clock)
    assert rec.actions() == ["abandoned"] and rec.events[0][2]["details"]["op"] == "open"
    for i in range(10):
        sink.write("/cm/ch0/severity", "severity", T0 + i, {"severity_index": 0.1, "i": i})
        clock.t += 1.0
        sink.tick()
    assert sink.current is None and sink.dropped == 11      # 10 + the event itself
    filler.unlink()
    clock.t += 5.0
    sink.tick()                                  # retry: open
    sink.tick()                                  # fsync of a header alone: not back yet (a full disk takes one)
    assert not sink.logging and rec.actions() == ["abandoned"]
    sink.write("/cm/ch0/severity", "severity", T0 + 10, {"severity_index": 0.1, "i": 10})
    sink.tick()                                  # fsync with a message in the file: resumed
    assert sink.logging and rec.actions() == ["abandoned", "resumed"]
    assert rec.events[1][2]["count"] == 11
    path = sink.close()
    assert [m.get("i", m.get("details", {}).get("action")) for _t, _s, m in read_messages(path)] == [10, "resumed"]
    assert not list(logs.glob("*.part"))


def test_an_unusable_directory_at_start_is_still_a_configuration_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(SinkError, match="cannot create output directory") as info:
        RotatingSink(output(blocker / "logs"))
    assert "\n" not in str(info.value)


def _swap_fd(sink: RotatingSink, device: str) -> int:
    """Put ``device`` under the descriptor the current file is written through; its inode."""
    fd = sink.current.fileno()
    ino = os.fstat(fd).st_ino
    dev = os.open(device, os.O_WRONLY)
    try:
        os.dup2(dev, fd)
    finally:
        os.close(dev)
    return ino


def test_dev_full_under_the_open_file_is_enospc_the_file_is_abandoned_and_salvaged(tmp_path, clock):
    sink = RotatingSink(output(tmp_path), clock=clock)
    rec = Recorder(sink, clock)
    for i in range(12):
        sink.write("/cm/ch0/severity", "severity", T0 + i, {"severity_index": 0.1, "i": i})
        clock.t += 0.25
    sink.flush()                                 # 0..11 are in the file
    first = sink.current.part_path
    _swap_fd(sink, "/dev/full")                  # every write from now on: ENOSPC
    for i in range(12, 15):
        sink.write("/cm/ch0/severity", "severity", T0 + i, {"severity_index": 0.1, "i": i})
    sink.tick()                                  # not yet flush_s: nothing written
    assert rec.actions() == []
    clock.t += 1.0
    sink.tick()                                  # flush: ENOSPC
    kind, message, fields = rec.events[0]
    assert (kind, fields["details"]["errno"], fields["count"]) == ("disk_error", "ENOSPC", 3)
    assert f"kept as {first.name}" in message
    # a new file at once (the directory is fine); the event is in it, fsynced: resumed
    assert sink.current is not None and sink.current.part_path != first
    sink.tick()
    assert rec.actions()[:3] == ["abandoned", "resumed", "salvaged"]
    assert rec.events[2][2]["count"] == 12       # 0..11 salvaged from the abandoned file
    sink.write("/cm/ch0/severity", "severity", T0 + 15, {"severity_index": 0.1, "i": 15})
    sink.close()
    finished, parts = log_files(tmp_path, "cmsensord")
    assert parts == []
    ii, events = logged(finished)
    assert sorted(ii) == list(range(12)) + [15] and sink.dropped == 3
    assert {e["details"]["action"] for e in events} == {"abandoned", "resumed", "salvaged"}


def test_a_failed_fsync_is_never_retried_on_that_file(tmp_path, monkeypatch, clock):
    fsynced = []
    real = os.fsync

    def spy(fd):
        try:
            fsynced.append(os.fstat(fd).st_ino)
        except OSError:
            fsynced.append("closed descriptor")
        return real(fd)

    monkeypatch.setattr(os, "fsync", spy)
    sink = RotatingSink(output(tmp_path, fsync_s=5.0), clock=clock)
    rec = Recorder(sink, clock)
    for i in range(8):
        sink.write("/cm/ch0/severity", "severity", T0 + i, {"severity_index": 0.1, "i": i})
        clock.t += 0.5
        sink.tick()
    clock.t += 5.0
    sink.tick()                                  # a good fsync: 0..7 durable
    first = sink.current.part_path
    ino = _swap_fd(sink, "/dev/null")            # writes vanish, fsync fails with EINVAL
    null = os.stat("/dev/null").st_ino           # what the file's descriptor now is
    assert fsynced.count(ino) == 1               # the good fsync
    for i in range(8, 12):
        sink.write("/cm/ch0/severity", "severity", T0 + i, {"severity_index": 0.1, "i": i})
        clock.t += 0.5
        sink.tick()                              # flushes go to /dev/null "successfully"
    clock.t += 5.0
    sink.tick()                                  # fsync: EINVAL
    _kind, message, fields = rec.events[0]
    assert fields["details"]["op"] == "fsync" and fields["details"]["errno"] == "EINVAL"
    assert fields["details"]["unsynced"] == 4 and "4 more written since the last good fsync" in message
    assert fsynced.count(null) == 1              # the failed one
    for i in range(12, 40):
        sink.write("/cm/ch0/severity", "severity", T0 + i, {"severity_index": 0.1, "i": i})
        clock.t += 0.5
        sink.tick()
    sink.reopen()
    sink.close()
    assert fsynced.count(null) == 1              # never again on that file (its descriptor
    # points at /dev/null until it is closed), nor on its closed descriptor (inode numbers
    # are reused once the salvaged .part is deleted, so they cannot tell the file later)
    assert "closed descriptor" not in fsynced and len(fsynced) > 4
    assert not first.exists()                    # salvaged when logging resumed
    finished, parts = log_files(tmp_path, "cmsensord")
    ii, _events = logged(finished)
    assert parts == [] and sorted(ii) == list(range(8)) + list(range(12, 40))


def daemon_filling(small_fs: Path, tmp_path: Path, config: str, *, settle_s: float, full_s: float) -> str:
    """``cmsensord --simulate`` (5x) logging to the tmpfs ``small_fs``/logs with ``config`` (YAML):
    filled ``settle_s`` after its first file appears, freed ``full_s`` later, stopped 3 s after
    (retry_s 1 in ``config``: logging resumed). It ran through and exited 0: its stderr."""
    logs = small_fs / "logs"
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(config)
    d = spawn([sys.executable, "-m", "cmsensord", "--simulate", "--config", str(cfg),
               "--out", str(logs), "--duration", "3600", "--speed", "5"],
              stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=ENV)
    try:
        deadline = time.monotonic() + 30
        while not list(logs.glob("*.part")) and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(settle_s)
        filler = fill(small_fs, leave=16 * 1024)
        time.sleep(full_s)
        assert d.poll() is None                  # still running
        filler.unlink()
        time.sleep(3.0)
        d.send_signal(signal.SIGTERM)
        _, err = d.communicate(timeout=20)
    finally:
        if d.poll() is None:
            d.kill()
            d.wait()
    assert d.returncode == 0, err[-2000:]
    assert "Traceback" not in err
    return err


@pytest.mark.slow
def test_the_daemon_keeps_running_on_a_full_disk_and_resumes_logging(small_fs, tmp_path):
    """The whole daemon (simulated board on a pty) writing to a tmpfs that fills up (the AKF
    trace fills the rest within a second)."""
    logs = small_fs / "logs"
    err = daemon_filling(small_fs, tmp_path, "output:\n  retry_s: 1.0\n  retain_mb: 0\n  min_free_mb: 0\n"
                         "  akf_trace: true\n  status_line: false\n", settle_s=1.0, full_s=3.0)
    journal = [ln for ln in err.splitlines() if "disk_error" in ln]
    assert any("No space left on device" in ln for ln in journal), err[-2000:]
    assert any("logging resumed" in ln for ln in journal), err[-2000:]
    finished, parts = log_files(logs, "cmsensord")
    assert parts == []
    ii = []
    for p in finished:
        s = summarize(p)
        assert s["complete"] and s["error"] is None
        with open(p, "rb") as f:
            ii += [m.log_time for _s, _c, m in make_reader(f, validate_crcs=True).iter_messages()]
    events = [m for p in finished for t, _s, m in read_messages(p) if t == TOPIC_EVENTS]
    resumed = [e for e in events if e["kind"] == "disk_error" and e["details"]["action"] == "resumed"]
    assert len(resumed) == 1 and resumed[0]["count"] > 0
    assert any(e["kind"] == "stop" for e in events)


def test_enospc_while_finishing_keeps_the_part_and_the_next_start_salvages_it(tmp_path, clock):
    sink = RotatingSink(output(tmp_path), clock=clock)
    rec = Recorder(sink, clock)
    for i in range(6):
        sink.write("/cm/ch0/severity", "severity", T0 + i, {"severity_index": 0.1, "i": i})
    sink.flush()
    part = sink.current.part_path
    _swap_fd(sink, "/dev/full")                  # the summary and footer cannot be written
    assert sink.close() is None and sink.paths == []
    (kind, message, fields), = rec.events        # its own event could not be logged: counted
    assert (kind, fields["details"]["op"], fields["details"]["errno"]) == ("disk_error", "close",
                                                                          "ENOSPC")
    assert part.exists() and sink.dropped == 1 and f"kept as {part.name}" in message
    again = RotatingSink(output(tmp_path), clock=clock)   # the next start
    (kind, message, fields), = again.pending_events
    assert kind == "salvage" and fields["count"] == 6 and not part.exists()
    again.close()
    finished, parts = log_files(tmp_path, "cmsensord")
    assert parts == [] and sorted(logged(finished)[0]) == list(range(6))


def _salvage_refused(small_fs: Path, clock) -> tuple[RotatingSink, Recorder, Path, Path]:
    """A file abandoned (ENOSPC under its descriptor) whose salvage, when logging resumes in a
    new file on a disk filled to a few kB, the full disk refuses: (sink, recorder, part, filler)."""
    sink = RotatingSink(output(small_fs / "logs", flush_s=1.0, retry_s=1.0), clock=clock)
    rec = Recorder(sink, clock)
    rec.events.clear()                           # a salvage at start (a previous part's)
    for i in range(120):
        sink.write("/cm/ch0/severity", "severity", T0 + i, {"severity_index": 0.1, "i": i, "pad": PAD})
    sink.flush()
    part = sink.current.part_path
    filler = fill(small_fs, leave=40 * 1024)     # room for a new file and a rotation, not for the part's copy
    _swap_fd(sink, "/dev/full")
    sink.write("/cm/ch0/severity", "severity", T0 + 120, {"severity_index": 0.1, "i": 120})
    clock.t += 1.0
    sink.tick()                                  # ENOSPC: abandoned, a new file at once
    sink.tick()                                  # the new file fsynced: resumed, salvage refused
    assert rec.actions()[:3] == ["abandoned", "resumed", "salvage_failed"]
    kind, message, fields = rec.events[2]
    assert (kind, message) == ("disk_error", f"{part}: cannot salvage: No space left on device; "
                                             "tried again after the next rotation")
    assert fields["details"]["errno"] == "ENOSPC" and part.exists()
    return sink, rec, part, filler


def test_a_salvage_the_full_disk_refuses_is_tried_again_after_a_rotation(small_fs, clock, caplog, monkeypatch):
    """A salvage refused for want of room keeps the file, said once: a rotation on a disk still
    full tries it again when the free space seems to hold it (refused again: counted, not said
    again), else leaves it waiting untried; the first rotation with room salvages it."""
    sink, rec, part, filler = _salvage_refused(small_fs, clock)
    errors = sink.disk_errors
    with monkeypatch.context() as m:             # the free space misread as ample: tried, refused
        m.setattr("cmsensord.sinks.disk_outage.free_bytes", lambda path: 1 << 40)
        sink.rotate()
    assert rec.actions().count("salvage_failed") == 1 and part.exists() and sink.disk_errors == errors + 1
    sink.rotate()                                # less room than the part: not tried
    assert rec.actions().count("salvage_failed") == 1 and part.exists() and sink.disk_errors == errors + 1
    filler.unlink()
    sink.rotate()                                # the disk took a whole file: salvaged now
    assert rec.actions().count("salvage_failed") == 1 and rec.actions().count("salvaged") == 1
    kind, message, fields = next(e for e in rec.events if e[2]["details"]["action"] == "salvaged")
    salvaged = small_fs / "logs" / part.name.replace(".mcap.part", ".salvaged.mcap")
    assert kind == "salvage" and fields["count"] == 120 and message.startswith(f"{part.name}: salvaged 120 message(s)")
    assert not part.exists() and salvaged in sink.paths
    sink.rotate()                                # nothing waits: nothing tried, nothing said
    sink.close()
    assert rec.actions().count("salvaged") == 1 and "left for the next start" not in caplog.text
    finished, parts = log_files(small_fs / "logs", "cmsensord")
    assert parts == [] and sorted(logged([salvaged])[0]) == list(range(120))


def test_a_file_waiting_for_salvage_is_left_for_the_next_start_or_dropped_when_gone(small_fs, clock, caplog):
    """At close a file still waiting for room is left for the next start, one journal line; a
    waiting file removed by hand is dropped from the list, quietly (never tried again)."""
    caplog.set_level("INFO", logger="cmsensord")
    sink, rec, part, filler = _salvage_refused(small_fs, clock)
    sink.close()
    assert [r.getMessage() for r in caplog.records if "left for the next start" in r.getMessage()] == [
        f"1 log file(s) kept for salvage and not salvaged yet: {part.name}; left for the next start"]
    assert part.exists()
    filler.unlink()
    caplog.clear()
    sink, rec, part, filler = _salvage_refused(small_fs, clock)   # the next start salvaged the first
    part.unlink()                                # an operator makes room
    filler.unlink()
    errors, actions = sink.disk_errors, rec.actions()
    sink.rotate()
    sink.close()
    assert rec.actions()[:len(actions)] == actions and "salvage_failed" not in rec.actions()[len(actions):]
    assert sink.disk_errors == errors and "left for the next start" not in caplog.text


def _wait_until(predicate, timeout: float) -> bool:
    """Whether ``predicate()`` came true within ``timeout`` seconds."""
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            return False
        time.sleep(0.05)
    return True


def test_a_leftover_the_full_disk_refuses_at_start_is_salvaged_after_a_rotation_with_room(small_fs, tmp_path):
    """The daemon (background salvage) started on a disk too full to copy an earlier run's
    ``.part``: the refusal is one line, the file waits; once another program's file is removed,
    the next rotation salvages it, all its messages. Not 'left for the next start': a daemon runs
    for months."""
    logs = small_fs / "logs"
    logs.mkdir()
    src = McapSink(tmp_path / "src", compression="none", clock=FakeClock(), wall_clock=lambda: 1_700_000_000.0)
    for i in range(300):                         # ~150 kB: a third of the tmpfs
        src.write("/cm/ch0/severity", "severity", T0 + i, {"severity_index": 0.1, "i": i, "pad": PAD})
    src.flush()
    part = logs / src.part_path.name
    part.write_bytes(src.part_path.read_bytes())  # as a kill leaves it
    src.close()
    filler = fill(small_fs, leave=part.stat().st_size * 2 // 3)   # room for the daemon's files, not the copy
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text("output:\n  rotate_s: 1.0\n  retain_mb: 0\n  min_free_mb: 0\n  status_line: false\n")
    journal = tmp_path / "stderr"
    with open(journal, "w") as err_file:
        d = spawn([sys.executable, "-m", "cmsensord", "--simulate", "--config", str(cfg), "--out", str(logs),
                   "--duration", "3600", "--speed", "5"], stderr=err_file, stdout=subprocess.DEVNULL, env=ENV)
    refused = f"ERROR disk_error: {part}: cannot salvage: No space left on device; tried again after the next rotation"
    try:
        assert _wait_until(lambda: "cannot salvage" in journal.read_text(), 30), journal.read_text()
        filler.unlink()                          # another program's file removed: room
        _wait_until(lambda: not part.exists() or d.poll() is not None, 5)   # rotate_s 1: salvaged
        d.send_signal(signal.SIGTERM)
        d.wait(timeout=20)
    finally:
        if d.poll() is None:
            d.kill()
            d.wait()
    lines = journal.read_text().splitlines()
    assert d.returncode == 0 and "Traceback" not in "\n".join(lines), lines[-30:]
    salvaged = logs / part.name.replace(".mcap.part", ".salvaged.mcap")
    assert [ln for ln in lines if part.name in ln] == [
        refused, f"INFO salvage: {part.name}: salvaged 300 message(s) from 1 complete chunk(s) into {salvaged.name}"]
    assert not part.exists() and [m["i"] for _t, _s, m in read_messages(salvaged)] == list(range(300))
    finished, parts = log_files(logs, "cmsensord")
    events = [m for p in finished for t, _s, m in read_messages(p) if t == TOPIC_EVENTS and part.name in m["message"]]
    assert [(e["kind"], e["details"]["action"], e.get("count")) for e in events] == [
        ("disk_error", "salvage_failed", None), ("salvage", "salvaged", 300)], events
