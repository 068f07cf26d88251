"""The daemon on a full disk says so where an operator looks: the status line names the outage,
and a capture that went to no file is not logged as captured. (A capture taken into a new
file that the retry opened, whose chunk then fails, is in the outage's count of lost messages.)"""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from processes import ENV, spawn
from test_disk_full import fill


@pytest.mark.slow
def test_full_disk_on_the_status_line_and_captures_not_written_are_said(small_fs, tmp_path):
    logs = small_fs / "logs"
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text("output:\n  retry_s: 1.0\n  retain_mb: 0\n  min_free_mb: 0\n  akf_trace: true\n"
                   "capture:\n  every_s: 3\n  pre_s: 1\n  post_s: 1\n  min_interval_s: 0\n")
    d = spawn([sys.executable, "-m", "cmsensord", "--simulate", "--config", str(cfg),
               "--out", str(logs), "--duration", "3600", "--speed", "5"],
              stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=ENV)
    try:
        deadline = time.monotonic() + 30
        while not list(logs.glob("*.part")) and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(2.0)
        filler = fill(small_fs, leave=16 * 1024)
        time.sleep(5.0)                          # 25 s of board time: captures fall due
        filler.unlink()
        time.sleep(3.0)                          # retry_s 1: logging resumes
        d.send_signal(signal.SIGTERM)
        _, err = d.communicate(timeout=20)
    finally:
        if d.poll() is None:
            d.kill()
            d.wait()
    assert d.returncode == 0, err[-2000:]
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
