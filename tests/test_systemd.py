"""The daemon under a fake service manager: a real notify socket, a real process, a real pty.

The test plays systemd's part: it binds the datagram socket named in NOTIFY_SOCKET, sets
WATCHDOG_USEC, and starts ``cmsensord --config FILE`` the way systemd starts the unit's
main process (WATCHDOG_PID is the daemon's own pid). It then reads READY, STATUS,
WATCHDOG and STOPPING as they arrive.

To stall the processing loop it uses a real failure of a service: a journal that stops
reading. The daemon's stderr is a pipe the test holds; filling that pipe blocks the loop
in its next status-line write (once a second) while the reader thread goes on reading
the port. A watchdog pinged from a side thread would go on pinging; pinged from the
loop, it stops, and starts again once the pipe is drained.
"""

from __future__ import annotations

import fcntl
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import uuid

import pytest

from processes import ENV, board_on_pty, drain, fill, spawn

WATCHDOG_USEC = 1_000_000
WATCHDOG_S = WATCHDOG_USEC / 1e6


class FakeManager:
    """The service manager's end of NOTIFY_SOCKET: every datagram with its arrival time."""

    def __init__(self, abstract: bool):
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        if abstract:
            name = f"cmsensord-test-{os.getpid()}-{uuid.uuid4().hex[:8]}"
            self.sock.bind("\0" + name)
            self.name, self._dir = "@" + name, None
        else:
            self._dir = tempfile.mkdtemp(prefix="sdn")       # sun_path holds only 108 bytes
            self.name = os.path.join(self._dir, "notify")
            self.sock.bind(self.name)
        self.sock.settimeout(0.05)
        self.messages: list[tuple[float, str]] = []          # (monotonic time, datagram)
        self._lock = threading.Lock()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._receive, daemon=True)
        self._thread.start()

    def _receive(self) -> None:
        while not self._done.is_set():
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                continue
            with self._lock:
                self.messages.append((time.monotonic(), data.decode()))

    def times(self, assignment: str, since: float = 0.0, until: float = float("inf")) -> list[float]:
        """Arrival times of the datagrams holding ``assignment`` (e.g. ``WATCHDOG=1``)."""
        with self._lock:
            return [t for t, m in self.messages if assignment in m.split("\n") and since <= t <= until]

    def first(self, assignment: str) -> str | None:
        """The first datagram holding ``assignment``."""
        with self._lock:
            return next((m for _, m in self.messages if assignment in m.split("\n")), None)

    def statuses(self, since: float = 0.0) -> list[str]:
        with self._lock:
            return [line[len("STATUS="):] for t, m in self.messages if t >= since
                    for line in m.split("\n") if line.startswith("STATUS=")]

    def wait_for(self, assignment: str, timeout: float, since: float = 0.0) -> float | None:
        """Arrival time of the first ``assignment`` after ``since``, waiting up to ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = self.times(assignment, since=since)
            if found:
                return found[0]
            time.sleep(0.01)
        return None

    def close(self) -> None:
        self._done.set()
        self._thread.join(timeout=2)
        self.sock.close()
        if self._dir:
            os.unlink(self.name)
            os.rmdir(self._dir)


def start_daemon(config, manager: FakeManager, stderr) -> tuple[subprocess.Popen, float]:
    """``cmsensord --config FILE`` as systemd runs it: NOTIFY_SOCKET, WATCHDOG_USEC, WATCHDOG_PID."""
    env = dict(ENV, NOTIFY_SOCKET=manager.name, WATCHDOG_USEC=str(WATCHDOG_USEC))
    env.pop("WATCHDOG_PID", None)
    t0 = time.monotonic()
    # exec keeps the shell's pid, so WATCHDOG_PID=$$ is the daemon's pid, as systemd sets it
    d = spawn(["/bin/sh", "-c", 'WATCHDOG_PID=$$ exec "$0" "$@"', sys.executable, "-m",
                          "cmsensord", "--config", str(config)],
                         stdout=subprocess.DEVNULL, stderr=stderr, env=env)
    return d, t0


def gaps(times: list[float]) -> list[float]:
    return [b - a for a, b in zip(times, times[1:])]


@pytest.fixture
def manager_abstract():
    m = FakeManager(abstract=True)
    yield m
    m.close()


@pytest.fixture
def manager_path():
    m = FakeManager(abstract=False)
    yield m
    m.close()


def test_ready_watchdog_from_the_loop_and_stopping(tmp_path, manager_abstract):
    m = manager_abstract
    r, w = os.pipe()                                  # the daemon's stderr: the "journal"
    # a second, non-blocking description of the same pipe for the test's writes
    # (O_NONBLOCK on w itself would make the daemon's writes fail instead of block)
    w_test = os.open(f"/proc/self/fd/{w}", os.O_WRONLY | os.O_NONBLOCK)
    fcntl.fcntl(r, fcntl.F_SETFL, fcntl.fcntl(r, fcntl.F_GETFL) | os.O_NONBLOCK)
    d = None
    try:
        with board_on_pty("--scenario", "healthy", "--speed", "1") as port:
            cfg = tmp_path / "cmsensord.yaml"
            cfg.write_text(f"link:\n  port: {port}\noutput:\n  dir: {tmp_path / 'logs'}\n")
            d, t_start = start_daemon(cfg, m, stderr=w)
            os.close(w)
            w = -1
            t_ready = m.wait_for("READY=1", timeout=10)
            assert t_ready is not None, drain(r).decode()
            assert t_ready - t_start <= 1.5

            time.sleep(4.0)                          # running on a healthy board
            t_fill = time.monotonic()
            running = m.times("WATCHDOG=1", since=t_ready, until=t_fill)
            assert len(running) >= 3.5 / (WATCHDOG_S / 2)
            assert running[0] - t_ready <= WATCHDOG_S / 2
            assert max(gaps(running)) <= WATCHDOG_S / 2, gaps(running)
            assert t_fill - running[-1] <= WATCHDOG_S / 2
            status = m.statuses(since=t_ready)
            assert status and "ch0 S=" in status[-1] and "waiting" not in status[-1], status

            # stall the loop: its next status-line write (within 1 s) blocks on the full pipe
            drain(r)
            fill(w_test)
            time.sleep(4.0)
            t_unstall = time.monotonic()
            assert d.poll() is None                  # alive, and its reader thread still reads
            # blocked at the latest at its next status line, 1 s after the fill (+ an iteration)
            t_blocked = t_fill + 1.0 + WATCHDOG_S / 4
            assert t_unstall - t_blocked > 2 * WATCHDOG_S   # long enough for systemd to act
            stalled = m.times("WATCHDOG=1", since=t_blocked, until=t_unstall)
            assert stalled == [], f"{len(stalled)} WATCHDOG=1 while the loop was blocked"

            drain(r)                                 # the journal reads again: the loop goes on
            resumed = m.wait_for("WATCHDOG=1", timeout=2.0, since=t_unstall)
            assert resumed is not None and resumed - t_unstall <= 1.0

            d.send_signal(signal.SIGTERM)
            t_term = time.monotonic()
            err = b""
            deadline = time.monotonic() + 15
            while d.poll() is None and time.monotonic() < deadline:
                err += drain(r)
                time.sleep(0.05)
            err += drain(r)
            assert d.returncode == 0, err.decode(errors="replace")[-2000:]
            stopping = m.times("STOPPING=1", since=t_term)
            assert len(stopping) == 1
    finally:
        if d is not None and d.poll() is None:
            d.kill()
            d.wait()
        for fd in (r, w, w_test):
            if fd >= 0:
                os.close(fd)


def test_ready_and_waiting_status_when_the_port_is_missing_then_the_board_appears(tmp_path, manager_path):
    """A missing device is a state of the loop, not an exit: READY, "waiting for" the port,
    watchdog pings while waiting; when the device node appears (as udev makes the symlink)
    the reader opens it and the status becomes the running status line."""
    m = manager_path
    port = tmp_path / "cmsensord-tty"                # not there yet
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {port}\n  reconnect_min_s: 0.2\n  reconnect_max_s: 0.5\n"
                   f"output:\n  dir: {tmp_path / 'logs'}\n  status_line: false\n")
    d, t_start = start_daemon(cfg, m, stderr=subprocess.PIPE)
    try:
        t_ready = m.wait_for("READY=1", timeout=10)
        assert t_ready is not None and t_ready - t_start <= 1.5
        assert f"STATUS=waiting for {port}" in m.first("READY=1")
        time.sleep(2.5)
        assert d.poll() is None
        waiting = m.statuses(since=t_ready + 0.5)
        assert len(waiting) >= 2 and all(s.startswith(f"waiting for {port}") for s in waiting), waiting
        pings = m.times("WATCHDOG=1", since=t_ready)
        assert len(pings) >= 4 and max(gaps(pings)) <= WATCHDOG_S / 2

        with board_on_pty("--scenario", "healthy", "--speed", "1") as pty:
            t_plug = time.monotonic()
            os.symlink(pty, port)
            deadline = time.monotonic() + 6.0
            while time.monotonic() < deadline and not any(
                    "ch0 S=" in s and not s.startswith("waiting") for s in m.statuses(since=t_plug)):
                time.sleep(0.05)
            assert any("ch0 S=" in s and not s.startswith("waiting") for s in m.statuses(since=t_plug)), \
                m.statuses(since=t_plug)
            d.send_signal(signal.SIGTERM)
            _, err = d.communicate(timeout=15)
        assert d.returncode == 0, err.decode(errors="replace")[-2000:]
        assert m.wait_for("STOPPING=1", timeout=1.0) is not None
    finally:
        if d.poll() is None:
            d.kill()
            d.wait()
