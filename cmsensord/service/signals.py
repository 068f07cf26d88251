"""SIGINT/SIGTERM (stop) and SIGHUP (reopen the logs) as flags the loops check."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from typing import Any

from cmsensord import hangup


class StopFlag:
    """SIGINT/SIGTERM set a flag the loop checks, and call ``wake`` (if set: what ends the
    loop's wait for frames, so it stops at once, not at its next wake-up); a second signal
    is not needed."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal: int | None = None
        self.reopen = False
        self.wake: Callable[[], None] | None = None

    def install(self) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handler)

    def install_reopen(self) -> None:
        """SIGHUP sets ``reopen`` and calls ``wake``; the loop then reopens the logs at once
        (for log rotation tools), not at its next wake-up.  One that came while the entry point
        held SIGHUP (:func:`cmsensord.hangup.hold`) sets ``reopen`` now."""
        signal.signal(signal.SIGHUP, self._hup)
        if hangup.take():
            self.reopen = True

    def why(self) -> str:
        """Why the loop ended: the signal's name, or the end of the run."""
        return f"signal {signal.Signals(self.signal).name}" if self.signal else "end of run"

    def _handler(self, signum, _frame) -> None:
        self.signal = signum
        self.event.set()
        if self.wake is not None:
            self.wake()

    def _hup(self, _signum, _frame) -> None:
        self.reopen = True              # only a flag: the loop does the work
        if self.wake is not None:
            self.wake()


class Interrupt:
    """Ctrl-C (SIGINT) as a flag a batch run checks between reads (``seen``), so that it ends
    as at the end of its input: its log finished, its summary printed. :meth:`sleep` (a paced
    replay's) ends at it, and ``then`` is called (what else should stop waiting). A second
    Ctrl-C interrupts at once. Installed in the main thread only (elsewhere: never set)."""

    def __init__(self, then: Callable[[], None] | None = None) -> None:
        self.seen = False
        self.then = then
        self._event = threading.Event()
        self._old: Any = None

    def sleep(self, seconds: float) -> None:
        """Sleep ``seconds``, or until Ctrl-C."""
        self._event.wait(seconds)

    def install(self) -> None:
        """Take SIGINT (in the main thread)."""
        if threading.current_thread() is threading.main_thread():
            self._old = signal.signal(signal.SIGINT, self._handler)

    def restore(self) -> None:
        """Give SIGINT back to the handler before :meth:`install`."""
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
            self._old = None

    def __enter__(self) -> Interrupt:
        self.install()
        return self

    def __exit__(self, *exc: object) -> None:
        self.restore()

    def _handler(self, _signum, _frame) -> None:
        self.seen = True
        self._event.set()
        signal.signal(signal.SIGINT, self._old if callable(self._old) else signal.default_int_handler)
        if self.then is not None:
            self.then()
