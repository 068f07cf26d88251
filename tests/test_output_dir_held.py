"""The output directory stays held by the process writing into it, through the commands a
user types: a replay holds its lock while it writes (a daemon started meanwhile is refused, as
beside another daemon)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

from processes import run_module, spawn, stop


def refusal(logs: Path, pid: int) -> str:
    return (f"cmsensord: {logs}: another cmsensord (pid {pid}) writes its logs here; stop it first "
            "(systemctl stop cmsensord), or give this one another output.dir")


def second_daemon(cfg: Path) -> tuple[int | None, str]:
    """``cmsensord --config cfg`` beside the first: (its exit status, its last stderr line);
    (None, "still running") when it was not refused within 20 s (then stopped)."""
    p = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE, text=True)
    try:
        _, err = p.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        stop(p)
        return None, "still running"
    return p.returncode, err.strip().splitlines()[-1]


def test_a_replay_holds_the_directory_a_daemon_started_meanwhile_is_refused(tmp_path):
    """Before, the replay only checked the lock: a daemon started on the service's configuration
    while the replay wrote there ran beside it, both writing into the directory. Once the
    replay has ended the directory is free again."""
    logs, cfg, cap = tmp_path / "logs", tmp_path / "c.yaml", tmp_path / "cap.bin"
    cfg.write_text(f"link:\n  port: {tmp_path / 'ttyNONE'}\noutput:\n  dir: {logs}\n  status_line: false\n")
    assert run_module("firmware_sim", "--scenario", "healthy", "--duration", "60", "--out", str(cap)).returncode == 0
    replay = spawn([sys.executable, "-m", "cmsensord", "replay", str(cap), "--config", str(cfg), "--realtime"],
                   stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + 20
        while not list(logs.glob("*.mcap.part")) and time.monotonic() < end:
            time.sleep(0.1)                         # the replay writes
        status, line = second_daemon(cfg)
        assert replay.poll() is None                # still replaying
    finally:
        replay.send_signal(signal.SIGINT)
        replay.communicate(timeout=30)
    assert (status, line) == (78, refusal(logs, replay.pid))
    assert replay.returncode == 130
    after = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE, text=True)
    time.sleep(3.0)
    assert after.poll() is None                     # the replay let the lock go: this one runs
    err = stop(after)
    assert after.returncode == 0, err
