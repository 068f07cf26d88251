"""The control socket beside clients that connect and send nothing, or trickle their line:
`cmsensord status` and `cmsensord ack` still answer, and an ack is reported as what happened to
it (one the daemon had not applied in time is said to be not applied, and is not applied later);
an ack of an alarm whose name is as long as the configuration takes it."""

from __future__ import annotations

import json
import socket
import sys
import threading
import time

import pytest

from cmsensord.service.control import REPLY_S, SOCKET_NAME, ControlServer
from processes import cmsensord, spawn, stop

pytestmark = pytest.mark.process

LONG = "x" * 20_000                 # an alarm name the configuration takes


def daemon(tmp_path, rules: str):
    """``cmsensord --simulate`` of the faulty motor with alarm ``rules``, once its first alarm
    latched: the process and its socket."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"link: {{max_drift_s: 0}}\noutput: {{status_line: false}}\nalarms:\n  rules:\n{rules}")
    d = spawn([sys.executable, "-m", "cmsensord", "--simulate", "--scenario", "faulty", "--duration", "600",
               "--speed", "1", "--config", str(cfg), "--out", str(tmp_path / "logs")], stderr=-1, text=True)
    sock = tmp_path / "logs" / SOCKET_NAME
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        time.sleep(0.5)
        if sock.is_socket() and "latched" in cmsensord("status", "--socket", str(sock)).stdout:
            return d, str(sock)
    stop(d)
    raise AssertionError("no alarm latched within 60 s")


def connect(path: str) -> socket.socket:
    s = socket.socket(socket.AF_UNIX)
    s.connect(path)
    return s


def answer(s: socket.socket) -> dict:
    s.settimeout(30)
    buf = b""
    while not buf.endswith(b"\n"):
        chunk = s.recv(4096)
        if not chunk:
            break
        buf += chunk
    return json.loads(buf)


def test_idle_and_trickling_clients_hold_up_no_ack(tmp_path):
    """Three connections that send nothing and one that sends a blank every second: status and
    ack --all answer beside them, the ack reported done and shown acknowledged; each silent
    connection is told, at its time, that no request came."""
    d, sock = daemon(tmp_path, "    - {name: lat, indicator: accel_rms, alert: 0.5, latch: true}\n")
    try:
        idle = [connect(sock) for _ in range(3)]
        slow = connect(sock)
        done = threading.Event()

        def trickle():
            while not done.wait(1.0):
                try:
                    slow.sendall(b" ")
                except OSError:
                    return
        t = threading.Thread(target=trickle)
        t.start()
        try:
            before = cmsensord("status", "--socket", sock)
            assert before.returncode == 0, before.stderr
            assert [ln.split()[-1] for ln in before.stdout.splitlines() if ln.startswith("lat/ch0")] == ["latched"]
            ack = cmsensord("ack", "--all", "--socket", sock)
            assert (ack.returncode, ack.stdout, ack.stderr) == (0, "acknowledged 1 alarm(s): lat/ch0\n", "")
            after = cmsensord("status", "--socket", sock)
            assert [ln.split()[-1] for ln in after.stdout.splitlines() if ln.startswith("lat/ch0")] == \
                ["acknowledged"], after.stdout
            again = cmsensord("ack", "lat/ch0", "--socket", sock)     # the faulty motor stays above 0.5
            assert (again.returncode, again.stdout) == (
                0, "nothing to acknowledge: lat/ch0 is acknowledged already (it shows alert)\n"), after.stdout
            for s in idle:
                assert answer(s) == {"ok": False, "error": f"no request line within {REPLY_S:g} s"}
            assert answer(slow) == {"ok": False, "error": f"no request line within {REPLY_S:g} s"}
        finally:
            done.set()
            t.join()
            for s in [*idle, slow]:
                s.close()
    finally:
        err = stop(d)
    assert "Traceback" not in err, err


def test_an_ack_of_the_longest_alarm_name(tmp_path):
    """An alarm named with 20,000 characters is acknowledged by its name."""
    d, sock = daemon(tmp_path, f"    - {{name: {LONG}, indicator: accel_rms, alert: 0.5, latch: true}}\n")
    try:
        ack = cmsensord("ack", f"{LONG}/ch0", "--socket", sock)
        assert (ack.returncode, ack.stdout, ack.stderr) == (0, f"acknowledged 1 alarm(s): {LONG}/ch0\n", "")
    finally:
        stop(d)


class _Proc:
    """A Processor that records acknowledgements."""

    def __init__(self):
        self.acks: list = []
        self.event_counts: dict = {}
        self.alarms = self

    active = True

    def ack(self, which, by):
        self.acks.append(which)


def test_an_ack_the_loop_did_not_take_in_time_is_not_applied(tmp_path):
    """The processing loop busy past the connection's time: `cmsensord ack` is told, in one
    line, that the request is not applied, and the loop, free again, does not apply it."""
    server = ControlServer(tmp_path / SOCKET_NAME)         # a daemon whose loop does not come round
    try:
        ack = cmsensord("ack", "--all", "--socket", str(tmp_path / SOCKET_NAME))
        proc = _Proc()
        server.apply(proc)
        assert proc.acks == []
        assert (ack.returncode, ack.stdout) == (1, "")
        assert ack.stderr == (f"cmsensord: ack: the processing loop did not answer within {REPLY_S:g} s "
                              "(the request is not applied)\n")
    finally:
        server.close()


def test_one_connection_more_than_served_is_told_busy(tmp_path, capsys):
    """MAX_CLIENTS connections open and silent: `cmsensord status` is told at once that the
    daemon is busy, in one line, exit status 1."""
    from cmsensord.cli import main
    from cmsensord.service.control import MAX_CLIENTS

    path = tmp_path / SOCKET_NAME
    server = ControlServer(path)
    held = [connect(str(path)) for _ in range(MAX_CLIENTS)]
    try:
        assert main(["status", "--socket", str(path)]) == 1
        assert capsys.readouterr() == ("", f"cmsensord: status: busy: {MAX_CLIENTS} connections are open\n")
    finally:
        for s in held:
            s.close()
        server.close()


def test_a_daemon_that_takes_the_request_and_never_answers(tmp_path):
    """A socket that takes the connection and never answers: `cmsensord ack` says the answer did
    not come and that the ack may have been applied (not that no daemon answers), exit status 1."""
    path = tmp_path / SOCKET_NAME
    with socket.socket(socket.AF_UNIX) as listening:
        listening.bind(str(path))
        listening.listen(4)
        ack = cmsensord("ack", "--all", "--socket", str(path))
    assert (ack.returncode, ack.stdout) == (1, "")
    assert ack.stderr == (f"cmsensord: ack: the daemon took the request but did not answer within {REPLY_S + 2:g} "
                          "s: it may have been applied (see cmsensord status)\n")


def test_a_request_nested_too_deep_is_answered_and_the_socket_still_serves(tmp_path):
    """A line of 100,000 ``[``: answered as not JSON; the socket takes the next connection."""
    path = tmp_path / SOCKET_NAME
    server = ControlServer(path)
    try:
        for _ in range(2):
            with connect(str(path)) as s:
                s.sendall(b"[" * 100_000 + b"\n")
                assert answer(s) == {"ok": False, "error": "the request is not one JSON line"}
    finally:
        server.close()
