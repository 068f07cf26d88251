"""The daemon's control socket: ``cmsensord ack``, ``status`` and ``capture-now`` talk to it.

A Unix stream socket ``cmsensord.sock`` in the output directory (the systemd
unit's state directory, ``/var/lib/cmsensord``; the unit allows AF_UNIX only).
One request per connection, one JSON line each way::

    {"cmd": "ack", "alarm": "de_velocity/ch0"}   ("alarm": null or absent: every alarm)
    {"cmd": "status"}
    {"cmd": "capture", "channel": "ch0"}       ("channel": null or absent: every channel)

A small thread (:class:`ControlServer`) accepts connections and hands each to a
thread of its own (at most ``MAX_CLIENTS`` at once; one more is answered
``busy`` at once), so a client that is slow to send, or sends nothing, holds up
no other.  Each connection has ``REPLY_S`` from its accept to send its line and
get its answer.  The requests are queued; the processing loop answers them
between batches (:meth:`ControlServer.apply`), so an acknowledgement is applied
in the stream's order, stamped with stream time, and nothing else touches the
Processor from another thread.  A request the loop has not taken when its
connection's time is up is answered as not applied, and the loop skips it: no
client is told a request failed that is then applied.  An acknowledgement is
recorded with the user the connecting process runs as (the socket's peer
credentials).  Idle, the server is one thread blocked in accept."""

from __future__ import annotations

import contextlib
import json
import os
import pwd
import queue
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cmsensord.config.yaml_file import MAX_CONFIG_BYTES

__all__ = ["ControlServer", "NoAnswer", "SOCKET_NAME", "socket_path", "request"]

SOCKET_NAME = "cmsensord.sock"
#: the unit's state directory: where the client looks without --config or --socket
STATE_DIR = Path("/var/lib/cmsensord")
#: seconds a connection has, from its accept, to send its line and get the answer
REPLY_S = 5.0
#: longest request line read: one naming an alarm or channel as long as a configuration file can be
MAX_REQUEST = MAX_CONFIG_BYTES + 4096
#: connections served at once
MAX_CLIENTS = 8
#: longest answer a client reads: a status of as many alarms, named as long, as a configuration holds
MAX_ANSWER = 16 * MAX_CONFIG_BYTES


def socket_path(output_dir: str | os.PathLike) -> Path:
    """The control socket of a daemon writing to ``output_dir``."""
    return Path(output_dir).resolve() / SOCKET_NAME


@dataclass
class _Request:
    body: dict
    by: str | None = None           # the user the client runs as
    done: threading.Event = field(default_factory=threading.Event)
    reply: dict | None = None
    state: str = "queued"           # then "taken" (the loop applies it) or "dropped" (its time is up)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def settle(self, state: str) -> bool:
        """Move a queued request to ``state``; False (nothing changed) if it is taken or dropped."""
        with self.lock:
            if self.state != "queued":
                return False
            self.state = state
            return True


