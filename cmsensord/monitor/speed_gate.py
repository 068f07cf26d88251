"""One bounded gate for everything that waits for a final shaft speed.

Rows along the board's time axis (observation slots for the anomaly decisions,
samples for the order tracker) wait here until the tacho's speed is final for
them, so what is computed from them does not depend on how the stream was read.
A gate never holds more than ``max_rows``: when asked to (``bounded``, after
each batch of frames), rows older than that are released with the speed as it
is — a tacho announced by STATUS whose TACHO frames never come, or stop, cannot
make it grow without limit.
"""

from __future__ import annotations

import numpy as np


class SpeedGate:
    """Contiguous rows of one or more arrays (the same leading length) waiting on a position.

    ``end``: the position after the newest row; ``waiting``: how many rows wait
    (the first at ``end - waiting``).
    """

    def __init__(self, max_rows: int):
        self.max_rows = int(max_rows)
        self._parts: list[tuple[np.ndarray, ...]] = []
        self.waiting = 0
        self.end: int | None = None

    @property
    def first(self) -> int:
        """Position of the oldest waiting row (``end`` when none waits)."""
        assert self.end is not None
        return self.end - self.waiting

    def restart(self, position: int) -> None:
        """The next rows start at ``position`` (nothing may be waiting)."""
        assert not self.waiting
        self.end = position

    def push(self, *arrays: np.ndarray) -> None:
        """Rows following the newest ones (position ``end`` on)."""
        assert self.end is not None, "restart() first"
        n = arrays[0].shape[0]
        self._parts.append(arrays)
        self.waiting += n
        self.end += n

    def release(self, upto: int, *, final: bool = False,
                bounded: bool = False) -> tuple[int, tuple[np.ndarray, ...]] | None:
        """The rows before position ``upto`` (all of them if ``final``; with ``bounded``, at
        least all but the newest ``max_rows``): (position of the first, the arrays), or None."""
        if not self.waiting:
            return None
        first = self.first
        end = first + self.waiting      # == self.end
        if final:
            upto = end
        else:
            upto = min(upto, end)
            if bounded and self.waiting > self.max_rows:
                upto = max(upto, end - self.max_rows)
        n = upto - first
        if n <= 0:
            return None
        whole = tuple(np.concatenate(a) for a in zip(*self._parts)) if len(self._parts) > 1 else self._parts[0]
        rest = whole[0].shape[0] - n
        self._parts = [tuple(a[n:] for a in whole)] if rest else []
        self.waiting = rest
        return first, tuple(a[:n] for a in whole)
