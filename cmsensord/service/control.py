"""The daemon's control socket: ``cmsensord ack``, ``status`` and ``capture-now`` talk to it.

A Unix stream socket ``cmsensord.sock`` in the output directory (the systemd
unit's state directory, ``/var/lib/cmsensord``; the unit allows AF_UNIX only).
One request per connection, one JSON line each way::

    {"cmd": "ack", "alarm": "de_velocity/ch0"}   ("alarm": null or absent: every alarm)
    {"cmd": "status"}
    {"cmd": "capture", "channel": "ch0"}       ("channel": null or absent: every channel)

A small thread (:class:`ControlServer`) accepts connections and queues the
requests; the processing loop answers them between batches
(:meth:`ControlServer.apply`), so an acknowledgement is applied in the stream's
order, stamped with stream time, and nothing else touches the Processor from
another thread.  The thread waits at most ``REPLY_S`` for the loop.  An
acknowledgement is recorded with the user the connecting process runs as (the
socket's peer credentials).
"""

from __future__ import annotations

import contextlib
import json
import os
import pwd
import queue
import socket
import struct
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["ControlServer", "SOCKET_NAME", "socket_path", "request"]

SOCKET_NAME = "cmsensord.sock"
#: the unit's state directory: where the client looks without --config or --socket
STATE_DIR = Path("/var/lib/cmsensord")
#: seconds the server thread waits for the loop's answer, and a client for the server's
REPLY_S = 5.0
MAX_REQUEST = 4096


def socket_path(output_dir: str | os.PathLike) -> Path:
    """The control socket of a daemon writing to ``output_dir``."""
    return Path(output_dir).resolve() / SOCKET_NAME


@dataclass
class _Request:
    body: dict
    by: str | None = None           # the user the client runs as
    done: threading.Event = field(default_factory=threading.Event)
    reply: dict | None = None


class ControlServer:
    """The socket and its accepting thread (see module docstring)."""

    def __init__(self, path: Path):
        self.path = path
        self.requests: queue.Queue[_Request] = queue.Queue(maxsize=16)
        self.wake: Callable[[], None] | None = None     # wakes the processing loop for a request
        self.status_line: Callable[[], str] | None = None    # the daemon's whole status line (STATUS=)
        self._stop = threading.Event()
        self.sock, self._ident = self._bind()
        self.thread = self._start()

    def _bind(self) -> tuple[socket.socket, tuple[int, int]]:
        """A socket bound and listening at ``path`` (one a dead daemon left there is replaced),
        and the identity (device, inode) of its file."""
        path = self.path
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            if path.is_socket() and not _answers(path):      # left by a daemon that died
                path.unlink()
            with _short(path) as name:
                sock.bind(name)
            st = os.stat(path)
            sock.listen(4)          # accept blocks: close's shutdown wakes it (no wake-ups when idle)
        except OSError:
            sock.close()
            raise
        return sock, (st.st_dev, st.st_ino)

    def _start(self) -> threading.Thread:
        thread = threading.Thread(target=self._serve, args=(self.sock,), name="cmsensord-control", daemon=True)
        thread.start()
        return thread

    def gone(self) -> bool:
        """Whether the socket's file is no longer there (removed with the output directory's
        contents, or replaced): clients cannot reach this daemon. One stat."""
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            return True
        except OSError:
            return False
        return (st.st_dev, st.st_ino) != self._ident

    def rebind(self) -> None:
        """Bind the socket at ``path`` again (:meth:`gone`: its file removed), the accepting
        thread with it; OSError (the old socket kept) when it cannot be bound."""
        sock, ident = self._bind()
        old, thread = self.sock, self.thread
        self.sock, self._ident = sock, ident
        _shut(old)
        thread.join(timeout=2.0)
        self.thread = self._start()

    # ---------------------------------------------------------- server thread
    def _serve(self, sock: socket.socket) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = sock.accept()
            except OSError:
                return
            with conn, contextlib.suppress(OSError):
                conn.settimeout(REPLY_S)
                conn.sendall(json.dumps(self._answer(_read_line(conn), _peer(conn))).encode() + b"\n")

    def _answer(self, line: bytes, by: str | None = None) -> dict:
        try:
            body = json.loads(line)
        except ValueError:
            return {"ok": False, "error": "the request is not one JSON line"}
        if not isinstance(body, dict) or body.get("cmd") not in ("ack", "status", "capture"):
            return {"ok": False, "error": "unknown request (cmd: ack, status or capture)"}
        req = _Request(body, by)
        try:
            self.requests.put_nowait(req)
        except queue.Full:
            return {"ok": False, "error": "busy: too many requests waiting"}
        if self.wake is not None:
            self.wake()
        if not req.done.wait(REPLY_S):
            return {"ok": False, "error": f"the processing loop did not answer within {REPLY_S:g} s"}
        return req.reply or {"ok": False, "error": "no answer"}

    # ---------------------------------------------------------- processing loop
    def apply(self, proc) -> None:
        """In the processing loop, between batches: answer every waiting request."""
        while True:
            try:
                req = self.requests.get_nowait()
            except queue.Empty:
                return
            try:
                req.reply = handle(proc, req.body, self.status_line, req.by)
            finally:
                req.done.set()

    def close(self) -> None:
        """Stop accepting (at once: shutdown wakes the thread's accept) and remove the socket
        (its file only if it is this daemon's)."""
        self._stop.set()
        _shut(self.sock)
        self.thread.join(timeout=2.0)
        if not self.gone():
            with contextlib.suppress(OSError):
                self.path.unlink()


