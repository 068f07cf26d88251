"""RAW blocks (docs/PROTOCOL.md type 3) -> physical values, once; the block RMS from them.

RAW frames wait here until they can be converted: before the first STATUS (its
scale/offset) at most ``RAW_WAIT_FRAMES`` of them (the oldest beyond are
dropped and counted), and the newest block until all its channels came (its
frames can straddle a read).  :meth:`RawInput.blocks` turns ready frames into
:class:`RawBlocks`: m/s² per frame, ``(count - offset) * scale`` with the
STATUS calibration overridden by the configuration (:mod:`cmsensord.dsp.rms`),
from which both the severity chain's block RMS and the order chain's samples
come; with ``monitor.flat_signal``, also each block's count where all its samples
are that one count (peak-to-peak 0: no observation for the severity chain and, enough of them, no
signal: :meth:`RawBlocks.flat_counts`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from itertools import compress
from operator import attrgetter, lt

import numpy as np

from cmsensord.config import Config
from cmsensord.dsp.rms import physical_rms, rows_physical
from cmsensord.frame_batch import Columns, FrameBatch, Pending
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.events import Event
from cmsensord.monitor.raw_grid import grid_of, hold_from, strays
from cmsensord.protocol import COUNT_MAX, Frame, Status

#: a field of every frame of a batch, in one C-level pass (map) rather than a generator
_CHAN, _PAYLOAD, _T0 = attrgetter("chan"), attrgetter("payload"), attrgetter("t0_unwrapped")

#: the fewest samples a block whose samples are all one count is flat in (a block of a few
#: samples of a slow import, one at 100 Hz, is one count by its length, not by a dead sensor)
FLAT_MIN_SAMPLES = 16
#: RAW frames held while waiting for the first STATUS (its scale/offset): 2 s of 4 channels
RAW_WAIT_FRAMES = 800


@dataclass
class RawBlocks:
    """Converted RAW frames of consecutive (or, across lost ones, gapped) blocks."""

    t0: np.ndarray          # (B,) int64 first sample of each block, in arrival order
    row: np.ndarray         # (F,) the block of each frame
    chan: np.ndarray        # (F,) the board channel of each frame
    x: np.ndarray           # (F, block_len) float64 m/s²
    n_channels: int         # C of the board
    flat: np.ndarray | None = None  # (F,) float32 the count of a frame whose samples are all it, else NaN
    # worked out once (the arrays are not changed after construction; each chain asks)
    _complete_memo: bool | None = field(default=None, init=False, repr=False, compare=False)
    _runs_memo: list[tuple[int, int]] | None = field(default=None, init=False, repr=False, compare=False)

    def rms(self) -> np.ndarray:
        """float32 (B, C): the block RMS per board channel, NaN where a frame is missing."""
        if self._complete():                    # frame i: block i // C, channel i % C
            return physical_rms(self.x).reshape(len(self.t0), self.n_channels)
        vals = np.full((len(self.t0), self.n_channels), np.nan, dtype=np.float32)
        vals[self.row, self.chan] = physical_rms(self.x)
        return vals

    def flat_counts(self) -> np.ndarray | None:
        """float32 (B, C): the count of each board channel's block whose samples all are that
        count, NaN where they move or the frame is missing (None: not looked for)."""
        if self.flat is None:
            return None
        if self._complete():
            return self.flat.reshape(len(self.t0), self.n_channels)
        vals = np.full((len(self.t0), self.n_channels), np.nan, dtype=np.float32)
        vals[self.row, self.chan] = self.flat
        return vals

    def samples(self, index: list[int]) -> np.ndarray:
        """float64 (B, block_len, len(index)): the board channels ``index``, NaN where lost;
        of a board with one channel and no frame lost, a read-only view of :attr:`x` (no copy:
        the chains read their samples, none writes them)."""
        L = self.x.shape[1]
        B, C = len(self.t0), self.n_channels
        if index == list(range(C)) and self._complete():   # every channel of every block, in order
            if C == 1:
                y = self.x.reshape(B, L, 1)
                y.flags.writeable = False
                return y
            return self.x.reshape(B, C, L).transpose(0, 2, 1).copy()
        where = np.full(max(self.n_channels, max(index, default=0) + 1), -1)
        where[index] = np.arange(len(index))          # board channel -> column (-1: not asked)
        pos = where[self.chan]
        sel = pos >= 0
        y = np.full((len(self.t0), L, len(index)), np.nan)
        y[self.row[sel], :, pos[sel]] = self.x[sel]
        return y

    def _complete(self) -> bool:
        """Frame i is block i // C, channel i % C (no frame lost, channels in order)."""
        if self._complete_memo is None:
            self._complete_memo = self._check_complete()
        return self._complete_memo

    def _check_complete(self) -> bool:
        C = self.n_channels
        n = len(self.row)
        return n == len(self.t0) * C and bool((self.row == np.arange(n) // C).all()) \
            and bool((self.chan == np.arange(n) % C).all())

    def take(self, a: int, b: int, ordered: bool | None = None) -> RawBlocks:
        """Blocks ``a`` .. ``b - 1`` (their frames' rows renumbered from 0; views where the
        frames are in block order, as the decoder gives them; ``ordered``: whether they are,
        if known)."""
        if a == 0 and b == len(self.t0):
            return self
        row = self.row
        if ordered is None:
            ordered = row.size < 2 or bool((row[1:] >= row[:-1]).all())
        if ordered:
            i, j = row.searchsorted([a, b]).tolist()
            return RawBlocks(self.t0[a:b], row[i:j] - a, self.chan[i:j], self.x[i:j], self.n_channels,
                             None if self.flat is None else self.flat[i:j])
        sel = (row >= a) & (row < b)
        return RawBlocks(self.t0[a:b], row[sel] - a, self.chan[sel], self.x[sel], self.n_channels,
                         None if self.flat is None else self.flat[sel])

    def pieces(self, most: int) -> list[RawBlocks]:
        """The runs of consecutive blocks (:meth:`runs`), each cut into pieces of at most
        ``most`` blocks, in order."""
        row = self.row
        ordered = row.size < 2 or bool((row[1:] >= row[:-1]).all())    # checked once for all pieces
        return [self.take(k, min(b, k + most), ordered) for a, b in self.runs() for k in range(a, b, most)]

    def runs(self) -> list[tuple[int, int]]:
        """(first, end) block rows of the runs of consecutive blocks (lost ones cut them)."""
        if self._runs_memo is None:
            L = self.x.shape[1]
            cuts = (np.flatnonzero(self.t0[1:] - self.t0[:-1] != L) + 1).tolist()
            self._runs_memo = list(zip([0, *cuts], [*cuts, len(self.t0)]))
        return list(self._runs_memo)


class RawInput:
    """RAW frames waiting for a STATUS or the rest of their block (see module docstring)."""

    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.waiting = Pending()        # RAW frames in order (lists, or batches kept as columns)
        self.dropped = 0
        self.strays = 0                 # RAW frames off the block grid dropped (:mod:`.raw_grid`)
        self._calibrated: tuple[Status | None, np.ndarray, np.ndarray] | None = None
        #: look for flat blocks (monitor.flat_signal of any channel)
        self.flat = any(ch.monitor.flat_signal for ch in cfg.channels) if cfg.channels else cfg.monitor.flat_signal

    def add(self, frames: Sequence[Frame]) -> None:
        self.waiting.extend(frames)

    def _overrides_complete(self) -> bool:
        return all(ch.scale is not None and ch.offset is not None for ch in self.cfg.channels)

    def ready(self, status: Status | None, final: bool,
              clock: BlockClock | None = None) -> tuple[Sequence[Frame], int, list[Event]]:
        """The frames that can be converted now and the board's channel count C (with
        ``final``, also the newest block's however many channels came).  With the block
        ``clock``, stray frames off its grid are dropped, each with a ``decode_error`` event at
        its block's stamp (:mod:`.raw_grid`)."""
        grid = None if clock is None else grid_of(clock)
        if not self.waiting:
            return [], 0, []
        frames = self.waiting.joined()
        self.waiting = Pending()
        if status is None and not self._overrides_complete():
            over = len(frames) - RAW_WAIT_FRAMES
            self.waiting.extend(frames[max(over, 0):])
            if over <= 0:
                return [], 0, []
            self.dropped += over
            return [], 0, [Event("decode_error", None, f"{over} RAW frame(s) dropped: no STATUS "
                                 "(scale/offset) from the board yet")]
        cols = frames.cols if type(frames) is FrameBatch else None     # a batch: its columns
        if status is not None:
            C = status.n_channels
        else:
            C = 1 + (int(cols.chan.max()) if cols is not None else max(f.chan for f in frames))
        if not final:
            # the newest block may still be missing channels (its frames can straddle a
            # read or a batch): it waits for a frame of a later block, or for the end
            if cols is not None:
                t0 = cols.t0_unwrapped
                other = np.flatnonzero(t0 != t0[-1])
                k = int(other[-1]) + 1 if other.size else 0
            else:
                last = frames[-1].t0_unwrapped
                k = len(frames)
                while k > 0 and frames[k - 1].t0_unwrapped == last:
                    k -= 1
            if len(frames) - k > 1:             # the newest block: from a channel that came again
                tail = cols.chan[k:].tolist() if cols is not None else list(map(_CHAN, frames[k:]))
                k += block_starts([0] * len(tail), tail)[-1]     # one t0: where a channel came again
            if len(frames) - k >= C:
                k = len(frames)
            held = None if grid is None else hold_from(*self._t0_chan(frames, cols), C, grid)
            if held is not None:                # a block with a frame off the grid waits for its others
                k = held
            if k < len(frames):
                frames, rest = frames[:k], frames[k:]
                self.waiting.extend(rest)
        if grid is None or not frames:
            return frames, C, []
        keep, events = strays(*self._t0_chan(frames, frames.cols if type(frames) is FrameBatch else None),
                              grid, clock.stamp_ns if clock is not None else None)
        if keep is not None:
            self.strays += len(keep) - int(keep.sum())
            frames = frames.take(np.flatnonzero(keep)) if type(frames) is FrameBatch \
                else list(compress(frames, keep.tolist()))
        return frames, C, events

    @staticmethod
    def _t0_chan(frames: Sequence[Frame], cols: Columns | None) -> tuple[np.ndarray, np.ndarray]:
        """The frames' unwrapped t0 and channels as int64 arrays (``cols``: a batch's columns)."""
        if cols is not None:
            return cols.t0_unwrapped, cols.chan
        return (np.fromiter(map(_T0, frames), dtype=np.int64, count=len(frames)),
                np.fromiter(map(_CHAN, frames), dtype=np.int64, count=len(frames)))

    def blocks(self, frames: Sequence[Frame], C: int, L: int, status: Status | None,
               stamp_ns: Callable[[int], int] | None = None) -> tuple[RawBlocks | None, list[Event]]:
        """Frames of ``L`` samples -> :class:`RawBlocks` (a frame of another length or a channel
        >= C is skipped with a decode_error event, stamped at its t0 by ``stamp_ns``).  A batch is
        read from its columns (no frame built): the same blocks."""
        chl: list[int] | None = None           # a list's channels (a batch's are its column)
        if type(frames) is FrameBatch:
            cols = frames.cols
            ok = (cols.chan < C) & (cols.end - cols.start == 2 * L)
            good_batch = frames if ok.all() else frames.take(np.flatnonzero(ok))
            n = len(good_batch)
            t0, chan = good_batch.cols.t0_unwrapped, good_batch.cols.chan
            payloads = good_batch.payloads()
            single = bool((t0[1:] > t0[:-1]).all())
        else:                                   # a live call's few frames: their fields as lists
            chl = list(map(_CHAN, frames))
            good = frames if max(chl, default=0) < C and set(map(len, map(_PAYLOAD, frames))) <= {2 * L} \
                else [f for f in frames if f.chan < C and len(f.payload) == 2 * L]
            if good is not frames:
                chl = list(map(_CHAN, good))
            n, t0l = len(good), list(map(_T0, good))
            t0, chan = np.array(t0l, dtype=np.int64), np.array(chl, dtype=np.int64)
            single = all(map(lt, t0l, t0l[1:]))
            payloads = list(map(_PAYLOAD, good))
        events = []
        if n < len(frames):
            for f in frames:
                if f.chan >= C or len(f.payload) != 2 * L:
                    why = f"channel >= {C}" if f.chan >= C else \
                        f"{len(f.payload)} bytes, not {2 * L} ({L} samples of 2 bytes)"
                    events.append(Event("decode_error", None, f"RAW frame of channel {f.chan} at t0 {f.t0_unwrapped} "
                                        f"skipped: {why}", stamp_ns(f.t0_unwrapped) if stamp_ns else None))
        if not n:
            return None, events
        # uint16 counts (each payload 2 L bytes), read in place: rows_physical converts them
        counts = np.frombuffer(b"".join(payloads), dtype="<u2").reshape(n, L)
        top = counts.max(axis=1)                # per frame: the 12-bit check and the flat blocks'
        if top.max() > COUNT_MAX:               # not 12-bit: a frame the protocol does not allow
            keep = top <= COUNT_MAX
            events += _over_12_bits(counts, t0, chan, keep, stamp_ns)
            counts, t0, chan, top = counts[keep], t0[keep], chan[keep], top[keep]
            n = len(t0)
            if not n:
                return None, events
            single = bool((t0[1:] > t0[:-1]).all())
            chl = None if chl is None else chan.tolist()
        step = None if single else t0[1:] - t0[:-1]
        if step is None:                        # one frame a block, in order (one channel)
            blocks, row = t0.copy(), np.arange(n)
        elif not ((step > 0) | (chan[1:] > chan[:-1])).all() and not (step < 0).any():
            starts = np.array(block_starts(t0.tolist(), chan.tolist()), dtype=np.int64)
            blocks = t0[starts]                 # a channel again under one t0: a block sent again
            row = np.zeros(len(t0), dtype=np.int64)
            row[starts[1:]] = 1
            np.cumsum(row, out=row)
        elif not (step < 0).any():              # in order (as sent): the blocks where t0 steps
            new = np.flatnonzero(step) + 1
            blocks = t0[np.concatenate(([0], new))]
            row = np.zeros(len(t0), dtype=np.int64)
            row[new] = 1
            np.cumsum(row, out=row)
        else:                                   # out of order: a board reset; keep arrival order
            blocks, first, row = np.unique(t0, return_index=True, return_inverse=True)
            order = np.argsort(first)
            blocks = blocks[order]
            row = np.argsort(order)[row]
        scale, offset = self.calibration(status)
        flat = np.where(counts.min(axis=1) == top, top.astype(np.float32), np.nan).astype(np.float32) \
            if self.flat and L >= FLAT_MIN_SAMPLES else None
        out = RawBlocks(blocks, row, chan, rows_physical(counts, scale[chan], offset[chan]), C, flat)
        if single and C == 1:                   # every block's one channel, in order
            out._complete_memo = not (chan.any() if chl is None else any(chl))
        return out, events

    def calibration(self, status: Status | None) -> tuple[np.ndarray, np.ndarray]:
        """Per board channel scale/offset: STATUS, overridden by the configuration (read-only
        arrays, made once per STATUS)."""
        cal = self._calibrated
        if cal is None or cal[0] is not status:
            scale, offset = self._calibration(status)
            scale.flags.writeable = offset.flags.writeable = False
            cal = self._calibrated = (status, scale, offset)
        return cal[1], cal[2]

    def _calibration(self, status: Status | None) -> tuple[np.ndarray, np.ndarray]:
        st = status
        n = max(st.n_channels if st else 0, 1 + max((ch.index for ch in self.cfg.channels), default=0))
        scale = np.ones(n, dtype=np.float32)
        offset = np.zeros(n, dtype=np.float32)
        if st is not None:
            scale[:len(st.scale)] = st.scale
            offset[:len(st.offset)] = st.offset
        for ch in self.cfg.channels:
            if ch.scale is not None:
                scale[ch.index] = ch.scale
            if ch.offset is not None:
                offset[ch.index] = ch.offset
        return scale, offset


def _over_12_bits(counts: np.ndarray, t0: np.ndarray, chan: np.ndarray, keep: np.ndarray,
                  stamp_ns: Callable[[int], int] | None) -> list[Event]:
    """A decode_error for each RAW frame with a count past the ADC's 12 bits (skipped)."""
    return [Event("decode_error", None, f"RAW frame of channel {int(chan[i])} at t0 {int(t0[i])} skipped: count "
                  f"{int(counts[i].max())} past the ADC's 12 bits (0..{COUNT_MAX})",
                  stamp_ns(int(t0[i])) if stamp_ns else None)
            for i in np.flatnonzero(~keep)]


def block_starts(t0: list[int], chan: list[int]) -> list[int]:
    """The first frame of each block of frames in arrival order: a block starts where t0
    changes or where a channel of the block comes again (a block the board sent twice under
    one t0 is two blocks, whether it came in one read or in two)."""
    starts: list[int] = []
    seen: set[int] = set()
    last = None
    for i, (t, c) in enumerate(zip(t0, chan)):
        if t != last or c in seen:
            starts.append(i)
            seen.clear()
            last = t
        seen.add(c)
    return starts
