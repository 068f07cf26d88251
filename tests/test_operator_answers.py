"""`cmsensord status`, `ack` and `capture-now` on a socket whose answer is not what this cmsensord
reads (a daemon of another version, another program's socket): one line on stderr and exit 1,
never a traceback, and never a client that reads an endless answer into memory."""

from __future__ import annotations

import contextlib
import socket
import threading

import pytest

from processes import cmsensord

pytestmark = pytest.mark.process

COMMANDS = [("status",), ("ack", "--all"), ("capture-now",)]


@contextlib.contextmanager
def answering(path, answer: bytes | None):
    """A Unix socket at ``path`` answering every request line with ``answer`` (None: bytes
    without a newline, as long as the client reads)."""
    srv = socket.socket(socket.AF_UNIX)
    srv.bind(str(path))
    srv.listen(4)

    def serve():
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            with conn, contextlib.suppress(OSError):
                conn.recv(65536)
                if answer is not None:
                    conn.sendall(answer)
                else:
                    while True:
                        conn.sendall(b"x" * 65536)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield str(path)
    finally:
        srv.shutdown(socket.SHUT_RDWR)
        srv.close()


def ask(sock: str, command: tuple[str, ...]):
    run = cmsensord(*command, "--socket", sock, timeout=30)
    assert "Traceback" not in run.stderr, run.stderr
    return run.returncode, run.stderr


#: what an older daemon answers: ok, but without the fields this version reads
_OLD = b'{"ok": true, "status": "link up", "alarms": []}\n'
_MISSING = {"status": "operating_state", "ack": "acknowledged", "capture-now": "captures"}


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c[0])
def test_an_answer_without_the_fields_read_is_one_line(tmp_path, command):
    with answering(tmp_path / "old.sock", _OLD) as sock:
        code, err = ask(sock, command)
    assert code == 1
    assert err == (f"cmsensord: {command[0]}: the daemon's answer is not one this cmsensord reads (no field "
                   f"'{_MISSING[command[0]]}'): a daemon of another cmsensord version? `cmsensord status --json` "
                   "prints the answer as it came\n")


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c[0])
def test_an_answer_that_is_no_json_object_is_one_line(tmp_path, command):
    with answering(tmp_path / "list.sock", b"[1, 2]\n") as sock:
        code, err = ask(sock, command)
    assert (code, err) == (1, f"cmsensord: {command[0]}: the answer is not a cmsensord daemon's (a JSON list, not "
                              "an object): not a cmsensord daemon on this socket?\n")


def test_an_endless_answer_is_cut_at_its_bound(tmp_path):
    """A socket sending bytes without end: the client stops at its bound, 16 MiB (control.MAX_ANSWER;
    it read on until the test's timeout, its memory growing all the while)."""
    with answering(tmp_path / "endless.sock", None) as sock:
        code, err = ask(sock, ("status",))
    assert (code, err) == (1, "cmsensord: status: the answer is longer than 16777216 bytes: not a cmsensord "
                              "daemon on this socket?\n")


@pytest.mark.parametrize("answer", [b'{"ok": false}\n', b'{"ok": false, "error": null}\n',
                                    b'{"ok": false, "error": ["x"]}\n'], ids=["none", "null", "list"])
@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c[0])
def test_a_refusal_without_an_error_text_says_no_reason_was_given(tmp_path, command, answer):
    # the line was "cmsensord: ack: None" (or the field's repr)
    with answering(tmp_path / "refusing.sock", answer) as sock:
        code, err = ask(sock, command)
    assert (code, err) == (1, f"cmsensord: {command[0]}: the daemon refused the request without saying why (no "
                              "'error' text in its answer): a daemon of another cmsensord version? `cmsensord "
                              "status --json` prints the answer as it came\n")
