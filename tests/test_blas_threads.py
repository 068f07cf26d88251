"""The daemon and the simulated board run with one BLAS thread (cmsensord/blas_threads.py):
started from an environment that bounds no BLAS library, neither process has a thread
besides its own (numpy's and scipy's OpenBLAS each start a worker per further core at import,
and spin them after every product they split)."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from cmsensord.blas_threads import LIMITS
from processes import ENV, spawn, start_daemon, stop

#: the environment of a user who set none of the limits
BARE = {k: v for k, v in ENV.items() if k not in LIMITS}

pytestmark = [pytest.mark.process,
              pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core: BLAS starts no worker")]


def threads(pid: int) -> int:
    """The process's threads (Python's and native ones)."""
    return len(os.listdir(f"/proc/{pid}/task"))


def settled_threads(pid: int, least: int, timeout: float = 20.0) -> int:
    """The process's threads once at least ``least`` run and a further second has passed."""
    end = time.monotonic() + timeout
    while threads(pid) < least and time.monotonic() < end:
        time.sleep(0.05)
    time.sleep(1.0)
    return threads(pid)


def test_board_and_daemon_run_no_blas_workers(tmp_path, monkeypatch):
    monkeypatch.setattr("processes.ENV", BARE)      # start_daemon's environment too
    sim = spawn([sys.executable, "-m", "firmware_sim", "--pty", "--hold", "--speed", "1", "--seed", "1",
                 "--scenario", "faulty", "--mode", "raw", "--tacho", "--channels", "1"],
                stdout=subprocess.PIPE, text=True, env=BARE)
    try:
        assert sim.stdout is not None
        port = sim.stdout.readline().strip()
        daemon = start_daemon(tmp_path, port)
        try:
            # the daemon: its loop, the serial reader, the control socket
            assert settled_threads(daemon.pid, 3) == 3
            # the board: its main thread, the one waiting for signals, the one watching its parent
            assert settled_threads(sim.pid, 3) == 3
        finally:
            err = stop(daemon)
        assert daemon.returncode == 0, err
    finally:
        sim.terminate()
        sim.wait(timeout=10)
