"""A board that stops sending while its port stays open (a hung USB device): the status line
says the link is stalled and for how long, and the daemon closes the port and opens it again
after ``link.reopen_s`` without a byte, twice as long each time."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from processes import run_module, spawn, start_board, stop


def test_a_silent_open_port_is_said_stalled_and_reopened(tmp_path):
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--duration", "4", "--speed", "2", "--link", str(link),
                      "--flow-control")                # a daemon slow to start still gets the 2 s
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {link}\n  max_drift_s: 0\n  stall_s: 1.0\n  reopen_s: 3.0\n"
                   f"output:\n  dir: {tmp_path / 'logs'}\n  status_line: false\n")
    d = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE, text=True)
    try:
        status = ""
        deadline = time.monotonic() + 40             # the board's 2 s of signal, then silence
        while "stalled, no bytes for" not in status and time.monotonic() < deadline:
            time.sleep(0.5)
            status = run_module("cmsensord", "status", "--config", str(cfg)).stdout
        time.sleep(12.0)                             # reopened after 3 s, then after 6 s more
    finally:
        err = stop(d)
        sim.terminate()
        sim.wait(timeout=5)
    assert f"| {link}: stalled, no bytes for " in status, status
    assert d.returncode == 0 and "Traceback" not in err, err
    lost = [ln for ln in err.splitlines() if "link_lost:" in ln]
    assert any(ln.endswith(f"WARNING link_lost: {link}: no byte for 3 s on the open port; closing it to "
                           "open it again (a hung USB device or board?)") for ln in lost), err
    assert len(lost) == 1, lost                      # the next reopens of the silence: INFO lines
    assert f"INFO link: {link}: still no byte, 6 s after reopen 1; opening it again" in err, err
    assert "link_restored" not in err, err           # no byte came back


def test_a_port_open_with_never_a_byte_is_a_stall(tmp_path):
    """A board off behind its USB adapter: the port opens, no byte ever comes. A link_stalled
    after 10 s and the status line say so (it showed zero counters only)."""
    master, slave = os.openpty()
    link = tmp_path / "ttySILENT"
    link.symlink_to(os.ttyname(slave))
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {link}\n  reopen_s: 0\noutput:\n  dir: {tmp_path / 'logs'}\n"
                   "  status_line: false\n")
    d = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE, text=True)
    try:
        status, deadline = "", time.monotonic() + 30
        while "stalled" not in status and time.monotonic() < deadline:
            time.sleep(0.5)
            status = run_module("cmsensord", "status", "--config", str(cfg)).stdout
    finally:
        err = stop(d)
        os.close(master)
        os.close(slave)
    assert f"| {link}: stalled, no bytes since the port opened for " in status, status
    assert f"WARNING link_stalled: {link}: open for 10 s and no byte yet (is the board powered and sending? " \
           "the right port?)" in err, err
