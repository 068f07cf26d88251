"""Link faults through real processes: line noise, an unplugged board, t0 wrapping.

The board is firmware_sim on a real pty (published under a stable symlink, as a
udev rule would), the daemon is ``python -m cmsensord --config``; nothing is mocked.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from cmsensord.config import config_from_dict
from cmsensord.protocol import OVERHEAD, iter_frames
from cmsensord.sinks.mcap_sink import read_messages
from firmware_sim.board import Board, BoardConfig
from firmware_sim.faults import frames_hit, read_records
from firmware_sim.scenarios import make_scenario
from messages import comparable
from processes import ENV, board_then_daemon, cmsensord, drain, fill, spawn, start_board, start_daemon, stop
from stream import run_processor


def test_line_noise_loses_only_the_frames_it_hits_and_replay_matches_live(tmp_path):
    """Byte error rate 1e-3 (flips, drops, insertions) injected by firmware_sim on the pty:
    no exception, exactly the frames hit by a fault are lost, the counters and the
    frames_lost events say so, and replaying the capture gives the live messages."""
    stats = board_then_daemon(tmp_path, "--scenario", "faulty", "--channels", "2", "--duration", "30",
                              "--speed", "5", "--seed", "3", "--byte-error-rate", "1e-3",
                              "--faults-out", str(tmp_path / "faults.jsonl"))
    assert stats["dropped_bytes"] == 0

    # what the board sent, clean, and which of its frames a fault hit
    sc = make_scenario("faulty", n_channels=2, duration_s=30.0, seed=3)
    board = Board(sc, BoardConfig(n_channels=2))
    clean = b"".join(data for data, _ in board.iter_blocks(board.n_blocks_for(30.0)))
    sent, _ = iter_frames(clean)
    spans = [(f.offset, f.offset + OVERHEAD + len(f.payload)) for f in sent]
    records = read_records(tmp_path / "faults.jsonl")
    hit = frames_hit(spans, records)
    assert len(records) > 50 and len(hit) > 40      # ~80 kB at 1e-3
    kinds = {r.kind for r in records}
    assert kinds == {"flip", "drop", "insert"}

    captured = (tmp_path / "cap.bin").read_bytes()
    got, counters = iter_frames(captured)
    key = lambda f: (f.type, f.seq, f.t0, f.chan, f.payload)        # noqa: E731
    # pyserial flushes the input when it opens the port: the capture starts with the
    # first frame read after that, part way into the board's stream
    first = [key(f) for f in sent].index(key(got[0]))
    assert first < len(sent) // 2
    hit = {i - first for i in hit if i >= first}
    sent = sent[first:]
    want = [f for i, f in enumerate(sent) if i not in hit]
    assert [key(f) for f in got] == [key(f) for f in want]
    last_hit = sum(1 for i in hit if i > max(i for i in range(len(sent)) if i not in hit))
    assert counters.frames_lost == len(hit) - last_hit
    assert counters.crc_failures + counters.header_rejects > 0

    live = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    lost_events = [m for t, _, m in live if t == "/cm/events" and m["kind"] == "frames_lost"]
    assert sum(m["count"] for m in lost_events) == counters.frames_lost

    r = cmsensord("replay", str(tmp_path / "cap.bin"), "--out", str(tmp_path / "replay"))
    assert r.returncode == 0, r.stderr
    replayed = read_messages(next((tmp_path / "replay").glob("*.mcap")))
    assert comparable(live) == comparable(replayed)


def test_unplugged_board_is_link_lost_then_restored_and_monitoring_goes_on(tmp_path):
    """The board goes away (its pty is closed and its device name removed), comes back 3 s
    later on a new pty under the same name: link_lost, link_restored within 5 s of the
    return, the daemon never stops and monitors the second board."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--speed", "5", "--link", str(link), "--flow-control")
    d = start_daemon(tmp_path, link)
    time.sleep(3.0)
    sim.terminate()                     # unplugged
    sim.wait(timeout=5)
    assert not link.exists()
    time.sleep(3.0)
    assert d.poll() is None             # still running, waiting for the port
    back = time.monotonic()
    sim = start_board("--scenario", "healthy", "--speed", "5", "--link", str(link), "--seed", "1",
                      "--flow-control")
    restored_after, err = _seconds_until_logged(d, "link_restored", back, 8.0)
    time.sleep(max(0.0, back + 5.0 - time.monotonic()))
    err += stop(d)
    sim.terminate()
    sim.wait(timeout=5)
    assert d.returncode == 0, err
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    events = [(s, m) for t, s, m in msgs if t == "/cm/events"]
    kinds = [m["kind"] for _, m in events]
    assert "link_lost" in kinds and "link_restored" in kinds
    assert kinds.index("link_lost") < kinds.index("link_restored")
    # seen on stderr within 5 s of the replug (the MCAP stamp is no wall clock here: the board
    # at 5x puts the stream ahead of it, and an event is never stamped before what precedes it)
    assert restored_after is not None and restored_after < 5.0, err
    # the second board's data was processed after the gap
    sev = [s for t, s, _ in msgs if t == "/cm/ch0/severity"]
    assert len(sev) >= 8


