"""The output directory stays held by the process writing into it, through the commands a
user types: a replay holds its lock while it writes (a daemon started meanwhile is refused, as
beside another daemon), and a daemon whose directory is deleted (``rm -rf logs``) or emptied
(``rm logs/*``) under it takes its lock again and binds its control socket again, saying so in
one journal line: ``cmsensord status`` reaches it and a second daemon is refused, as before."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from processes import run_module, spawn, start_board, start_daemon, stop

AGAIN = "(a second daemon on this directory is refused again)"
REACH = "(cmsensord status, ack and capture-now reach this daemon again)"


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


def status_answers(cfg: Path, within_s: float = 15.0) -> subprocess.CompletedProcess:
    """``cmsensord status --config cfg``, again until it answers (exit 0) or ``within_s`` pass."""
    end = time.monotonic() + within_s
    while True:
        r = run_module("cmsensord", "status", "--config", str(cfg))
        if r.returncode == 0 or time.monotonic() > end:
            return r
        time.sleep(0.5)


def test_a_replay_holds_the_directory_a_daemon_started_meanwhile_is_refused(tmp_path):
    """A replay holds its output directory, not only checks the lock: a daemon started on the
    service's configuration while the replay writes there is refused, never running beside it with
    both writing into the directory. Once the replay has ended the directory is free again."""
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


def _daemon_with_its_directory(tmp_path: Path, remove) -> tuple[subprocess.Popen, str, tuple,
                                                                subprocess.CompletedProcess]:
    """The daemon on a simulated board; ``remove(logs)`` 3 s in; ``cmsensord status`` until it
    answers and a second daemon then; (the daemon, its stderr, the second's (status, line), the
    status command's result)."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--link", str(link))
    first = start_daemon(tmp_path, link)
    try:
        time.sleep(3.0)
        remove(tmp_path / "logs")
        answered = status_answers(tmp_path / "cmsensord.yaml")
        second = second_daemon(tmp_path / "cmsensord.yaml")
        assert first.poll() is None
    finally:
        err = stop(first)
        sim.terminate()
        sim.wait(timeout=5)
    assert first.returncode == 0, err
    return first, err, second, answered


def test_the_directory_deleted_under_the_daemon_its_lock_and_socket_are_made_again(tmp_path):
    """``rm -rf logs``: guards against ``cmsensord status`` saying `no daemon answers on
    .../cmsensord.sock` (exit 1) for good, and a second daemon starting and reading the port beside
    the first."""
    logs = tmp_path / "logs"
    first, err, second, answered = _daemon_with_its_directory(tmp_path, shutil.rmtree)
    assert answered.returncode == 0, answered.stderr
    assert answered.stdout.startswith("[") and "| rx " in answered.stdout, answered.stdout
    assert second == (78, refusal(logs, first.pid))
    assert [line for line in err.splitlines() if "removed (the output" in line] == [
        f"WARNING disk_error: {logs}: its lock file and control socket were removed (the output directory "
        f"emptied or deleted?): lock taken again {AGAIN}; socket bound again {REACH}"]
    assert (logs / "cmsensord.sock").exists() is False      # removed at the stop, as before


def test_the_directory_emptied_under_the_daemon_its_socket_is_bound_again(tmp_path):
    """``rm logs/*`` takes the socket and not the dotfile lock (the flock still holds): the
    socket alone is bound again."""
    def empty(logs: Path) -> None:                 # as typed: the shell's * leaves dotfiles out
        assert subprocess.run(["sh", "-c", f"rm {logs}/*"]).returncode == 0

    logs = tmp_path / "logs"
    first, err, second, answered = _daemon_with_its_directory(tmp_path, empty)
    assert answered.returncode == 0, answered.stderr
    assert second == (78, refusal(logs, first.pid))
    assert [line for line in err.splitlines() if "removed (the output" in line] == [
        f"WARNING disk_error: {logs}: its control socket was removed (the output directory emptied or "
        f"deleted?): socket bound again {REACH}"]