class ControlServer:
    """The socket and its accepting thread (see module docstring)."""

    def __init__(self, path: Path):
        self.path = path
        self.requests: queue.Queue[_Request] = queue.Queue(maxsize=16)
        self.wake: Callable[[], None] | None = None     # wakes the processing loop for a request
        self.status_line: Callable[[], str] | None = None    # the daemon's whole status line (STATUS=)
        self._stop = threading.Event()
        self._slots = threading.BoundedSemaphore(MAX_CLIENTS)
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
            if not self._slots.acquire(blocking=False):
                _send(conn, {"ok": False, "error": f"busy: {MAX_CLIENTS} connections are open"})
                continue
            try:
                threading.Thread(target=self._client, args=(conn,), name="cmsensord-control-client",
                                 daemon=True).start()
            except RuntimeError:            # no thread to be had
                self._slots.release()
                _send(conn, {"ok": False, "error": "busy: no thread for the connection"})

    def _client(self, conn: socket.socket) -> None:
        """One connection, in a thread of its own: its line read, its answer sent."""
        deadline = time.monotonic() + REPLY_S
        try:
            with conn:
                try:
                    line = _read_line(conn, deadline)
                except OSError:
                    return
                if line is None:
                    answer = {"ok": False, "error": f"no request line within {REPLY_S:g} s"}
                else:
                    answer = self._answer(line, _peer(conn), deadline)
                _send(conn, answer)
        finally:
            self._slots.release()

    def _answer(self, line: bytes, by: str | None = None, deadline: float | None = None) -> dict:
        """The answer to one request line: from the loop if it takes the request by ``deadline``
        (default: ``REPLY_S`` from now), else that it is not applied."""
        if len(line) > MAX_REQUEST:
            return {"ok": False, "error": f"the request is longer than {MAX_REQUEST} bytes"}
        try:
            body = json.loads(line)
        except (ValueError, RecursionError):       # RecursionError: arrays nested a thousand deep
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
        left = (time.monotonic() + REPLY_S if deadline is None else deadline) - time.monotonic()
        if not req.done.wait(max(left, 0.0)) and req.settle("dropped"):
            return {"ok": False, "error": f"the processing loop did not answer within {REPLY_S:g} s "
                    "(the request is not applied)"}
        req.done.wait()                     # taken by the loop: its answer comes
        return req.reply or {"ok": False, "error": "no answer"}

    # ---------------------------------------------------------- processing loop
    def apply(self, proc) -> None:
        """In the processing loop, between batches: answer every waiting request."""
        while True:
            try:
                req = self.requests.get_nowait()
            except queue.Empty:
                return
            if not req.settle("taken"):
                continue                    # its connection's time is up: not applied
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
    try:
        done = proc.ack(which, by)
    except KeyError:
        names = ", ".join(alarms.manager.alarms if alarms.manager else alarms.saved_names())
        return {"ok": False, "error": f"no alarm named {which!r} (alarms: {names})"}
    out = {"ok": True, "acknowledged": len(done), "alarms": done}
    row = next((r for r in alarms.table()["alarms"] if r["id"] == which), None) if which and not done else None
    if row is not None:             # why there was nothing to acknowledge: the level it shows
        out["level"] = row["level"]
    return out


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


def _read_line(conn: socket.socket, deadline: float) -> bytes | None:
    """The request line (without its newline; all that came, if the client closed first or it
    grew past MAX_REQUEST); None if it did not come by ``deadline`` (time.monotonic)."""
    buf = b""
    while b"\n" not in buf and len(buf) <= MAX_REQUEST:
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        conn.settimeout(left)
        try:
            chunk = conn.recv(65536)
        except TimeoutError:
            return None
        if not chunk:
            break
        buf += chunk
    return buf.split(b"\n", 1)[0]


def _send(conn: socket.socket, answer: dict) -> None:
    """Send ``answer`` (one JSON line) and close ``conn``; a client gone is no error."""
    with conn, contextlib.suppress(OSError):
        conn.settimeout(REPLY_S)
        conn.sendall(json.dumps(answer).encode() + b"\n")


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


class NoAnswer(Exception):
    """A daemon took the connection, but its answer did not come (in time, or at all)."""


def request(path: Path, body: dict, timeout: float = REPLY_S + 2.0) -> dict:
    """Send one request to the daemon at ``path``; its answer.  OSError when nothing takes the
    connection; NoAnswer when the answer does not come within ``timeout`` s (the daemon
    answers within ``REPLY_S``), the daemon closes the connection without one, or what comes is
    not a daemon's answer (longer than ``MAX_ANSWER``, not a JSON object)."""
    deadline = time.monotonic() + timeout
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        with _short(path) as name:
            s.connect(name)
        with contextlib.suppress(OSError):          # a daemon that answered at once (busy) and closed
            s.sendall(json.dumps(body, ensure_ascii=False).encode(errors="backslashreplace") + b"\n")
        buf = bytearray()
        try:
            while not buf.endswith(b"\n"):
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError
                s.settimeout(left)
                chunk = s.recv(65536)
                if not chunk:
                    break
                buf += chunk
                if len(buf) > MAX_ANSWER:
                    raise NoAnswer(f"the answer is longer than {MAX_ANSWER} bytes: not a cmsensord daemon "
                                   "on this socket?")
        except TimeoutError:
            raise NoAnswer(f"the daemon took the request but did not answer within {timeout:g} s: it may "
                           "have been applied (see cmsensord status)") from None
        except OSError as exc:
            raise NoAnswer(f"the connection broke before the daemon's answer ({exc.strerror or exc}): the "
                           "request may have been applied (see cmsensord status)") from None
    try:
        answer = json.loads(buf)
    except (ValueError, RecursionError):
        raise NoAnswer("the daemon closed the connection without an answer") from None
    if not isinstance(answer, dict):
        raise NoAnswer(f"the answer is not a cmsensord daemon's (a JSON {type(answer).__name__}, not an object): "
                       "not a cmsensord daemon on this socket?")
    return answer
