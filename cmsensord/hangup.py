"""SIGHUP held from the command's first line, until the daemon's loop takes it.

A SIGHUP (``systemctl reload``, a log rotation tool) may come while the command starts, before
the daemon's loop takes it (:meth:`cmsensord.service.signals.StopFlag.install_reopen`, after
~0.3 s of imports and the configuration): its default action would end the process, which
systemd's ``Restart=on-failure`` does not restart (a clean signal).  So the entry point
(:mod:`cmsensord.entry`) holds it first of all (:func:`hold`): until the loop takes it
(:func:`take`), a SIGHUP is a reopen pending, which the loop then honours; a command that is not
the daemon gives it back (:func:`release`), a SIGHUP held meanwhile then acting as it would have.
This module imports nothing but :mod:`signal`, so the hold starts as early as the interpreter
lets it (its own start, ~0.015 s, comes before any of it).
"""

from __future__ import annotations

import signal

#: whether SIGHUP is held, and whether one came while it was
_HELD = {"holding": False, "pending": False}


def hold() -> None:
    """SIGHUP, from now until :func:`take` or :func:`release`, sets a pending reopen instead of
    ending the process (in the main thread; elsewhere nothing is held)."""
    try:
        signal.signal(signal.SIGHUP, _held)
    except ValueError:                  # not the main thread
        return
    _HELD["holding"] = True


def release() -> None:
    """SIGHUP's default action again; one that came while it was held is delivered now (it ends
    the process, as it would have).  Nothing when it is not held."""
    if not _HELD["holding"]:
        return
    _HELD["holding"] = False
    signal.signal(signal.SIGHUP, signal.SIG_DFL)
    if _HELD["pending"]:
        _HELD["pending"] = False
        signal.raise_signal(signal.SIGHUP)


def take() -> bool:
    """Whether a SIGHUP came while held (the caller has put its own handler in place): the hold
    ends, and the pending one is the caller's."""
    pending = _HELD["pending"]
    _HELD["holding"] = _HELD["pending"] = False
    return pending


def _held(_signum, _frame) -> None:
    _HELD["pending"] = True
