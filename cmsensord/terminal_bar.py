"""One-line progress bars for long work in a command: ``label [#####...]  45.0%`` on stderr
when it is a terminal, silent otherwise. :class:`Bar` (an import, sending a replay's MQTT
backlog) erases its line when done; :class:`Progress` (reading a capture) adds the rate in
MB/s and keeps its line. A log record written while a bar shows starts on a line of its own
(:func:`erase_line`, called by the log's handler)."""

from __future__ import annotations

import sys
import time

__all__ = ["Bar", "Progress", "erase_line"]

#: the bar whose line is on the terminal now (None: none)
_shown: Bar | None = None


def erase_line() -> None:
    """Erase the line of the bar on the terminal, if any, so that a line written next (a log
    record's) starts at the line's start; the bar draws itself again at its next call."""
    global _shown
    bar, _shown = _shown, None
    if bar is not None and bar.enabled:
        bar.stream.write("\r\033[K")
        bar.stream.flush()
        bar._last = 0.0


class Bar:
    """Called with the amount done of ``total``; redrawn at most 5 times a second; ``close``
    erases the line."""

    def __init__(self, total: int, label: str, stream=None):
        self.total, self.label = max(1, total), label
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if hasattr(self.stream, "isatty") else False
        self._last = 0.0
        self._text = ""                 # the line last drawn

    def __call__(self, done: float) -> None:
        self._draw(done, "")

    def _draw(self, done: float, suffix: str) -> None:
        now = time.monotonic()
        if not self.enabled or (now - self._last < 0.2 and done < self.total):
            return
        self._last = now
        frac = min(1.0, done / self.total)
        self._text = f"{self.label} [{'#' * int(frac * 30):<30}] {frac * 100:5.1f}%{suffix}"
        self.stream.write("\r" + self._text)
        self.stream.flush()
        global _shown
        _shown = self

    def close(self) -> None:
        global _shown
        if _shown is self:
            _shown = None
        if self.enabled:
            self.stream.write("\r\033[K")
            self.stream.flush()


class Progress(Bar):
    """A bar of bytes read, with their rate in MB/s and ``extra`` text; ``close`` ends its line
    (once)."""

    def __init__(self, total: int, label: str, stream=None):
        super().__init__(total, label, stream)
        self.t0 = time.monotonic()

    def update(self, done: int, extra: str = "") -> None:
        if not self.enabled:
            return
        rate = done / max(time.monotonic() - self.t0, 1e-9) / 1e6
        self._draw(done, f" {rate:6.1f} MB/s {extra}")

    def close(self) -> None:
        """End the bar's line (once), drawn again if a log record erased it since."""
        global _shown
        erased = _shown is not self
        if not erased:
            _shown = None
        if self.enabled:
            self.stream.write(("\r" + self._text if erased and self._text else "") + "\n")
            self.stream.flush()
            self.enabled = False
