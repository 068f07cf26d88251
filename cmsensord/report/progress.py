"""A progress bar on a terminal: bytes read of the logs, redrawn at most 5 times a second."""

from __future__ import annotations

import time
from typing import TextIO

__all__ = ["Progress"]


class Progress:
    """``[#####.....]  45%  12.3/27.0 MB`` on ``stream`` when it is a terminal; silent otherwise."""

    WIDTH = 30

    def __init__(self, total_bytes: int, stream: TextIO) -> None:
        self.total = max(1, total_bytes)
        self.stream = stream
        self.active = stream.isatty()
        self._last = 0.0

    def update(self, done_bytes: int, *, force: bool = False) -> None:
        """Redraw for ``done_bytes`` read so far (at most every 0.2 s unless ``force``)."""
        if not self.active:
            return
        now = time.monotonic()
        if not force and now - self._last < 0.2:
            return
        self._last = now
        frac = min(1.0, done_bytes / self.total)
        bar = "#" * int(frac * self.WIDTH)
        self.stream.write(f"\r[{bar:.<{self.WIDTH}}] {frac:4.0%}  {done_bytes / 1e6:.1f}/{self.total / 1e6:.1f} MB")
        self.stream.flush()

    def close(self) -> None:
        """The full bar and a newline."""
        if self.active:
            self.update(self.total, force=True)
            self.stream.write("\n")
            self.stream.flush()