def _shut(sock: socket.socket) -> None:
    """Close a listening socket, waking the thread blocked in its accept."""
    with contextlib.suppress(OSError):
        sock.shutdown(socket.SHUT_RDWR)
    sock.close()


def handle(proc, body: dict, line: Callable[[], str] | None = None, by: str | None = None) -> dict:
    """The answer to one request, from the Processor (the loop's thread); ``line``: the daemon's
    whole status line (the link's counters and state, the broker's), else the Processor's part;
    ``by``: the user who asks (recorded with an acknowledgement)."""
    from cmsensord.service.status import status_line

    if body["cmd"] == "capture":
        return _capture(proc, body)
    alarms = proc.alarms
    if body["cmd"] == "status":
        out: dict[str, Any] = {"ok": True, "status": line() if line is not None else status_line(proc)}
        if alarms.active:
            out.update(alarms.table())
        return out
    which = body.get("alarm")
    if which is not None and not isinstance(which, str):
        return {"ok": False, "error": "alarm must be a name or null"}
    if not alarms.active:
        return {"ok": False, "error": "no alarm rules are configured (alarms.rules)"}
    before = proc.event_counts.get("alarm_ack", 0)
    try:
        proc.ack(which, by)
    except KeyError:
        names = ", ".join(alarms.manager.alarms if alarms.manager else alarms.saved_names())
        return {"ok": False, "error": f"no alarm named {which!r} (alarms: {names})"}
    return {"ok": True, "acknowledged": proc.event_counts.get("alarm_ack", 0) - before}


def _capture(proc, body: dict) -> dict:
    """``cmsensord capture-now``: a manual capture (:meth:`Captures.manual`)."""
    channel = body.get("channel")
    if channel is not None and not isinstance(channel, str):
        return {"ok": False, "error": "channel must be a name or null"}
    if proc.captures is None:
        return {"ok": False, "error": "captures are off in this daemon's configuration: give capture.triggers "
                "(e.g. [manual]) or capture.every_s"}
    return proc.captures.manual(channel)


def _peer(conn: socket.socket) -> str | None:
    """The user name (else ``uid N``) the process at the other end of ``conn`` runs as; None if
    the socket does not say."""
    try:
        _pid, uid, _gid = struct.unpack("3i", conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED,
                                                              struct.calcsize("3i")))
    except (OSError, AttributeError):
        return None
    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:
        return f"uid {uid}"


def _read_line(conn: socket.socket) -> bytes:
    buf = b""
    while b"\n" not in buf and len(buf) < MAX_REQUEST:
        chunk = conn.recv(MAX_REQUEST)
        if not chunk:
            break
        buf += chunk
    return buf.split(b"\n", 1)[0]


#: longest socket path bind() and connect() take as it is (sun_path holds 108 bytes)
_SUN_PATH = 100


@contextlib.contextmanager
def _short(path: Path) -> Iterator[str]:
    """A name of ``path`` short enough for a Unix socket address: itself, or (a deep output
    directory) the same file through an open descriptor of its directory."""
    if len(os.fsencode(str(path))) < _SUN_PATH:
        yield str(path)
        return
    fd = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
    try:
        yield f"/proc/self/fd/{fd}/{path.name}"
    finally:
        os.close(fd)


def _answers(path: Path) -> bool:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        try:
            with _short(path) as name:
                s.connect(name)
        except OSError:
            return False
    return True


def request(path: Path, body: dict, timeout: float = REPLY_S + 2.0) -> dict:
    """Send one request to the daemon at ``path``; its answer.  OSError when none answers."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        with _short(path) as name:
            s.connect(name)
        s.sendall(json.dumps(body).encode() + b"\n")
        buf = b""
        while not buf.endswith(b"\n"):
            chunk = s.recv(65536)
            if not chunk:
                break
            buf += chunk
    return json.loads(buf)
