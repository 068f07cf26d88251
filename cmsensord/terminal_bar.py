"""A one-line progress bar for long work in a command (an import, sending a replay's MQTT
backlog): ``label [#####...]  45.0%`` on stderr when it is a terminal, silent otherwise."""

from __future__ import annotations

import sys
import time

__all__ = ["Bar"]


class Bar:
    """Called with the amount done of ``total``; redrawn at most 5 times a second; ``close``
    erases the line."""

    def __init__(self, total: int, label: str, stream=None):
        self.total, self.label = max(1, total), label
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if hasattr(self.stream, "isatty") else False
        self._last = 0.0

    def __call__(self, done: float) -> None:
        now = time.monotonic()
        if not self.enabled or (now - self._last < 0.2 and done < self.total):
            return
        self._last = now
        frac = min(1.0, done / self.total)
        self.stream.write(f"\r{self.label} [{'#' * int(frac * 30):<30}] {frac * 100:5.1f}%")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\r\033[K")
            self.stream.flush()
