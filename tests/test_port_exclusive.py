"""One reader per serial port: the daemon, ``cmsensord record`` and ``--simulate`` open a port
exclusively, so a second cmsensord on it is refused, with one line naming the holder, instead of
both reading half the stream; and ``record`` counts the frames lost in seq gaps.

Real processes on a pty: firmware_sim's board, ``python -m cmsensord``; nothing is mocked.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from cmsensord.protocol import OVERHEAD, iter_frames
from firmware_sim.board import Board, BoardConfig
from firmware_sim.faults import frames_hit, read_records
from firmware_sim.scenarios import make_scenario
from processes import ENV, cmsensord, spawn, start_board, start_daemon, stop

PYTHON = Path(sys.executable).name
TWO_READERS = "two readers of one port each lose the frames the other reads"
RECORD_HINT = ("stop it first, or, if it is the daemon, use its captures (`cmsensord capture-now`, "
               "or its --capture FILE for the port's bytes)")


def shown(*argv) -> str:
    """A holder's command line as the refusal shows it (80 characters at most)."""
    text = " ".join([PYTHON, *map(str, argv)])
    return text if len(text) <= 80 else text[:77] + "..."


def last_line(cap: Path) -> str:
    """The last line ``record`` prints for the capture ``cap``, by decoding the file."""
    _, c = iter_frames(cap.read_bytes())
    return (f"capture: {cap} ({c.bytes_received} B, {sum(c.frames.values())} frames, crc errors "
            f"{c.crc_failures}, {c.frames_lost} frames lost (seq gaps))")


def start_record(port, out, duration) -> tuple[subprocess.Popen, str]:
    """``cmsensord record`` on ``port``, returned once its first status line is out (it holds
    the port), with that line."""
    rec = spawn([sys.executable, "-m", "cmsensord", "record", "--port", str(port), "--out", str(out),
                 "--duration", str(duration)], stderr=subprocess.PIPE, text=True)
    line = rec.stderr.readline()
    assert line.startswith("recorded "), line
    return rec, line.rstrip("\n")


def read_until(proc: subprocess.Popen, text: str, timeout: float = 30.0) -> str:
    """The lines ``proc`` writes to its stderr up to the first holding ``text`` (or its end: it
    is stopped after ``timeout`` seconds without one)."""
    out = ""
    timer = threading.Timer(timeout, proc.terminate)
    timer.start()
    try:
        while text not in out:
            line = proc.stderr.readline()
            if not line:
                break
            out += line
    finally:
        timer.cancel()
    return out


