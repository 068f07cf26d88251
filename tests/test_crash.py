"""The real daemon on a real pty, killed with SIGKILL at random moments and restarted on
the same log directory; and SIGHUP reopening its log.

How the loss at a kill is measured: every /cm/diagnostics message carries ``uptime_s``,
the daemon's monotonic time when it was written, and the run's ``start`` event carries the
wall clock at that time origin, so start + uptime_s is the wall-clock moment each
diagnostics message was handed to the sink (not its ADC time stamp, which runs 10x faster
than the wall here). The simulated board runs at 10x, so those messages come every ~0.1 s.
If the first diagnostics message missing from the salvaged file had been written more
than 1 s before the kill, something written more than 1 s before the kill was lost: that
is what the test rules out (to the ~0.1 s resolution of the diagnostics).
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from mcap.reader import make_reader

from cmsensord.sinks.mcap_sink import iter_messages_lenient, log_files, summarize
from cmsensord.sinks.schemas import TOPIC_DIAGNOSTICS, TOPIC_EVENTS
from processes import ENV, board_on_pty, spawn

NS = 1_000_000_000


def read_all(path: Path) -> list[tuple[str, int, bytes]]:
    """Every message through mcap's reader, CRCs checked (raises on any damage), with the stamp
    it was written with (its publish time, as iter_messages_lenient gives it)."""
    with open(path, "rb") as f:
        return [(c.topic, m.publish_time, m.data)
                for _s, c, m in make_reader(f, validate_crcs=True).iter_messages(log_time_order=False)]


def assert_every_finished_file_is_whole(logs: Path) -> list[Path]:
    finished, _parts = log_files(logs, "cmsensord")
    for p in finished:
        s = summarize(p)
        assert s["complete"] and s["error"] is None and s["valid_bytes"] == s["file_bytes"], p
        assert len(read_all(p)) == s["messages"], p
    return finished


def start_daemon(cfg: Path, err: Path) -> subprocess.Popen:
    with open(err, "ab") as f:
        return spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)],
                                stdout=subprocess.DEVNULL, stderr=f, env=ENV)


def wait_for(predicate, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = predicate()
        if found:
            return found
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def new_part(logs: Path, seen: set[str]):
    return lambda: next((p for p in logs.glob("cmsensord-*.mcap.part") if p.name not in seen), None)


def written_at(messages) -> list[int]:
    """Wall-clock ns at which each diagnostics message was written: start event + uptime_s."""
    start = [t for topic, t, data in messages
             if topic == TOPIC_EVENTS and json.loads(data)["kind"] == "start"]
    assert len(start) == 1
    return [start[0] + round(json.loads(data)["uptime_s"] * NS)
            for topic, _t, data in messages if topic == TOPIC_DIAGNOSTICS]


def test_kill_9_at_random_moments_loses_at_most_the_last_second(tmp_path):
    rng = random.Random(1122)
    logs = tmp_path / "logs"
    err = tmp_path / "daemon.err"
    kills = []                                   # (part, kill wall ns, readable messages, early)
    with board_on_pty("--scenario", "degrading", "--duration", "600", "--speed", "10") as port:
        cfg = tmp_path / "cmsensord.yaml"            # + the AKF trace: ~1000 messages a second
        cfg.write_text(f"link:\n  port: {port}\noutput:\n  dir: {logs}\n  status_line: false\n"
                       "  akf_trace: true\n")
        seen: set[str] = set()
        for delay in [rng.uniform(1.5, 4.0) for _ in range(3)] + [rng.uniform(0.0, 0.3)]:
            early = delay < 1.0                  # killed before any diagnostics
            d = start_daemon(cfg, err)
            part = wait_for(new_part(logs, seen), 30, "the daemon's .part file")
            seen.add(part.name)
            time.sleep(delay)
            t_kill = time.time_ns()
            os.kill(d.pid, signal.SIGKILL)
            assert d.wait(timeout=10) == -signal.SIGKILL
            copy = tmp_path / f"{part.name}.copy"
            shutil.copyfile(part, copy)          # what a lenient reader finds in it
            kills.append((part, t_kill, list(iter_messages_lenient(copy)), early))
            assert_every_finished_file_is_whole(logs)   # a kill never leaves a damaged .mcap
        # a last start salvages the last kill's file; SIGTERM ends it cleanly
        d = start_daemon(cfg, err)
        wait_for(new_part(logs, seen), 30, "the daemon's .part file")
        time.sleep(1.0)
        d.send_signal(signal.SIGTERM)
        assert d.wait(timeout=10) == 0, err.read_text()[-3000:]
    assert "Traceback" not in err.read_text()
    finished = assert_every_finished_file_is_whole(logs)
    assert not list(logs.glob("*.part"))
    salvage_events = [json.loads(data) for p in finished for topic, _t, data in read_all(p)
                      if topic == TOPIC_EVENTS and json.loads(data)["kind"] == "salvage"]
    report = []
    journal = err.read_text()
    for k, (part, t_kill, readable, early) in enumerate(kills):
        salvaged = logs / part.name.replace(".mcap.part", ".salvaged.mcap")
        event = [e for e in salvage_events if e["details"]["source"].endswith(part.name)]
        assert not part.exists()
        if not event and k + 1 < len(kills) and kills[k + 1][3]:
            # salvaged by the next start, killed within 0.3 s: its event was in its last second,
            # which a kill may lose (the journal has it); the salvaged file is checked below
            line = next(x for x in journal.splitlines() if f"salvage: {part.name}: " in x)
            assert f"salvaged {len(readable)} message(s)" in line, line
            event = [{"count": len(readable), "message": line}]
        assert len(event) == 1, part.name
        if not readable:                         # killed before its first flush
            assert early and not salvaged.exists() and event[0]["count"] == 0
            assert "nothing recoverable" in event[0]["message"]
            report.append((part.name, 0, None))
            continue
        got = read_all(salvaged)
        assert got == readable                   # everything readable, nothing else
        assert event[0]["count"] == len(got)
        stamps = written_at(got)
        if early:                                # the kill within 0.3 s: salvaged, and whole
            report.append((part.name, len(got), None))
            continue
        assert len(stamps) >= 3, (part.name, len(got))   # > 1.5 s of a 10x board: ~10/s
        step = sorted(b - a for a, b in zip(stamps, stamps[1:]))[len(stamps) // 2]
        gap = (t_kill - stamps[-1]) / NS         # kill -> last diagnostics message on disk
        assert 0 < step < 0.3 * NS
        # the first missing diagnostics message was written less than 1 s before the kill
        assert stamps[-1] + step >= t_kill - 1.0 * NS, (part.name, gap, step / NS)
        report.append((part.name, len(got), round(gap, 3)))
    print("kill -9 runs (file, messages salvaged, kill - last message on disk [s]):", report)


def test_sighup_finishes_the_log_and_continues_in_a_new_file(tmp_path):
    logs = tmp_path / "logs"
    err = tmp_path / "daemon.err"
    with board_on_pty("--scenario", "healthy", "--speed", "10") as port:
        cfg = tmp_path / "cmsensord.yaml"
        cfg.write_text(f"link:\n  port: {port}\noutput:\n  dir: {logs}\n  status_line: false\n")
        d = start_daemon(cfg, err)
        first = wait_for(new_part(logs, set()), 30, "the daemon's .part file")
        time.sleep(1.5)
        d.send_signal(signal.SIGHUP)
        second = wait_for(new_part(logs, {first.name}), 5, "a new .part after SIGHUP")
        finished = logs / first.name.removesuffix(".part")
        assert finished.exists() and not first.exists()   # finished and renamed, not salvaged
        assert len(read_all(finished)) > 10
        time.sleep(1.5)
        d.send_signal(signal.SIGTERM)
        assert d.wait(timeout=10) == 0, err.read_text()[-3000:]
    assert "Traceback" not in err.read_text()
    files = assert_every_finished_file_is_whole(logs)
    assert [p.name for p in files] == [finished.name, second.name.removesuffix(".part")]
    a, b = (read_all(p) for p in files)
    kinds = [[json.loads(m)["kind"] for t, _s, m in x if t == TOPIC_EVENTS] for x in (a, b)]
    assert kinds[0][0] == "start" and kinds[1][-1] == "stop"
    # nothing lost at the switch: the diagnostics (every ~0.1 s) go on without a gap
    up = [json.loads(m)["uptime_s"] for x in (a, b) for t, _s, m in x if t == TOPIC_DIAGNOSTICS]
    assert up == sorted(up) and max(y - x for x, y in zip(up, up[1:])) < 0.5
    assert max(s for _t, s, _m in a) <= min(s for _t, s, _m in b)
