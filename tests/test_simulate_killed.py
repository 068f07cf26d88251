"""``cmsensord --simulate`` killed with SIGKILL (it finishes nothing) leaves no simulated board
behind: the simulator notices its parent has gone and ends, pty and all."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from processes import ENV, spawn


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_a_killed_simulate_leaves_no_board_running(tmp_path):
    d = spawn([sys.executable, "-m", "cmsensord", "--simulate", "--duration", "400", "--speed", "20",
               "--out", str(tmp_path / "logs")], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL,
              text=True, env=ENV)
    deadline = time.monotonic() + 30
    sims: list[int] = []
    while not sims and time.monotonic() < deadline:
        time.sleep(0.2)
        sims = [p for p in _children(d.pid) if "firmware_sim" in Path(f"/proc/{p}/cmdline").read_text()]
    assert sims, "no simulator started"
    time.sleep(1.0)
    os.kill(d.pid, signal.SIGKILL)
    d.wait(timeout=10)
    deadline = time.monotonic() + 5
    while _alive(sims[0]) and time.monotonic() < deadline:
        time.sleep(0.1)
    try:
        assert not _alive(sims[0]), "the simulator outlived the killed daemon"
    finally:
        if _alive(sims[0]):
            os.kill(sims[0], signal.SIGKILL)
