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
* a frame is also a repeat when the board sent it again under the next seq: a block's frame
  (the same type, t0, channel, flags and payload) that came already in that block, the
  frames under the newest t0 (a firmware that sends a block's buffer again with a fresh
  header); it moves the seq on.  (A frame under a t0 already taken with other samples, a t0
  that stuck, is no repeat: the Processor places it a block on; nor is one after a seq gap.)
* the next frame taken carries the number of repeats dropped just before it in its flags
  above the wire's eight bits (``flags >> 8``, :data:`REPEATS_SHIFT`), so that the stream's
  consumer reports them where they were, whatever the reads were.

Only a scan whose seq gaps could hold a repeat (their sum reaches ``65536 - WINDOW``), that
follows one, or that holds a frame of a type and channel that came already under its t0
(:class:`BlockKeys`, a few array operations a scan) is looked at frame by frame; the frames
of any other scan only pass through :meth:`Repeats.take` (its most recent :data:`WINDOW`
frames kept by reference).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
from operator import attrgetter

import numpy as np

from cmsensord.frame_batch import Columns

__all__ = ["WINDOW", "REPEATS_SHIFT", "BlockKeys", "Repeats", "repeats_before"]

#: how many of the newest frames taken a repeat is looked for among
WINDOW = 256
#: a frame's flags above the wire's eight bits: the repeats dropped just before it
REPEATS_SHIFT = 8
_SEQ = 0x10000
#: the least seq-gap sum of a scan that may hold a repeat
_SUSPECT = _SEQ - WINDOW
#: what places a frame in its block: (unwrapped t0, type, channel)
_PLACE = attrgetter("t0_unwrapped", "type", "chan")


def repeats_before(flags: int) -> int:
    """How many repeats the receiver dropped just before the frame of ``flags``."""
    return flags >> REPEATS_SHIFT


class BlockKeys:
    """The type and channel of each frame taken under the newest t0, as ``type << 8 | chan``:
    whether a scan holds a frame whose type and channel came already under its t0."""

    def __init__(self) -> None:
        self.t0: int | None = None
        self.keys: set[int] = set()

    def clash(self, out: list) -> bool:
        """True when a frame of ``out`` (a scan's frames and run columns, in stream order) has the
        type and channel of a frame before it under its t0 (then the caller looks at the scan
        frame by frame and sets :attr:`t0` and :attr:`keys`); else the newest t0's keys are kept."""
        t0, keys = self.t0, set(self.keys)
        for item in out:
            if type(item) is Columns:
                clash, t0, keys = self._columns(item, t0, keys)
                if clash:
                    return True
                continue
            t, ftype, chan = _PLACE(item)
            key = ftype << 8 | chan
            if t != t0:
                t0, keys = t, {key}
            elif key in keys:
                return True
            else:
                keys.add(key)
        self.t0, self.keys = t0, keys
        return False

    @staticmethod
    def _columns(cols: Columns, t0: int | None, keys: set[int]) -> tuple[bool, int | None, set[int]]:
        t = cols.t0_unwrapped
        n = len(t)
        if not n:
            return False, t0, keys
        key = cols.code << 8 | cols.chan
        if (t[1:] == t[:-1]).any():             # frames of one block: no key twice under one t0
            place = t * 4096 + key
            if not (place[1:] > place[:-1]).all() and np.unique(place).size < n:
                return True, t0, keys
        other = t != t[-1]
        if t0 is not None and int(t[0]) == t0:  # the block the scan goes on with
            lead = int(np.argmax(t != t0)) if (t != t0).any() else n
            if not keys.isdisjoint(key[:lead].tolist()):
                return True, t0, keys
        start = n - int(np.argmax(other[::-1])) if other.any() else 0
        last = set(key[start:].tolist())
        return False, int(t[-1]), (last | keys if start == 0 and int(t[-1]) == t0 else last)


class Repeats:
    """The receiver's record of its newest frames and the repeats it dropped (module docstring).

    ``make(cols, data)``: the frames of a run's columns over the scanned bytes (the decoder's).
    """

    def __init__(self, make: Callable[[Columns, bytes], list]):
        self._make = make
        self._recent: deque[tuple[list, bytes, int]] = deque()     # scans taken: (out, data, frames)
        self._held = 0              # frames in ``_recent``
        self.blocks = BlockKeys()
        self.newest: int | None = None   # seq of the newest frame taken (or sent again under a new seq)
        self.pending = 0            # repeats dropped that no frame taken has carried yet
        self.dropped: list = []     # the repeats the last :meth:`take` dropped
        self.lost_removed = 0       # the seq gaps it counted that the frames taken do not carry

    def take(self, out: list, data: bytes, last_before: int | None, last_after: int | None,
             lost: int) -> list:
        """One scan's frames and run columns (in stream order) with the repeats dropped
        (:attr:`dropped`, and :attr:`lost_removed` of ``lost``, for the link's counters).

        ``last_before``/``last_after``: the seq of the newest frame received before and after the
        scan; ``lost``: the sum of the scan's seq gaps."""
        self.dropped, self.lost_removed = [], 0
        if lost >= _SUSPECT or self.newest != last_before or self.pending or self.blocks.clash(out):
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
        recent, block = self._identities()
        kept: list = []
        for f in self._frames(out, data):
            key, t = _identity(f), f.t0_unwrapped
            place = f.type << 8 | f.chan
            newest = self.newest
            if newest is not None and (newest - f.seq) % _SEQ < WINDOW and recent.get(f.seq) == key:
                self._drop(f)                       # the same frame again, under its seq
                continue
            gap = f.lost_before if newest is None else (f.seq - newest - 1) % _SEQ
            if not gap and t == self.blocks.t0 and block.get(place) == key[4:]:
                self._drop(f)                       # a block's frame again, under the next seq
                self.newest = f.seq
                continue
            self.lost_removed += f.lost_before - gap
            if gap != f.lost_before or self.pending:
                f = f._replace(flags=f.flags | self.pending << REPEATS_SHIFT, lost_before=gap)
            self.pending = 0
            kept.append(f)
            recent[f.seq] = key
            if t != self.blocks.t0:
                self.blocks.t0, block = t, {}
            block[place] = key[4:]
            self.newest = f.seq
        self.blocks.keys = set(block)
        return kept

    def _drop(self, f) -> None:
        self.pending += 1
        self.dropped.append(f)
        self.lost_removed += f.lost_before

    def _frames(self, out: list, data: bytes) -> Iterator:
        for item in out:
            if type(item) is Columns:
                yield from self._make(item, data)
            else:
                yield item

    def _identities(self) -> tuple[dict[int, tuple], dict[int, tuple]]:
        """seq -> what the newest frame taken under it was (:func:`_identity`), and, for the
        frames taken under the newest t0, type << 8 | chan -> (flags, payload)."""
        by_seq: dict[int, tuple] = {}
        block: dict[int, tuple] = {}
        t0 = None
        for out, data, _ in self._recent:
            for f in self._frames(out, data):
                key = by_seq[f.seq] = _identity(f)
                if f.t0_unwrapped != t0:
                    t0, block = f.t0_unwrapped, {}
                block[f.type << 8 | f.chan] = key[4:]
        return by_seq, block


def _identity(f) -> tuple:
    """What a frame was on the wire (its flags without the receiver's bits)."""
    return int(f.type), f.seq, f.t0, f.chan, f.flags & 0xFF, f.payload
