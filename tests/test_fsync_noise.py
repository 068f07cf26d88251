"""A chronically noisy serial line does not fsync the log at every loop iteration: its routine
events (``frames_lost``, ``decode_error``, ...) ride ``output.fsync_s``; only the events of
:data:`cmsensord.sinks.durable.FSYNC_AT_ONCE` are fsynced at the next tick (an SD card's wear).

The daemon runs under ``strace`` (Debian's strace package; ``.ci/run`` installs it) on a simulated
board at 1x (a real board's pace) with a byte error rate of 1e-3, a few frames lost a second.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cmsensord.sinks.mcap_read import read_messages
from processes import spawn, start_board, stop

STRACE = shutil.which("strace")
pytestmark = pytest.mark.skipif(STRACE is None, reason="strace is not installed (Debian package strace)")
RUN_S = 15.0


def test_a_noisy_line_costs_no_fsync_per_event(tmp_path):
    logs, trace, link = tmp_path / "logs", tmp_path / "strace.txt", tmp_path / "ttyBOARD"
    board = start_board("--scenario", "healthy", "--byte-error-rate", "1e-3", "--link", str(link))
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {link}\n  max_drift_s: 2\noutput:\n  dir: {logs}\n  status_line: false\n"
                   "  fsync_s: 30\n  retain_mb: 0\n  min_free_mb: 0\n")
    tracer = spawn([STRACE, "-f", "-o", str(trace), "-e", "trace=fsync,fdatasync",
                    sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(RUN_S)
        (daemon,) = Path(f"/proc/{tracer.pid}/task/{tracer.pid}/children").read_text().split()
        os.kill(int(daemon), 15)
        err = tracer.communicate(timeout=30)[1]
    finally:
        stop(board)
    assert tracer.returncode == 0, err[-3000:]
    (log,) = logs.glob("cmsensord-*.mcap")
    kinds = [m["kind"] for t, _, m in read_messages(log) if t == "/cm/events"]
    lost = kinds.count("frames_lost")
    assert lost >= 5, kinds                      # the line was noisy: events every few seconds
    fsyncs = [line for line in trace.read_text().splitlines() if "fsync(" in line and "= 0" in line]
    # the directories at start (2), start's event, the file and the directory at the end; nothing per event
    assert len(fsyncs) <= 6, (len(fsyncs), lost, fsyncs)
