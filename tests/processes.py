"""Helpers for tests that run the daemon and the simulated board as real processes, and
read what they write into pipes.

The environment puts this checkout first on PYTHONPATH, so ``python -m cmsensord``
and ``python -m firmware_sim`` run the code under test.  Tests using these helpers
start processes or ptys: tests/conftest.py marks them ``process``.
"""

from __future__ import annotations

import contextlib
import json
import os
import pty
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))

#: the boards and daemons start_board and start_daemon started (conftest stops what a test left)
STARTED: list[subprocess.Popen] = []


def stop_left_running() -> list[str]:
    """Kill every process of STARTED still running (a test that failed before stopping its
    daemon or board, whose daemon would otherwise reopen its pty's number and steal bytes from
    a later test's pty); their command lines."""
    left = []
    while STARTED:
        proc = STARTED.pop()
        if proc.poll() is None:
            left.append(" ".join(map(str, proc.args)))
            proc.kill()
            proc.communicate()
    return left


def spawn(args, **kw) -> subprocess.Popen:
    """``subprocess.Popen(args, **kw)`` (``env``: default ENV), kept in STARTED: a test that fails
    before stopping it leaves it to conftest to stop, not running on into later tests."""
    proc = subprocess.Popen(args, **{"env": ENV, **kw})
    STARTED.append(proc)
    return proc


def cmsensord(*args, timeout=120, env=None, **kw) -> subprocess.CompletedProcess:
    """Run ``python -m cmsensord ARGS`` to completion, output captured as text (``env``: the
    environment, default ENV)."""
    return subprocess.run([sys.executable, "-m", "cmsensord", *args], capture_output=True, text=True,
                          env=ENV if env is None else env, timeout=timeout, **kw)


def run_module(module: str, *args, timeout=120) -> subprocess.CompletedProcess:
    """``python -m MODULE ARGS`` as a user types it (text output captured)."""
    return subprocess.run([sys.executable, "-m", module, *args], capture_output=True, text=True,
                          env=ENV, timeout=timeout)


@contextlib.contextmanager
def board_on_pty(*args):
    """A simulated board serving a pty (``python -m firmware_sim --pty --hold ARGS``): its path."""
    sim = spawn([sys.executable, "-m", "firmware_sim", "--pty", "--hold", *args], stdout=subprocess.PIPE, text=True)
    try:
        yield sim.stdout.readline().strip()
    finally:
        sim.terminate()
        try:
            sim.wait(timeout=5)
        except subprocess.TimeoutExpired:   # fail, but leave no board running
            sim.kill()
            sim.wait()
            raise


def start_board(*args) -> subprocess.Popen:
    """``python -m firmware_sim --pty --hold ARGS``, returned once the pty is up; the caller stops it."""
    sim = spawn([sys.executable, "-m", "firmware_sim", "--pty", "--hold", *args], stdout=subprocess.PIPE, text=True)
    sim.stdout.readline()                      # the pty's path: the board is up
    return sim


def start_daemon(tmp_path, port, *extra, config="", max_drift_s=0.0) -> subprocess.Popen:
    """``cmsensord --config`` on ``port``, logs in tmp_path/logs; ``config``: more YAML.
    ``max_drift_s``: 0 by default, as the simulated boards run faster than real time."""
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {port}\n  reconnect_min_s: 0.5\n  reconnect_max_s: 5.0\n"
                   f"  max_drift_s: {max_drift_s}\n"
                   f"output:\n  dir: {tmp_path / 'logs'}\n  status_line: false\n{config}")
    return spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg), *extra],
                 stderr=subprocess.PIPE, text=True)


def daemon_on_short_board(tmp_path, *extra, config: str = "",
                          board: tuple[str, ...] = ("--duration", "3")) -> tuple[subprocess.Popen, str]:
    """A healthy board (``board``: firmware_sim's arguments, default 3 s at 1x; flow control; it
    holds its pty after) and the daemon on it (``extra`` arguments, ``config`` as for
    :func:`start_daemon`), stopped a second after the board has sent everything: the daemon
    (exited 0, no traceback) and its stderr."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", *board, "--link", str(link), "--flow-control")
    d = start_daemon(tmp_path, link, *extra, config=config)
    json.loads(sim.stdout.readline())                # the board has sent everything
    time.sleep(1.0)
    err = stop(d)
    sim.terminate()
    sim.wait(timeout=5)
    assert d.returncode == 0 and "Traceback" not in err, err
    return d, err


def board_then_daemon(tmp_path, *board_args, config: str = "") -> dict:
    """firmware_sim on a pty (``board_args``; published at tmp_path/ttyBOARD, with flow control,
    so a daemon slow to start loses no byte) and the daemon on it, its bytes captured to
    tmp_path/cap.bin, until the board has sent everything: the board's stats.  ``config``: more
    YAML for the daemon.  The daemon exited 0 without a traceback."""
    link = tmp_path / "ttyBOARD"
    sim = start_board(*board_args, "--link", str(link), "--flow-control")
    d = start_daemon(tmp_path, link, "--capture", str(tmp_path / "cap.bin"), config=config)
    stats = json.loads(sim.stdout.readline())["stats"]          # the board has sent everything
    time.sleep(1.5)
    err = stop(d)
    sim.terminate()
    sim.wait(timeout=5)
    assert d.returncode == 0, err
    assert "Traceback" not in err
    return stats


def stop(proc, timeout=10) -> str:
    """SIGTERM ``proc`` and wait for it: its stderr."""
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=timeout)
    return err


def on_terminal(args, **kw) -> tuple[int, bytes]:
    """Run ``args`` with its stderr on a pseudo-terminal until it exits: (its exit status, what
    it wrote there)."""
    master, slave = pty.openpty()
    p = spawn(args, stderr=slave, env=ENV, **kw)
    os.close(slave)
    out = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:                             # EIO: the process closed the terminal
            break
        if not chunk:
            break
        out += chunk
    os.close(master)
    return p.wait(timeout=60), out


def fill(fd: int) -> None:
    """Write into a non-blocking pipe until not even one more byte fits."""
    size = 65536
    while size:
        try:
            os.write(fd, b"#" * size)
        except BlockingIOError:
            size //= 2


def drain(fd: int) -> bytes:
    """Everything a non-blocking pipe holds now (up to its end, when the writer has closed it)."""
    out = b""
    while True:
        try:
            chunk = os.read(fd, 65536)
        except BlockingIOError:
            return out
        if not chunk:
            return out
        out += chunk


#: ``cmsensord COMMAND ARGV`` as the command runs it, then its own peak resident memory (VmHWM,
#: which starts afresh at exec: a child's ru_maxrss starts at its parent's peak, this test
#: process's, which would hide any command's smaller than that)
_PEAK = """import atexit, sys
def _peak():
    kb = next(line.split()[1] for line in open('/proc/self/status') if line.startswith('VmHWM:'))
    sys.stderr.write(f'\\nVmHWM {kb}\\n')
atexit.register(_peak)
from cmsensord.cli import main
sys.exit(main(sys.argv[1:]))
"""


def peak_rss_mb(*args, cwd=None, timeout=300) -> tuple[int, str, float]:
    """(exit status, stderr, peak resident memory in MB) of ``cmsensord ARGS``."""
    p = subprocess.run([sys.executable, "-c", _PEAK, *map(str, args)], cwd=cwd, stdout=subprocess.DEVNULL,
                       stderr=subprocess.PIPE, text=True, timeout=timeout, env=ENV)
    err, _, peak = p.stderr.rpartition("\nVmHWM ")
    return p.returncode, err, int(peak) / 1024
