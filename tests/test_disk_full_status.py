"""The daemon on a full disk says so where an operator looks: the status line names the outage,
and a capture that went to no file is not logged as captured. (A capture taken into a new
file that the retry opened, whose chunk then fails, is in the outage's count of lost messages.)"""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from processes import ENV, spawn, stop
from test_disk_full import daemon_filling, fill


@pytest.mark.slow
def test_full_disk_on_the_status_line_and_captures_not_written_are_said(small_fs, tmp_path):
    err = daemon_filling(small_fs, tmp_path, "output:\n  retry_s: 1.0\n  retain_mb: 0\n  min_free_mb: 0\n"
                         "  akf_trace: true\ncapture:\n  every_s: 3\n  pre_s: 1\n  post_s: 1\n"
                         "  min_interval_s: 0\n", settle_s=2.0, full_s=5.0)   # 25 s of board time full
    lines = err.splitlines()
    start = next(i for i, ln in enumerate(lines) if "disk_error" in ln and "No space left" in ln)
    end = next(i for i, ln in enumerate(lines) if "logging resumed" in ln)
    outage = lines[start:end]
    assert any("| disk: not logging for " in ln and "No space left on device" in ln
               and "message(s) dropped" in ln for ln in outage), "\n".join(outage)[-3000:]
    assert any("capture on periodic not written: the log is not being written (disk error)" in ln
               for ln in outage), "\n".join(outage)[-3000:]
    assert not [ln for ln in lines[end + 2:] if "| disk: not logging" in ln]
    assert any(": captured " in ln for ln in lines[:start])


@pytest.mark.slow
def test_the_daemon_starts_on_a_full_disk_and_runs(small_fs, tmp_path):
    """Started on a full disk (the lock file's pid cannot be written there), the daemon runs
    without a file, says why, and stops cleanly (it died with a traceback, a restart loop under
    systemd)."""
    logs = small_fs / "logs"
    logs.mkdir()
    fill(small_fs, leave=0)
    cfg = tmp_path / "c.yaml"
    cfg.write_text("output:\n  retain_mb: 0\n  min_free_mb: 0\n  status_line: false\n")
    d = spawn([sys.executable, "-m", "cmsensord", "--simulate", "--config", str(cfg), "--out", str(logs),
               "--duration", "3600", "--speed", "5"], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL,
              text=True, env=ENV)
    time.sleep(4.0)
    running = d.poll() is None
    err = stop(d)
    assert running and d.returncode == 0 and "Traceback" not in err, err[-3000:]
    assert "ERROR disk_error: " in err and "No space left on device" in err, err[-3000:]


def test_a_capture_stopped_by_a_full_disk_is_said_in_the_summary(small_fs, tmp_path):
    """``--capture`` onto a disk that fills: the capture stops (a disk_error says so) and the
    run's summary says it is not whole (it named the file as if it were)."""
    cap = small_fs / "cap.bin"
    fill(small_fs, leave=8 * 1024)
    p = subprocess.run([sys.executable, "-m", "cmsensord", "--simulate", "--duration", "20", "--speed", "20",
                        "--out", str(tmp_path / "logs"), "--capture", str(cap)],
                       capture_output=True, text=True, env=ENV, timeout=120)
    assert p.returncode == 0, p.stderr[-3000:]
    assert "capture file: No space left on device; capture stopped" in p.stderr, p.stderr[-3000:]
    assert f"  capture: {cap} (stopped: capture file: No space left on device; what came after is not in it)" \
        in p.stderr, p.stderr[-3000:]
