"""SIGHUP while the daemon starts (``systemctl reload``, a log rotation tool's postrotate): from
the entry point's first line it is a reopen of the logs, not the end of the process, which
systemd's ``Restart=on-failure`` would not restart (a clean signal)."""

from __future__ import annotations

import re
import signal
import time

import pytest

from processes import board_on_pty, start_daemon, stop

pytestmark = pytest.mark.process

#: a SIGHUP this long after the start at the latest (the daemon's loop takes SIGHUP ~0.3 s in)
LATEST_S = 0.15


def _catches_sighup(pid: int) -> bool:
    """Whether process ``pid`` has a handler for SIGHUP (its SigCgt mask in /proc)."""
    with open(f"/proc/{pid}/status") as f:
        mask = next(line.split()[1] for line in f if line.startswith("SigCgt:"))
    return bool(int(mask, 16) >> (signal.SIGHUP - 1) & 1)


def test_a_sighup_in_the_daemons_first_moments_is_a_reopen_not_its_end(tmp_path):
    """SIGHUP 0.02 s to 0.3 s after the daemon's process started, before and after its loop takes
    SIGHUP (~0.3 s in): it runs on, exits 0 on SIGTERM, and reopened its log once.  The first
    ~0.015 s are the interpreter's own start, before any of the daemon's code runs: a SIGHUP
    due then waits until the process catches SIGHUP, or ``LATEST_S``.  Guards against the
    default action of SIGHUP ending the daemon (exit status -1) in its first ~0.3 s."""
    with board_on_pty("--scenario", "healthy") as port:
        for k, delay in enumerate((0.02, 0.02, 0.02, 0.05, 0.1, 0.3)):
            (tmp_path / str(k)).mkdir()
            d = start_daemon(tmp_path / str(k), port)
            start = time.monotonic()
            time.sleep(delay)
            while not _catches_sighup(d.pid) and time.monotonic() - start < LATEST_S:
                time.sleep(0.001)
            d.send_signal(signal.SIGHUP)
            sent = time.monotonic() - start
            time.sleep(1.5)
            alive = d.poll() is None
            err = stop(d) if alive else d.communicate()[1]
            assert alive and d.returncode == 0 and "Traceback" not in err, (delay, sent, d.returncode, err)
            reopens = [line for line in err.splitlines() if line.startswith("INFO reopen:")]
            assert len(reopens) == 1 and re.fullmatch(r"INFO reopen: finished \S+\.mcap, now writing \S+\.mcap",
                                                      reopens[0]), (delay, err)
