"""RAW frames off the block grid: a stray one is dropped, and the time base stays.

The frames of a block share its t0 and the blocks follow one another ``block_len`` samples
apart (docs/PROTOCOL.md), so the t0 of a segment's RAW frames lie on one grid: the block
clock's slots (:meth:`~cmsensord.monitor.clock.BlockClock.slot_t0`).  A RAW frame whose t0
is off that grid falls in the block its t0 rounds down to.  It is a *stray* (a frame of
garbage that passed the CRC, a frame with a t0 off, sent besides the block's own), dropped
with a ``decode_error`` event at its block's stamp, when that block

* is at or behind the newest block taken before it (a frame on the grid, one kept off it, or
  the newest slot the block clock placed), or
* has a frame on the grid (of any channel) among the frames that come with it.

Else it is its block's own frame under a t0 a few samples off, and it is taken as any frame
(the block clock places it in the block it falls in), as are the block's other channels after
it.  A stream whose block clock has no grid yet takes the first t0 two of its frames agree on
(two channels of a block, or two blocks), so that a stray first frame does not set the grid;
its frames wait until two agree.  A frame farther from the newest t0 before it than the
longest gap the block clock fills (a board clock jump, a step back) starts another grid, the
block clock's to anchor: it and the frames after it are not judged against the old one.  So
the block clock never sees a stray and is not re-anchored for it; a block grid that changes
with a board reset, a jump of the board clock past the gap a block clock fills, or a STATUS
with another block length is the block clock's, as before.

Whether a frame of the grid comes with an off-grid one is known once a frame of a later block
came: the newest block, when a frame off the grid is among its frames or after them and fewer
than C channels came on the grid in it, waits for one (:func:`hold_from`).  So which frames are
strays does not depend on how the stream was cut into reads.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from cmsensord.monitor.clock import MAX_FILL_S, MAX_FILL_SLOTS, BlockClock
from cmsensord.monitor.events import Event

_BEFORE_ALL = np.iinfo(np.int64).min


class Grid(NamedTuple):
    """The block grid the RAW frames are checked against."""

    origin: int | None      # a t0 on the grid (None: the first frame's)
    newest: int | None      # t0 of the newest block placed (None: none yet)
    block_len: int
    reach: int              # the most samples a frame may lie from the newest t0 and be of the grid


def grid_of(clock: BlockClock) -> Grid:
    """The grid of a :class:`~cmsensord.monitor.clock.BlockClock`: its slots, its newest slot, and
    as far as it reaches (the longest gap the clock fills: past it, the clock re-anchors)."""
    reach = clock.block_len * max(1, min(MAX_FILL_SLOTS, int(MAX_FILL_S * clock.fs / clock.block_len)))
    if clock.slot0_t0 is None:
        return Grid(None, None, clock.block_len, reach)
    newest = int(clock.slot_t0(clock.next_slot - 1)) if clock.next_slot else None
    return Grid(int(clock.slot0_t0), newest, clock.block_len, reach)


def judged(t0: np.ndarray, grid: Grid) -> int:
    """How many of the frames, from the first, lie within the grid's reach of the newest t0
    before each (a board clock jump past it, or a step back as far, starts another grid: the
    block clock's to anchor, not strays)."""
    if t0.size < 2 and grid.newest is None:
        return int(t0.size)
    ref = np.maximum.accumulate(np.concatenate([[t0[0] if grid.newest is None else grid.newest], t0[:-1]]))
    far = np.flatnonzero(np.abs(t0 - ref) > grid.reach)
    return int(far[0]) if far.size else int(t0.size)


def agreed(t0: np.ndarray, block_len: int) -> int | None:
    """The first t0 another frame's agrees with (the same t0, or whole blocks apart): the grid of
    a stream whose block clock has none yet; None when no two agree (a lone frame, a stray
    first among others)."""
    _, inverse, counts = np.unique(t0 % block_len, return_inverse=True, return_counts=True)
    twice = counts[inverse] >= 2
    return int(t0[int(np.argmax(twice))]) if twice.any() else None


def offsets(t0: np.ndarray, grid: Grid) -> np.ndarray | None:
    """Each frame's samples past the grid's block it falls in; None when all are on the grid.
    Without a grid yet, the grid is the first t0 two frames agree on (:func:`agreed`), else the
    first frame's."""
    if not t0.size:
        return None
    origin = grid.origin
    if origin is None:
        origin = agreed(t0, grid.block_len)
        origin = int(t0[0]) if origin is None else origin
    off = (t0 - origin) % grid.block_len
    n = judged(t0, grid)
    if n < t0.size:
        off[n:] = 0                             # another grid's: not judged here
    return off if off.any() else None


def hold_from(t0: np.ndarray, chan: np.ndarray, C: int, grid: Grid) -> int | None:
    """Where the frames that wait for a later block start, when the newest block on the grid
    (from its first frame on) holds a frame off the grid: there, while fewer than ``C`` channels
    came on the grid in it (whether the frame off it is a stray is not known yet), else
    ``len(t0)`` (none waits).  None: no frame off the grid from there on (the blocks wait as
    they do on the grid)."""
    if grid.origin is None and t0.size and agreed(t0, grid.block_len) is None:
        return 0                                # no grid yet: all wait for a frame that agrees
    off = offsets(t0, grid)
    if off is None:
        return None
    g = t0 - off
    s = int(np.argmax(g == g.max()))
    if not off[s:].any():
        return None
    on = (off[s:] == 0) & (g[s:] == g[s])
    return len(t0) if len(set(chan[s:][on].tolist())) >= C else s


def strays(t0: np.ndarray, chan: np.ndarray, grid: Grid,
           stamp_ns: Callable[[int], int] | None) -> tuple[np.ndarray | None, list[Event]]:
    """(which frames to keep, None: all; a ``decode_error`` event per stray) of frames in
    arrival order (see module docstring)."""
    off = offsets(t0, grid)
    if off is None:
        return None, []
    on = off == 0
    g = t0 - off
    first = _BEFORE_ALL if grid.newest is None else grid.newest
    newest_on = np.maximum.accumulate(np.where(on, t0, first))     # the newest block on the grid so far
    on_blocks = set(t0[on].tolist())
    keep = np.ones(len(t0), dtype=bool)
    kept, events = _BEFORE_ALL, []
    kept_chans: set[int] = set()                # the channels taken in block ``kept``
    for i in np.flatnonzero(~on).tolist():
        block, newest, ch = int(g[i]), max(int(newest_on[i]), kept), int(chan[i])
        if block == kept and ch not in kept_chans and block >= int(newest_on[i]):
            kept_chans.add(ch)                  # another channel of that block
            continue
        if block > newest and block not in on_blocks:
            kept, kept_chans = block, {ch}      # its block's own frame, a t0 off
            continue
        keep[i] = False
        events.append(_stray(int(t0[i]), int(chan[i]), block, newest, grid.block_len, stamp_ns))
    return (None if keep.all() else keep), events


def _stray(t0: int, chan: int, block: int, newest: int, L: int, stamp_ns: Callable[[int], int] | None) -> Event:
    """The ``decode_error`` of a stray frame at ``t0`` in ``block`` (the newest block taken before
    it: ``newest``), naming the t0 fields as the board sent them."""
    off = t0 - block if 2 * (t0 - block) <= L else t0 - block - L     # from the nearest t0 of the grid
    why = ("which has frames on the grid" if block > newest else "the newest block taken" if block == newest
           else f"behind the newest block {newest & 0xFFFFFFFF}")
    return Event("decode_error", None, f"RAW frame of channel {chan} at t0 {t0 & 0xFFFFFFFF} dropped: t0 off the block "
                 f"grid by {off:+d} sample(s) and in block {block & 0xFFFFFFFF}, {why} (a stray frame: the time base "
                 "is kept)", stamp_ns(block) if stamp_ns else None, {"count": 1})