def test_a_second_daemon_on_the_same_configuration_is_refused_and_the_first_loses_nothing(tmp_path):
    """Started by hand beside the service: one line, exit 78, and the first daemon runs on without
    a lost frame (guards against both reading the port, each losing the other's frames, and the
    second salvaging the first's open .part file). A replay into its directory (its logs, queue and
    state) is refused the same way; elsewhere it runs."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--speed", "2", "--link", str(link), "--flow-control")
    first = start_daemon(tmp_path, link)
    try:
        time.sleep(3.0)
        second = spawn([sys.executable, "-m", "cmsensord", "--config", str(tmp_path / "cmsensord.yaml")],
                       stderr=subprocess.PIPE, text=True)
        _, err2 = second.communicate(timeout=60)
        cap, cfg = str(tmp_path / "cap.bin"), str(tmp_path / "cmsensord.yaml")
        assert subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "healthy", "--duration", "3",
                               "--out", cap], capture_output=True, env=ENV).returncode == 0
        replay = cmsensord("replay", cap, "--config", cfg)            # no --out: the daemon's directory
        elsewhere = cmsensord("replay", cap, "--config", cfg, "--out", str(tmp_path / "replay"))
        time.sleep(2.0)
        assert first.poll() is None
    finally:
        err1 = stop(first)
        sim.terminate()
        sim.wait(timeout=5)
    assert (second.returncode, err2.strip().splitlines()[-1]) == (78, (
        f"cmsensord: {tmp_path / 'logs'}: another cmsensord (pid {first.pid}) writes its logs here; stop it first "
        "(systemctl stop cmsensord), or give this one another output.dir"))
    assert (replay.returncode, replay.stderr.strip().splitlines()[-1]) == (78, (
        f"cmsensord: {tmp_path / 'logs'}: the running cmsensord (pid {first.pid}) writes its logs here; give "
        "replay another directory (--out DIR)")), replay.stderr
    assert elsewhere.returncode == 0, elsewhere.stderr
    assert first.returncode == 0, err1
    (log,) = (tmp_path / "logs").glob("*.mcap")
    kinds = [m["kind"] for t, _, m in read_messages(log) if t == "/cm/events"]
    assert "frames_lost" not in kinds and "salvage" not in " ".join(kinds), kinds


def test_a_port_that_is_not_there_is_said_on_every_status_line(tmp_path):
    """No board on the port: besides the one link_lost event, each status line says what the
    daemon is waiting for (a line of zero counters alone looked like a board sending nothing)."""
    port = tmp_path / "ttyNONE"
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"link:\n  port: {port}\noutput:\n  dir: {tmp_path / 'logs'}\n")
    d = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE, text=True)
    time.sleep(5.0)                              # two status lines, on a loaded machine too
    err = stop(d)
    assert d.returncode == 0, err
    status = [line for line in err.splitlines() if line.startswith("[")]
    assert len(status) >= 2, err
    assert all(line.endswith(f"| {port}: no such device (is the board plugged in? check `ls /dev/tty*`); retrying")
               for line in status), status


def test_a_stalled_link_reports_the_last_partial_interval_at_once(tmp_path):
    """The board stops sending mid-interval and stays connected: at link_stalled the daemon
    writes the open indicator interval (partial) and the ones waiting for the tacho, so they
    are on disk before any stop (the daemon is then killed with SIGKILL, which finishes nothing).
    The board starts once the daemon has the port open: the intervals count from the first
    sample the daemon sees, and with a board already sending, a daemon that opened the port
    at 0.5 s (of 3.5) would have seen the data end with an interval (complete)."""
    sim = spawn([sys.executable, "-m", "firmware_sim", "--pty", "--hold", "--start-on-stdin",
                            "--scenario", "healthy", "--mode", "raw", "--tacho", "--duration", "3.5"],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=ENV)
    try:
        port = sim.stdout.readline().strip()
        d = start_daemon(tmp_path, port)
        assert _opened(d, port, 30.0), "the daemon did not open the port"
        time.sleep(0.2)                          # pyserial discards what waits at its open
        sim.stdin.write("\n")
        sim.stdin.flush()
        stalled, err = _seconds_until_logged(d, "link_stalled", time.monotonic(), 30.0)
        time.sleep(2.0)                          # the sink's flush (flush_s: 1 s)
        d.send_signal(signal.SIGKILL)
        d.wait(timeout=10)
    finally:
        sim.terminate()
        sim.wait(timeout=5)
    assert stalled is not None, err
    recs = [m for t, _, m in read_messages(next((tmp_path / "logs").glob("*.mcap.part")), lenient=True)
            if t == "/cm/ch0/indicators"]
    assert len(recs) >= 3, recs
    assert all(r["missing_fraction"] == 0 and r["speed_source"] == "tacho" for r in recs[1:-1]), recs
    last = recs[-1]
    assert 0 < last["missing_fraction"] < 1 and last["speed_source"] == "tacho", last


def _opened(d: subprocess.Popen, port: str, timeout: float) -> bool:
    """Whether process ``d`` has ``port`` open within ``timeout`` seconds."""
    real, end = os.path.realpath(port), time.monotonic() + timeout
    while time.monotonic() < end and d.poll() is None:
        try:
            fds = os.listdir(f"/proc/{d.pid}/fd")
        except OSError:
            fds = []
        for fd in fds:
            try:
                if os.readlink(f"/proc/{d.pid}/fd/{fd}") == real:
                    return True
            except OSError:
                continue
        time.sleep(0.02)
    return False


def test_the_partial_interval_is_in_the_file_when_link_stalled_is_logged(tmp_path):
    """The loop notices the stall (_Watch.done): the open indicator interval (partial) is in the
    file before the link_stalled event and its journal line are written, so a daemon killed as
    soon as the line appears has it.  Checked at the moment the line is logged."""
    import logging
    import threading
    from types import SimpleNamespace

    from cmsensord.monitor.processor import Processor
    from cmsensord.service.live import _Watch
    from cmsensord.service.sink import open_sink

    cfg = config_from_dict({"output": {"dir": str(tmp_path / "logs")}})
    sc = make_scenario("healthy", n_channels=1, duration_s=3.5, seed=0)
    frames, _ = iter_frames(Board(sc, BoardConfig(n_channels=1, mode="rms")).generate(3.5))
    sink = open_sink(cfg, {})
    proc = Processor(cfg, sink)
    proc.handle(frames)                             # the board stops 0.5 s into an interval
    reader = SimpleNamespace(connected=threading.Event())
    reader.connected.set()
    source = SimpleNamespace(reader=reader, last_bytes=time.monotonic() - 5.0)
    seen: list[list[dict]] = []

    class AtTheLine(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            if "link_stalled" in record.getMessage():
                path = next((tmp_path / "logs").glob("*.mcap.part"))
                seen.append([m for t, _, m in read_messages(path, lenient=True) if t == "/cm/ch0/indicators"])

    handler = AtTheLine()
    logging.getLogger("cmsensord").addHandler(handler)
    try:
        assert _Watch(cfg, proc, source, None, None).done(False, time.monotonic()) is False
    finally:
        logging.getLogger("cmsensord").removeHandler(handler)
        proc.finish()
        sink.close()
    assert len(seen) == 1 and len(seen[0]) >= 3, seen
    assert 0 < seen[0][-1]["missing_fraction"] < 1, seen[0][-1]
    assert all(r["missing_fraction"] == 0 for r in seen[0][1:-1]), seen[0]


def _seconds_until_logged(d: subprocess.Popen, text: str, since: float,
                          timeout: float) -> tuple[float | None, str]:
    """Seconds from ``since`` (monotonic) until ``text`` appears on the daemon's stderr (None:
    not within ``timeout``), and the stderr read meanwhile."""
    fd = d.stderr.fileno()
    os.set_blocking(fd, False)
    seen = b""
    try:
        while time.monotonic() - since < timeout:
            seen += drain(fd)
            if text.encode() in seen:
                return time.monotonic() - since, seen.decode()
            time.sleep(0.05)
        return None, seen.decode()
    finally:
        os.set_blocking(fd, True)


@pytest.mark.parametrize("mode", ["rms", "raw"])
def test_t0_wrapping_past_2_32_changes_nothing_downstream(mode):
    """The same board run with its sample counter starting 1 s before 2^32 and from 0:
    identical messages (stamps are relative to the first frame)."""
    seconds = 20.0 if mode == "rms" else 3.0
    kw = dict(n_channels=1, mode=mode, tacho=(mode == "raw"))
    sc = make_scenario("close_orders" if mode == "raw" else "faulty", n_channels=1,
                       duration_s=seconds, seed=0)
    runs = []
    for t0_start in (0, 2**32 - 25000):
        data = Board(sc, BoardConfig(t0_start=t0_start, **kw)).generate(seconds)
        cfg = config_from_dict({"orders": {"max_rpm": 3000.0}}) if mode == "raw" else config_from_dict({})
        sink, _, dec = run_processor(data, cfg)
        assert dec.counters.frames_lost == 0
        runs.append([(t, s, {k: v for k, v in m.items() if k != "timestamp"})
                     for t, s, m in sink.messages if t != "/cm/diagnostics"])
    topics = {t for t, _, _ in runs[0]}
    assert "/cm/ch0/severity" in topics and len(runs[0]) > 20
    assert mode == "rms" or "/cm/ch0/orders" in topics
    assert runs[0] == runs[1]


def test_a_silent_link_is_a_stall_event_and_the_daemon_waits(tmp_path):
    """The board stops sending but keeps the port open (--hold): link_stalled after 2 s."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--duration", "3", "--speed", "1", "--link", str(link))
    d = start_daemon(tmp_path, link)
    json.loads(sim.stdout.readline())                   # the board has sent its 3 s
    quiet_from = time.time()
    time.sleep(3.5)
    assert d.poll() is None
    err = stop(d)
    sim.terminate()
    sim.wait(timeout=5)
    assert d.returncode == 0, err
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    stalls = [(s, m) for t, s, m in msgs if t == "/cm/events" and m["kind"] == "link_stalled"]
    assert len(stalls) == 1
    assert 1.5 < stalls[0][0] / 1e9 - quiet_from < 3.5      # 2 s after the last byte
    assert "no bytes for 2 s" in stalls[0][1]["message"]


