"""cmsensord.sdnotify.Notifier against real AF_UNIX datagram sockets (a path and an abstract name)."""

from __future__ import annotations

import logging
import os
import socket
import tempfile
import uuid

import pytest

from cmsensord.sdnotify import Notifier


@pytest.fixture
def path_socket():
    """A datagram socket bound to a short filesystem path (sun_path holds 108 bytes)."""
    d = tempfile.mkdtemp(prefix="sdn")
    path = os.path.join(d, "notify")
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(path)
    s.setblocking(False)
    yield s, path
    s.close()
    os.unlink(path)
    os.rmdir(d)


@pytest.fixture
def abstract_socket():
    """A datagram socket in the abstract namespace: NOTIFY_SOCKET=@name."""
    name = f"cmsensord-test-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind("\0" + name)
    s.setblocking(False)
    yield s, "@" + name
    s.close()


def received(sock) -> list[str]:
    """Every datagram queued on the socket (a datagram is queued when sendto returns)."""
    out = []
    while True:
        try:
            out.append(sock.recv(4096).decode())
        except BlockingIOError:
            return out


@pytest.mark.parametrize("kind", ["path_socket", "abstract_socket"])
def test_ready_status_stopping_reach_the_socket(kind, request):
    sock, name = request.getfixturevalue(kind)
    n = Notifier({"NOTIFY_SOCKET": name})
    assert n.enabled
    n.ready("waiting for /dev/ttyACM0")
    n.status("[    12.0 s] ch0 S=0.3 out/s=  4 F=1110000000")
    n.stopping("stopping")
    assert received(sock) == ["READY=1\nSTATUS=waiting for /dev/ttyACM0",
                              "STATUS=[    12.0 s] ch0 S=0.3 out/s=  4 F=1110000000",
                              "STOPPING=1\nSTATUS=stopping"]


def test_a_status_with_line_breaks_is_sent_as_one_line(path_socket):
    sock, name = path_socket
    n = Notifier({"NOTIFY_SOCKET": name})
    n.status("two\nlines\r\nREADY=1")          # must not smuggle a second assignment in
    assert received(sock) == ["STATUS=two lines READY=1"]


def test_without_notify_socket_nothing_is_set_up_or_sent():
    n = Notifier({"WATCHDOG_USEC": "1000000"})
    assert not n.enabled and n.watchdog_interval_s is None
    n.ready("x"), n.status("x"), n.watchdog(), n.stopping()   # no socket, no error


def test_watchdog_pings_at_a_quarter_of_watchdog_usec_and_only_when_called(abstract_socket, clock):
    sock, name = abstract_socket
    n = Notifier({"NOTIFY_SOCKET": name, "WATCHDOG_USEC": "2000000"}, clock=clock)
    assert n.watchdog_interval_s == pytest.approx(0.5)
    sent_at = []
    for k in range(41):                         # the loop calls it every 0.1 s for 4 s
        clock.t = 100.0 + 0.1 * k
        n.watchdog()
        sent_at += [round(clock.t - 100.0, 6)] * len(received(sock))
    assert sent_at == pytest.approx([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0])
    clock.t += 60.0                             # not called for a minute: nothing was sent meanwhile
    assert received(sock) == []
    n.watchdog()
    assert received(sock) == ["WATCHDOG=1"]


def test_no_watchdog_usec_means_no_pings(path_socket):
    sock, name = path_socket
    n = Notifier({"NOTIFY_SOCKET": name})
    n.watchdog()
    n.ready()
    assert received(sock) == ["READY=1"]


def test_watchdog_pid_of_another_process_turns_the_notifier_off(path_socket):
    sock, name = path_socket
    other = Notifier({"NOTIFY_SOCKET": name, "WATCHDOG_USEC": "1000000", "WATCHDOG_PID": str(os.getpid() + 1)})
    assert not other.enabled
    other.ready(), other.watchdog(), other.stopping()
    assert received(sock) == []
    mine = Notifier({"NOTIFY_SOCKET": name, "WATCHDOG_USEC": "1000000", "WATCHDOG_PID": str(os.getpid())})
    mine.watchdog()
    assert received(sock) == ["WATCHDOG=1"]


@pytest.mark.parametrize("env", [{"NOTIFY_SOCKET": "relative/notify"},
                                 {"NOTIFY_SOCKET": "vsock:2:1234"}])
def test_an_unusable_notify_socket_is_reported_and_ignored(env, caplog):
    with caplog.at_level(logging.WARNING, logger="cmsensord"):
        n = Notifier(env)
    assert not n.enabled
    assert env["NOTIFY_SOCKET"] in caplog.text


def test_a_socket_error_is_logged_once_and_never_raised(caplog):
    d = tempfile.mkdtemp(prefix="sdn")
    gone = os.path.join(d, "notify")             # nobody listens there (systemd went away)
    try:
        n = Notifier({"NOTIFY_SOCKET": gone, "WATCHDOG_USEC": "4"})
        with caplog.at_level(logging.DEBUG, logger="cmsensord"):
            n.ready("x")
            n.status("y")
            n.watchdog()
            n.stopping()
        warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
        assert len(warnings) == 1 and gone in warnings[0].getMessage()
        assert sum(r.levelno == logging.DEBUG for r in caplog.records) == 3
    finally:
        os.rmdir(d)


def test_a_full_receive_queue_costs_a_bounded_wait_not_a_hang_nor_a_busy_loop(path_socket, caplog):
    """The manager not reading: a send waits for room at most SEND_TIMEOUT_S, asleep, then gives up."""
    import time

    from cmsensord.sdnotify import SEND_TIMEOUT_S

    sock, name = path_socket
    n = Notifier({"NOTIFY_SOCKET": name})
    with caplog.at_level(logging.WARNING, logger="cmsensord"):
        for _ in range(10_000):                # far more than the socket's receive queue holds
            n.status("x" * 100)
            if caplog.records:
                break
    assert "sd_notify" in caplog.text          # the queue is full and a send gave up
    wall, cpu = time.monotonic(), time.thread_time()
    n.status("one more")
    wall, cpu = time.monotonic() - wall, time.thread_time() - cpu
    assert SEND_TIMEOUT_S * 0.9 <= wall < 2.0  # it waited for room, boundedly ...
    assert cpu < 0.3 * wall                    # ... asleep, not polling a socket that says writable
    received(sock)
    n.status("room again")
    assert received(sock) == ["STATUS=room again"]


def test_a_new_socket_at_the_same_path_is_found_again(path_socket):
    """The manager re-creates its socket (systemctl daemon-reexec): the next message gets there."""
    sock, name = path_socket
    n = Notifier({"NOTIFY_SOCKET": name})
    n.status("before")
    assert received(sock) == ["STATUS=before"]
    sock.close()
    os.unlink(name)
    new = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    new.bind(name)
    new.setblocking(False)
    try:
        n.status("after")
        assert received(new) == ["STATUS=after"]
    finally:
        new.close()                            # the fixture removes the path
