"""The daemon's hold on its output directory while it runs: its lock and its control socket.

Removing the directory (``rm -rf logs``) or its contents (``rm logs/*``: the socket, not the
dotfile lock) under a running daemon took both away for good: the sink made the directory
again for its next file, but ``cmsensord status``, ``ack`` and ``capture-now`` found no socket,
and a second daemon on the same configuration found no lock and read the port beside the first.
:class:`DirGuard` looks every :data:`CHECK_S` seconds (a stat of each file) and takes the lock
again and binds the socket again, with one ``disk_error`` event (``details.action``
``relocked``, a journal WARNING) saying what was gone and is back. A directory no longer on the
device it was on at start (its file system unmounted: :mod:`cmsensord.sinks.log_dir`) gets
neither made on the file system under it: one ``relock_waiting`` event says so, and they are
looked at again once it is back.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from cmsensord.service.control import ControlServer
from cmsensord.service.instance import LOCK_NAME, HeldDir
from cmsensord.sinks.log_dir import off_device, place_of
from cmsensord.sinks.retention import DISK_EVENT

__all__ = ["CHECK_S", "DirGuard"]

#: seconds between two looks at the lock file and the socket (two stats)
CHECK_S = 2.0


class DirGuard:
    """Keeps ``held`` (the directory's lock; None: not held, nothing to keep) and ``control``
    (the socket; None: not started) while the daemon runs. ``emit(kind, message, level,
    details)``: an event."""

    def __init__(self, held: HeldDir | None, control: ControlServer | None,
                 emit: Callable[[str, str, int, dict], None], now: float = 0.0):
        self.held, self.control, self.emit = held, control, emit
        self._next = now + CHECK_S
        self._told = ""                 # the failure said last (not repeated while it lasts)
        self.device = place_of(self._dir()) if held is not None or control is not None else None

    def check(self, now: float) -> None:
        """Every CHECK_S: a lock file or socket gone is taken or bound again, said in one event;
        what cannot be is said once (an ERROR) and tried again at each look."""
        if now < self._next:
            return
        self._next = now + CHECK_S
        held, control = self.held, self.control
        lock_gone = held is not None and held.gone()
        sock_gone = control is not None and control.gone()
        if not (lock_gone or sock_gone):
            self._told = ""
            return
        away = off_device(self._dir(), self.device)
        if away is not None:            # unmounted: nothing made on the file system under it
            if self._told != away:
                self.emit(DISK_EVENT, f"{self._dir()}: {away}; its lock file and control socket too (cmsensord "
                          "status, ack and capture-now cannot reach this daemon meanwhile)", logging.WARNING,
                          {"action": "relock_waiting"})
            self._told = away
            return
        back, failed = [], ""
        if held is not None and lock_gone:
            why = held.retake()
            if why is None:
                back.append("lock file")
            else:
                failed = f"its lock file {LOCK_NAME} was removed and cannot be taken again: {why}"
        if control is not None and sock_gone and not failed:    # never bound beside another daemon
            try:
                control.rebind()
                back.append("control socket")
            except OSError as exc:
                failed = f"its control socket {control.path} was removed and cannot be bound again: " \
                         f"{exc.strerror or exc}"
        if back:
            self._said_back(back)
        if failed and failed != self._told:
            self.emit(DISK_EVENT, f"{self._dir()}: {failed}; tried again every {CHECK_S:g} s", logging.ERROR,
                      {"action": "relock_failed"})
        self._told = failed

    def _dir(self) -> str:
        if self.held is not None:
            return str(self.held.dir)
        assert self.control is not None
        return str(self.control.path.parent)

    def _said_back(self, back: list[str]) -> None:
        said = {"lock file": "lock taken again (a second daemon on this directory is refused again)",
                "control socket": "socket bound again (cmsensord status, ack and capture-now reach this "
                                  "daemon again)"}
        self.emit(DISK_EVENT, f"{self._dir()}: its {' and '.join(back)} {'were' if len(back) > 1 else 'was'} "
                  f"removed (the output directory emptied or deleted?): {'; '.join(said[b] for b in back)}",
                  logging.WARNING, {"action": "relocked"})