def test_a_throttled_loop_sheds_raw_blocks_and_keeps_the_tacho(tmp_path):
    """The real daemon's loop is stalled for a few seconds (its stderr, the "journal", is a
    full pipe: the next status line blocks) while the board streams 2 RAW channels and a
    tacho into a queue of 512 frames: queue_overflow events, only RAW frames shed, the
    daemon goes on with orders and severity after the stall."""
    import fcntl
    import os

    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--mode", "raw", "--tacho", "--channels", "2",
                      "--speed", "1", "--link", str(link))
    r, w = os.pipe()
    w_test = os.open(f"/proc/self/fd/{w}", os.O_WRONLY | os.O_NONBLOCK)
    fcntl.fcntl(r, fcntl.F_SETFL, fcntl.fcntl(r, fcntl.F_GETFL) | os.O_NONBLOCK)
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {link}\n  queue_frames: 512\n"
                   f"output:\n  dir: {tmp_path / 'logs'}\n  status_line: true\n")
    d = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)],
                         stderr=w, env=ENV)
    os.close(w)
    try:
        time.sleep(3.0)                 # running
        drain(r)
        fill(w_test)                    # the loop blocks at its next status line (< 1 s)
        time.sleep(4.0)
        drain(r)                        # the journal reads again: the loop goes on
        time.sleep(0.3)
        drain(r)
        time.sleep(3.0)
        d.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 10
        while d.poll() is None and time.monotonic() < deadline:
            drain(r)
            time.sleep(0.05)
    finally:
        if d.poll() is None:
            d.kill()
        sim.terminate()
        sim.wait(timeout=5)
        os.close(w_test)
        os.close(r)
    assert d.returncode == 0
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    over = [(s, m) for t, s, m in msgs if t == "/cm/events" and m["kind"] == "queue_overflow"]
    assert over, "no queue_overflow event"
    shed = sum(m["count"] for _, m in over)
    assert shed > 100 and over[-1][1]["raw_total"] == shed          # RAW frames only
    kinds = {m["kind"] for t, _, m in msgs if t == "/cm/events"}
    assert "tacho_lost" not in kinds                                 # every TACHO frame kept
    t_over = over[-1][0]
    after = [m for t, s, m in msgs if t == "/cm/ch0/orders" and s > t_over + 1e9 and m["valid"]]
    assert len(after) >= 10
    assert any(t == "/cm/ch1/severity" and s > t_over + 1e9 for t, s, _ in msgs)
