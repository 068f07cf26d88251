"""Frames the link delivers twice: dropped by the receiver, counted, and marked on the next frame.

A board numbers every frame it sends (seq, +1 a frame, docs/PROTOCOL.md); the protocol
reads a seq gap of g as g lost frames (receiver rule 3).  A frame sent again (a firmware
that sends one DMA buffer twice, a capture written twice over a retried write) has the seq
of a frame already received, so rule 3 alone reads it as ~65,535 lost frames, and its t0,
behind the newest, as a board that restarted its clock.  The protocol does not name this
case; the receiver extends it (docs/PROTOCOL.md keeps the contract as it is):

* a frame is a **repeat** when its seq is one of the last :data:`WINDOW` seqs received
  and taken, and it is that frame again: the same type, seq, t0, channel, flags and
  payload (a board that restarts sends new frames under old seqs: they differ, and are
  taken);
* a repeat is dropped: not counted as a frame of its type, nor its overrun flag; its bytes
  are counted as discarded and it is counted in ``frames_repeated``; the seq gap of the
  next frame taken is counted from the newest frame taken (so the repeats' gaps are no
  loss);
* the next frame taken carries the number of repeats dropped just before it in its flags
  above the wire's eight bits (``flags >> 8``, :data:`REPEATS_SHIFT`), so that the stream's
  consumer reports them where they were, whatever the reads were.

Only a scan whose seq gaps could hold a repeat (their sum reaches ``65536 - WINDOW``), or
that follows one, is looked at frame by frame; the frames of any other scan only pass
through :meth:`Repeats.take` (its most recent :data:`WINDOW` frames kept by reference).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator

from cmsensord.frame_batch import Columns

__all__ = ["WINDOW", "REPEATS_SHIFT", "Repeats", "repeats_before"]

#: how many of the newest frames taken a repeat is looked for among
WINDOW = 256
#: a frame's flags above the wire's eight bits: the repeats dropped just before it
REPEATS_SHIFT = 8
_SEQ = 0x10000
#: the least seq-gap sum of a scan that may hold a repeat
_SUSPECT = _SEQ - WINDOW


def repeats_before(flags: int) -> int:
    """How many repeats the receiver dropped just before the frame of ``flags``."""
    return flags >> REPEATS_SHIFT


class Repeats:
    """The receiver's record of its newest frames and the repeats it dropped (module docstring).

    ``make(cols, data)``: the frames of a run's columns over the scanned bytes (the decoder's).
    """

    def __init__(self, make: Callable[[Columns, bytes], list]):
        self._make = make
        self._recent: deque[tuple[list, bytes, int]] = deque()     # scans taken: (out, data, frames)
        self._held = 0              # frames in ``_recent``
        self.newest: int | None = None   # seq of the newest frame taken
        self.pending = 0            # repeats dropped that no frame taken has carried yet
        self.dropped: list = []     # the repeats the last :meth:`take` dropped
        self.lost_removed = 0       # the seq gaps it counted that were no loss

    def take(self, out: list, data: bytes, last_before: int | None, last_after: int | None,
             lost: int) -> list:
        """One scan's frames and run columns (in stream order) with the repeats dropped
        (:attr:`dropped`, and :attr:`lost_removed` of ``lost``, for the link's counters).

        ``last_before``/``last_after``: the seq of the newest frame received before and after the
        scan; ``lost``: the sum of the scan's seq gaps."""
        self.dropped, self.lost_removed = [], 0
        if lost >= _SUSPECT or self.newest != last_before or self.pending:
            out = self._filter(out, data)
            data = b""
        elif last_after is not None:
            self.newest = last_after
        self._remember(out, data)
        return out

    def _remember(self, out: list, data: bytes) -> None:
        n = sum(len(item.code) if type(item) is Columns else 1 for item in out) if data else len(out)
        if not n:
            return
        self._recent.append((out, data, n))
        self._held += n
        while self._held - self._recent[0][2] >= WINDOW:
            self._held -= self._recent.popleft()[2]

    def _filter(self, out: list, data: bytes) -> list:
        """``out`` as frames, the repeats dropped and the next frame taken marked."""
        recent = self._identities()
        kept: list = []
        for f in self._frames(out, data):
            key = _identity(f)
            if self.newest is not None and (self.newest - f.seq) % _SEQ < WINDOW and recent.get(f.seq) == key:
                self.pending += 1
                self.dropped.append(f)
                self.lost_removed += f.lost_before
                continue
            lost = f.lost_before if self.newest is None else (f.seq - self.newest - 1) % _SEQ
            self.lost_removed += f.lost_before - lost
            if lost != f.lost_before or self.pending:
                f = f._replace(flags=f.flags | self.pending << REPEATS_SHIFT, lost_before=lost)
                self.pending = 0
            kept.append(f)
            recent[f.seq] = key
            self.newest = f.seq
        return kept

    def _frames(self, out: list, data: bytes) -> Iterator:
        for item in out:
            if type(item) is Columns:
                yield from self._make(item, data)
            else:
                yield item

    def _identities(self) -> dict[int, tuple]:
        """seq -> what the newest frame taken under it was (:func:`_identity`)."""
        return {f.seq: _identity(f) for out, data, _ in self._recent for f in self._frames(out, data)}


def _identity(f) -> tuple:
    """What a frame was on the wire (its flags without the receiver's bits)."""
    return int(f.type), f.seq, f.t0, f.chan, f.flags & 0xFF, f.payload
