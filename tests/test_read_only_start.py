"""The daemon started while its output directory is on a read-only file system (an SD card the
kernel remounted read-only after errors): it runs, processes and publishes (the MQTT
messages sent from memory), says once that it is not logging, and logs as soon as the file
system is writable again. Exit 78 there kept the service down for good
(``RestartPreventExitStatus=78``). A replay, with a user at the terminal, still stops at once with the one line.

A real tmpfs (``small_fs``) remounted read-only under the daemon, a simulated board on a pty.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from cmsensord.sinks.mcap_sink import log_files, read_messages
from mosquitto import Broker, Subscriber, needs_mosquitto
from processes import ENV, board_on_pty, cmsensord, spawn, stop


def remount(fs: Path, mode: str) -> None:
    subprocess.run(["mount", "-o", f"remount,{mode}", str(fs)], check=True, capture_output=True, timeout=10)


def daemon(tmp_path: Path, port: str, logs: Path, more: str = "") -> subprocess.Popen:
    """``cmsensord --config`` on ``port`` logging to ``logs`` (retry_s 1), as the unit runs it."""
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {port}\n  max_drift_s: 0\noutput:\n  dir: {logs}\n  status_line: false\n"
                   f"  retry_s: 1\n  min_free_mb: 0\n{more}")
    return spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE,
                 stdout=subprocess.DEVNULL, text=True, env=ENV)


@pytest.mark.parametrize("made", [True, False], ids=["directory-there", "directory-missing"])
def test_a_read_only_log_directory_at_start_is_waited_out_not_exit_78(small_fs, tmp_path, made):
    logs = small_fs / "logs"
    if made:
        logs.mkdir()
    remount(small_fs, "ro")
    with board_on_pty("--scenario", "healthy") as port:
        d = daemon(tmp_path, port, logs)
        time.sleep(4.0)
        running = d.poll() is None
        remount(small_fs, "rw")
        time.sleep(4.0)
        err = stop(d)
    assert running and d.returncode == 0, err[-3000:]
    what = "cannot write in output directory" if made else "cannot create output directory"
    lines = err.splitlines()
    assert f"ERROR disk_error: not logging: {logs}: {what}: Read-only file system; retrying every 1 s" in lines, \
        err[-3000:]
    assert any(ln.startswith("INFO disk_error: logging resumed in cmsensord-") for ln in lines), err[-3000:]
    finished, parts = log_files(logs, "cmsensord")
    assert len(finished) == 1 and parts == []
    severity = [m for t, _s, m in read_messages(finished[0]) if t.endswith("/severity")]
    assert len(severity) >= 2                     # decisions went on: those after the remount are logged


def test_a_replay_into_a_read_only_directory_still_stops_with_the_one_line(small_fs, tmp_path):
    (small_fs / "logs").mkdir()
    remount(small_fs, "ro")
    capture = tmp_path / "cap.bin"
    sim = cmsensord("--simulate", "--duration", "3", "--speed", "20", "--out", str(tmp_path / "sim"),
                    "--capture", str(capture))
    assert sim.returncode == 0, sim.stderr[-2000:]
    p = cmsensord("replay", str(capture), "--out", str(small_fs / "logs"))
    assert p.returncode == 78
    assert p.stderr.strip().splitlines()[-1] == (
        f"cmsensord: output error: {small_fs / 'logs'}: cannot write in output directory: Read-only file "
        "system (set output.dir or --out to a writable directory)")


@needs_mosquitto
def test_on_a_read_only_log_directory_the_decisions_are_published_from_memory_and_queued_once_writable(
        small_fs, tmp_path):
    """The MQTT queue lives in the output directory, which cannot take it: the messages are held
    in memory and sent from there (an alarm reaches the broker when the SD card fails), and go
    into the queue, in order, once the directory is writable."""
    logs = small_fs / "logs"
    remount(small_fs, "ro")
    broker = Broker(tmp_path / "broker").start()
    sub = Subscriber(broker.port, "cmsensord/rig1/#")
    try:
        with board_on_pty("--scenario", "healthy") as port:
            d = daemon(tmp_path, port, logs, f"mqtt:\n  host: 127.0.0.1\n  port: {broker.port}\n  client_id: rig1\n"
                       "  publish: [severity]\n  reconnect_min_s: 0.2\n  resend_per_s: 2000\n")
            while_read_only = sub.wait_for(lambda: len(sub.messages("/severity")) >= 2, timeout=15)
            running = d.poll() is None
            remount(small_fs, "rw")
            queued = _wait_for(lambda: any((logs / "mqtt-queue").glob("q-*.seg")), timeout=10)
            published = sub.wait_for(lambda: len(sub.messages("/severity")) >= 5, timeout=10)
            err = stop(d)
    finally:
        sub.close()
        broker.stop()
    assert running and d.returncode == 0, err[-3000:]
    said = [ln for ln in err.splitlines() if " mqtt_queue: " in ln]      # one of each for the outage
    assert said == [f"ERROR mqtt_queue: store-and-forward queue {logs}/mqtt-queue: cannot write (Read-only file "
                    "system); new messages are sent from memory, up to 4 MB kept until it takes them",
                    "INFO mqtt_queue: store-and-forward queue writable again"], err[-3000:]
    assert while_read_only and queued and published, err[-3000:]
    seqs = [m["seq"] for _, m in sub.messages("/severity")]
    assert seqs == sorted(set(seqs)), seqs                  # each once, in order, across the remount


def _wait_for(test, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if test():
            return True
        time.sleep(0.1)
    return False
