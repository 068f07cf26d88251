"""SIGINT/SIGTERM (stop) and SIGHUP (reopen the logs) as flags the loops check."""

from __future__ import annotations

import signal
import threading


class StopFlag:
    """SIGINT/SIGTERM set a flag the loop checks; a second signal is not needed."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal: int | None = None
        self.reopen = False

    def install(self) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handler)

    def install_reopen(self) -> None:
        """SIGHUP sets ``reopen``; the loop then reopens the logs (for log rotation tools)."""
        signal.signal(signal.SIGHUP, self._hup)

    def why(self) -> str:
        """Why the loop ended: the signal's name, or the end of the run."""
        return f"signal {signal.Signals(self.signal).name}" if self.signal else "end of run"

    def _handler(self, signum, _frame) -> None:
        self.signal = signum
        self.event.set()

    def _hup(self, _signum, _frame) -> None:
        self.reopen = True              # only a flag: the loop does the work