def test_record_on_the_port_the_daemon_reads_is_refused_and_the_daemon_loses_nothing(tmp_path):
    """The newcomer's ``record`` beside the running daemon: refused with one line naming the
    daemon, nothing written; the refused open costs the daemon no frame."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--speed", "10", "--link", str(link), "--flow-control")
    d = start_daemon(tmp_path, link)
    try:
        deadline = time.monotonic() + 30
        while not list((tmp_path / "logs").glob("*.part")) and time.monotonic() < deadline:
            time.sleep(0.1)                     # the daemon reads the port
        r = cmsensord("record", "--port", str(link), "--out", str(tmp_path / "cap.bin"), "--duration", "2")
        time.sleep(1.0)
    finally:
        err = stop(d)
        sim.terminate()
        sim.wait(timeout=5)
    holder = shown("-m", "cmsensord", "--config", tmp_path / "cmsensord.yaml")
    assert r.returncode == 2, r.stderr
    assert r.stderr.splitlines() == [
        f"cmsensord: {link}: held by another process (pid {d.pid}: {holder}): {TWO_READERS}; {RECORD_HINT}"]
    assert not (tmp_path / "cap.bin").exists()
    assert d.returncode == 0 and "Traceback" not in err, err
    assert "frames_lost" not in err and "link_lost" not in err, err


def test_a_record_holding_the_port_keeps_out_a_second_record_and_the_daemon_until_it_ends(tmp_path):
    """The second ``record`` is refused; a daemon started meanwhile waits for the port as for an
    unplugged board (``link_lost`` naming the holder, retried with the back-off) and reads it once
    the ``record`` has ended; the first ``record`` lost no frame."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--speed", "10", "--link", str(link), "--flow-control")
    first = tmp_path / "first.bin"
    try:
        rec, _ = start_record(link, first, 30)
        second = cmsensord("record", "--port", str(link), "--out", str(tmp_path / "second.bin"),
                           "--duration", "1")
        d = start_daemon(tmp_path, link)
        seen = read_until(d, "link_lost:")         # the daemon waits for the port
        rec.send_signal(signal.SIGTERM)
        _, rec_err = rec.communicate(timeout=10)
        seen += read_until(d, "link_restored:")     # and reads it once the record has ended
        err = seen + stop(d)
    finally:
        sim.terminate()
        sim.wait(timeout=5)
    holder = shown("-m", "cmsensord", "record", "--port", link, "--out", first, "--duration", "30")
    assert second.returncode == 2, second.stderr
    assert second.stderr.splitlines() == [
        f"cmsensord: {link}: held by another process (pid {rec.pid}: {holder}): {TWO_READERS}; {RECORD_HINT}"]
    assert rec.returncode == 0, rec_err
    assert rec_err.splitlines()[-1] == last_line(first)
    assert last_line(first).endswith(", 0 frames lost (seq gaps))")
    assert d.returncode == 0 and "Traceback" not in err, err
    lost = [ln for ln in err.splitlines() if "link_lost:" in ln]
    assert len(lost) == 1 and lost[0].endswith(
        f"WARNING link_lost: {link}: held by another process (pid {rec.pid}: {holder}): {TWO_READERS}; "
        "retrying"), err
    assert f"link_restored: {link} open again" in err, err
    assert "frames_lost" not in err, err


def test_record_counts_the_frames_lost_in_seq_gaps(tmp_path):
    """Line noise (firmware_sim --byte-error-rate) loses the frames it hits: each status line and
    the last one count them, as many as the faults hit between the first and last frame read."""
    faults = tmp_path / "faults.jsonl"
    sim = spawn([sys.executable, "-m", "firmware_sim", "--pty", "--hold", "--scenario", "healthy",
                 "--channels", "2", "--duration", "10", "--speed", "20", "--seed", "3",
                 "--byte-error-rate", "1e-3", "--faults-out", str(faults), "--flow-control",
                 "--start-on-stdin"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=ENV)
    cap = tmp_path / "cap.bin"
    try:
        rec, status = start_record(sim.stdout.readline().strip(), cap, 30)
        sim.stdin.close()                       # the board starts sending: record reads from its start
        json.loads(sim.stdout.readline())       # it has sent everything
        time.sleep(0.5)
        rec.send_signal(signal.SIGTERM)
        _, err = rec.communicate(timeout=10)
    finally:
        sim.terminate()
        sim.wait(timeout=5)
    assert rec.returncode == 0, err

    board = Board(make_scenario("healthy", n_channels=2, duration_s=10.0, seed=3), BoardConfig(n_channels=2))
    sent, _ = iter_frames(b"".join(data for data, _ in board.iter_blocks(board.n_blocks_for(10.0))))
    hit = frames_hit([(f.offset, f.offset + OVERHEAD + len(f.payload)) for f in sent], read_records(faults))
    good = [i for i in range(len(sent)) if i not in hit]
    lost = sum(1 for i in hit if good[0] < i < good[-1])
    assert lost > 10
    assert err.splitlines()[-1] == last_line(cap) + (
        "; incomplete: frames the board sent are missing (another program reading the port, or a link "
        "losing bytes?)")
    assert last_line(cap).endswith(f", {lost} frames lost (seq gaps))")
    assert status == "recorded 0 B, 0 frames, crc errors 0, 0 frames lost (seq gaps)"   # before the stream
