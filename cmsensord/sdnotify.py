"""systemd's notification protocol (sd_notify(3)), in a few lines over a datagram socket.

A ``Type=notify`` service tells the service manager how it is doing by sending
newline-separated ``KEY=VALUE`` datagrams to the AF_UNIX socket named in
``$NOTIFY_SOCKET`` (a path, or an abstract name written with a leading ``@``):

    READY=1       start-up is complete (config loaded, port open or being waited for)
    STATUS=...    one line shown by ``systemctl status``
    WATCHDOG=1    "the processing loop is still making progress" (``WatchdogSec=``)
    STOPPING=1    shutdown has begun

:class:`Notifier` reads the environment once.  Without ``$NOTIFY_SOCKET`` (any run
outside systemd) every method does nothing.  ``$WATCHDOG_PID``, when set, names the
process the variables were meant for: in any other process (a child that inherited
them) the notifier stays off.  ``$WATCHDOG_USEC`` enables :meth:`Notifier.watchdog`,
which sends at most one ping per ``WATCHDOG_USEC / 4``, and only when it is called:
it must be called from the loop whose progress it vouches for, never from a timer or
a side thread (a side thread keeps pinging when the loop has hung).

Socket errors never reach the daemon: the first one is logged, the rest at debug level.
A message waits at most ``SEND_TIMEOUT_S`` for room in the manager's receive queue and
is then dropped, so a manager that stops reading cannot hang the loop.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from collections.abc import Callable, Mapping

log = logging.getLogger("cmsensord")

__all__ = ["Notifier"]

#: the longest a send may wait for room in the manager's receive queue: the loop must not hang on it
SEND_TIMEOUT_S = 0.1


class Notifier:
    """READY / STATUS / WATCHDOG / STOPPING for systemd; inert when not run by it."""

    def __init__(self, environ: Mapping[str, str] | None = None, *,
                 clock: Callable[[], float] = time.monotonic) -> None:
        env = os.environ if environ is None else environ
        self._clock = clock
        self._sock: socket.socket | None = None
        self._connected = False
        self._addr: str | bytes | None = None
        self._errors = 0
        #: seconds between watchdog pings (WATCHDOG_USEC / 4), or None: no watchdog
        self.watchdog_interval_s: float | None = None
        self._last_ping = float("-inf")
        name = env.get("NOTIFY_SOCKET", "")
        pid = env.get("WATCHDOG_PID", "")
        if not name:
            return
        if pid and pid.strip() != str(os.getpid()):
            log.debug("NOTIFY_SOCKET ignored: WATCHDOG_PID=%s is another process", pid)
            return
        if name.startswith("@"):
            self._addr = b"\0" + name[1:].encode()          # abstract namespace
        elif name.startswith("/"):
            self._addr = name
        else:
            log.warning("NOTIFY_SOCKET=%s: not a socket path or @name; not notifying systemd", name)
            return
        try:
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.settimeout(SEND_TIMEOUT_S)
        except OSError as exc:
            log.warning("NOTIFY_SOCKET=%s: cannot create a socket (%s); not notifying systemd", name, exc)
            self._sock = None
            return
        usec = env.get("WATCHDOG_USEC", "")
        try:
            watchdog_s = int(usec) / 1e6 if usec else 0.0
        except ValueError:
            log.warning("WATCHDOG_USEC=%s: not an integer; watchdog pings off", usec)
            watchdog_s = 0.0
        if watchdog_s > 0:
            self.watchdog_interval_s = watchdog_s / 4

    @property
    def enabled(self) -> bool:
        """True when run by a service manager that listens (NOTIFY_SOCKET for this process)."""
        return self._sock is not None

    def ready(self, status: str | None = None) -> None:
        """READY=1 (and a STATUS line): start-up is complete."""
        self._send("READY=1" + (f"\nSTATUS={_line_breaks_as_spaces(status)}" if status is not None else ""))

    def status(self, text: str) -> None:
        """STATUS=: the one-line state ``systemctl status`` shows."""
        self._send(f"STATUS={_line_breaks_as_spaces(text)}")

    def watchdog(self) -> None:
        """WATCHDOG=1 if the last ping is WATCHDOG_USEC/4 old; call it from the loop each iteration."""
        if self.watchdog_interval_s is None or self._sock is None:
            return
        now = self._clock()
        if now - self._last_ping >= self.watchdog_interval_s:
            self._last_ping = now
            self._send("WATCHDOG=1")

    def stopping(self, status: str | None = None) -> None:
        """STOPPING=1 (and a STATUS line): shutdown has begun."""
        self._send("STOPPING=1" + (f"\nSTATUS={_line_breaks_as_spaces(status)}" if status is not None else ""))

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _send(self, message: str) -> None:
        if self._sock is None or self._addr is None:
            return
        data = message.encode("utf-8", "replace")
        error: OSError | None = None
        for _attempt in range(2):
            try:
                # connected, so that waiting for room polls the manager's queue: an unconnected
                # datagram socket polls writable while sendto() fails with EAGAIN, and the timed
                # send would spin on the CPU for its whole timeout
                if not self._connected:
                    self._sock.connect(self._addr)
                    self._connected = True
                self._sock.send(data)
                return
            except TimeoutError as exc:         # the manager's queue stayed full: drop this one
                error = exc
                break
            except OSError as exc:
                error = exc
                if not self._connected:         # nobody listens there
                    break
                self._connected = False         # the manager may have a new socket: connect again
        self._errors += 1
        if self._errors == 1:
            log.warning("sd_notify to %s failed: %s (further failures are logged at debug level)",
                        _printable(self._addr), error)
        else:
            log.debug("sd_notify failed (%d): %s", self._errors, error)


def _line_breaks_as_spaces(text: str) -> str:
    """A line break would end the STATUS assignment: each becomes a space."""
    return str(text).replace("\r\n", " ").replace("\n", " ").replace("\r", " ")


def _printable(addr: str | bytes | None) -> str:
    if isinstance(addr, bytes):
        return "@" + addr[1:].decode(errors="replace")
    return str(addr)
