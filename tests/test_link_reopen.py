"""A board that stops sending while its port stays open (a hung USB device): the status line
says the link is stalled and for how long, and the daemon closes the port and opens it again
after ``link.reopen_s`` without a byte, twice as long each time."""

from __future__ import annotations

import subprocess
import sys
import time

from processes import run_module, spawn, start_board, stop


def test_a_silent_open_port_is_said_stalled_and_reopened(tmp_path):
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--duration", "4", "--speed", "2", "--link", str(link))
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {link}\n  max_drift_s: 0\n  stall_s: 1.0\n  reopen_s: 3.0\n"
                   f"output:\n  dir: {tmp_path / 'logs'}\n  status_line: false\n")
    d = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE, text=True)
    try:
        status = ""
        deadline = time.monotonic() + 20             # the board's 2 s of signal, then silence
        while "stalled, no bytes for" not in status and time.monotonic() < deadline:
            time.sleep(0.5)
            status = run_module("cmsensord", "status", "--config", str(cfg)).stdout
        time.sleep(11.0)                             # reopened after 3 s, then after 6 s more
    finally:
        err = stop(d)
        sim.terminate()
        sim.wait(timeout=5)
    assert f"| {link}: stalled, no bytes for " in status, status
    assert d.returncode == 0 and "Traceback" not in err, err
    lost = [ln for ln in err.splitlines() if "link_lost" in ln]
    assert any(ln.endswith(f"WARNING link_lost: {link}: no byte for 3 s on the open port; closing it to "
                           "open it again (a hung USB device or board?)") for ln in lost), err
    assert any("no byte for 6 s on the open port" in ln for ln in lost), err
    assert sum(f"link_restored: {link} open again" in ln for ln in err.splitlines()) >= 2, err
