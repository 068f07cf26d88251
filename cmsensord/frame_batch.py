"""Decoded frames kept as columns: a batch of frames without a Python object per frame.

A replay decodes ~10^5 frames a second; most are RMS frames whose few fields the
Processor reads as arrays anyway (t0, the channel count, the values).  A
:class:`FrameBatch` holds the frames of one receive buffer as numpy columns (type
code, seq, t0, chan, flags, unwrapped t0, stream offset, seq gap) and the buffer's
bytes, with each frame's payload as a slice of them.  It is a ``Sequence[Frame]``:
indexing, iterating or comparing builds the very :class:`~cmsensord.protocol.Frame`
tuples the frame-by-frame decoder makes, so any consumer may take it as a list of
frames; a slice is a view of the same columns (a range, sliced when read).  What reads
columns (:meth:`~FrameBatch.columns`, :meth:`~FrameBatch.rms_values`, :func:`rms_fields`)
never builds a frame.

:class:`Pending` is the Processor's waiting batch: the parts it was extended with,
joined when it is processed (one batch when every part is one, else a list).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from itertools import compress, repeat
from operator import attrgetter
from typing import Any, NamedTuple, cast, overload

import numpy as np

__all__ = ["Columns", "FrameBatch", "Pending", "rms_fields", "build", "select", "scanned_frames", "scanned_batch"]

#: the fields of a frame as columns, in the order of :class:`~cmsensord.protocol.Frame`'s
#: fields (``start``/``end``: the payload's bytes in the buffer instead of the payload)
_FIELDS = ("code", "seq", "t0", "chan", "flags", "start", "end", "t0_unwrapped", "offset", "lost")


class Columns(NamedTuple):
    """One int64 array per field, one entry per frame (stream order)."""

    code: np.ndarray
    seq: np.ndarray
    t0: np.ndarray
    chan: np.ndarray
    flags: np.ndarray
    start: np.ndarray           # buffer offset of the payload
    end: np.ndarray             # buffer offset just after it (of the CRC)
    t0_unwrapped: np.ndarray
    offset: np.ndarray          # stream offset of the frame's sync
    lost: np.ndarray            # frames lost by seq gap in front of it

    def take(self, key: slice | np.ndarray) -> Columns:
        return Columns(*(a[key] for a in self))

    @staticmethod
    def join(parts: Sequence[Columns]) -> Columns:
        return Columns(*(np.concatenate(a) for a in zip(*parts)))


_FRAME_FIELDS = attrgetter("type", "seq", "t0", "chan", "flags", "t0_unwrapped", "offset", "lost_before")
_PAYLOAD = attrgetter("payload")


def _shift(cols: Columns, by: int) -> Columns:
    return cols._replace(start=cols.start + by, end=cols.end + by) if by else cols


class FrameBatch(Sequence):
    """Frames as columns over the bytes ``data`` of their receive buffer (see module docstring).

    ``make(cols, data)``: the frames of columns (the decoder's, passed in so that this module
    needs nothing of the protocol's: :func:`build` with its Frame class and type codes).
    """

    __slots__ = ("data", "_make", "_frames", "_base", "_lo", "_hi", "_cols")

    def __init__(self, cols: Columns, data: bytes, make):
        self.data, self._make = data, make
        self._frames: list | None = None
        self._base, self._lo, self._hi = cols, 0, len(cols.code)   # a view: base[lo:hi]
        self._cols: Columns | None = cols

    def _view(self, lo: int, hi: int) -> FrameBatch:
        """Frames lo .. hi - 1 of the base columns (sliced when read)."""
        view = FrameBatch.__new__(FrameBatch)
        view.data, view._make, view._frames = self.data, self._make, None
        view._base, view._lo, view._hi, view._cols = self._base, lo, hi, None
        return view

    @property
    def cols(self) -> Columns:
        """The frames' columns."""
        if self._cols is None:
            lo, hi = self._lo, self._hi
            self._cols = Columns(*(a[lo:hi] for a in self._base))
        return self._cols

    @classmethod
    def of(cls, frames: Sequence[Any], make) -> FrameBatch:
        """A batch of frames made by hand or by the frame-by-frame receiver (their payloads
        joined into the batch's bytes)."""
        n = len(frames)
        if not n:
            return cls(Columns(*(np.empty(0, dtype=np.int64) for _ in _FIELDS)), b"", make)
        code, seq, t0, chan, flags, unw, offset, lost = (np.array(c, dtype=np.int64)
                                                        for c in zip(*map(_FRAME_FIELDS, frames)))
        payloads = list(map(_PAYLOAD, frames))
        end = np.cumsum(np.fromiter(map(len, payloads), dtype=np.int64, count=n))
        start = np.empty_like(end)
        start[0] = 0
        start[1:] = end[:-1]
        batch = cls(Columns(code, seq, t0, chan, flags, start, end, unw, offset, lost), b"".join(payloads), make)
        batch._frames = list(frames)
        return batch

    @classmethod
    def join(cls, batches: Sequence[FrameBatch]) -> FrameBatch:
        """The frames of ``batches`` in order, as one batch (their bytes joined when they are
        not all of one buffer)."""
        if len(batches) == 1:
            return batches[0]
        first = batches[0]
        if all(b._base is first._base and b.data is first.data for b in batches):   # views of one batch
            if all(a._hi == b._lo for a, b in zip(batches, batches[1:])):
                return first._view(first._lo, batches[-1]._hi)
            idx = np.concatenate([np.arange(b._lo, b._hi) for b in batches])
            return cls(first._base.take(idx), first.data, first._make)
        blobs: list[bytes] = []
        at: dict[int, int] = {}
        cols = []
        size = 0
        for b in batches:
            where = at.get(id(b.data))
            if where is None:
                where = at[id(b.data)] = size
                blobs.append(b.data)
                size += len(b.data)
            cols.append(_shift(b.cols, where))
        data = blobs[0] if len(blobs) == 1 else b"".join(blobs)
        return cls(Columns.join(cols), data, batches[0]._make)

    def __len__(self) -> int:
        return self._hi - self._lo

    @overload
    def __getitem__(self, key: int) -> Any: ...
    @overload
    def __getitem__(self, key: slice) -> FrameBatch: ...

    def __getitem__(self, key):
        if isinstance(key, slice):
            start, stop, step = key.indices(len(self))
            if step != 1:
                return self.frames()[key]
            return self._view(self._lo + start, self._lo + max(start, stop))
        if self._frames is not None:
            return self._frames[key]
        n = len(self)
        if not -n <= key < n:
            raise IndexError("frame index out of range")
        i = self._lo + key % n
        return self._make(Columns(*(a[i:i + 1] for a in self._base)), self.data)[0]

    def __iter__(self) -> Iterator:
        return iter(self.frames())

    def __eq__(self, other: object) -> bool:
        if isinstance(other, FrameBatch | list | tuple):
            return self.frames() == list(other)
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def frames(self) -> list:
        """The frames as :class:`~cmsensord.protocol.Frame` tuples (built once)."""
        if self._frames is None:
            self._frames = self._make(self.cols, self.data)
        return self._frames

    def take(self, idx: np.ndarray) -> FrameBatch:
        """The frames at positions ``idx`` (ascending), as a batch of their columns (no frame
        is built)."""
        return FrameBatch(self.cols.take(idx), self.data, self._make)

    def payloads(self) -> list[bytes]:
        """Each frame's payload (the bytes a built frame would hold), without building the frames."""
        c = self.cols
        return list(map(self.data.__getitem__, map(slice, c.start.tolist(), c.end.tolist())))

    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(type codes, unwrapped t0, whether a break in the link is in front) of the frames: a
        seq gap, or repeats the receiver dropped (flags above the wire's eight bits)."""
        c = self.cols
        return c.code, c.t0_unwrapped, (c.lost != 0) | (c.flags > 0xFF)

    def payload_lengths(self) -> np.ndarray:
        return self.cols.end - self.cols.start

    def rms_values(self, n_channels: int) -> np.ndarray:
        """float32 (len, n_channels), m/s^2: the payloads of RMS frames of ``n_channels``
        channels each (the caller checked their lengths), as ``decode_rms_rows`` reads them."""
        width = 4 * n_channels
        a = np.frombuffer(self.data, dtype=np.uint8)
        rows = a[self.cols.start[:, None] + np.arange(width)]
        return rows.view("<f4").reshape(len(self), n_channels).astype(np.float32)


class Pending:
    """The parts (sequences of frames) a batch waiting to be processed was extended with."""

    __slots__ = ("parts", "n")

    def __init__(self) -> None:
        self.parts: list[Sequence] = []
        self.n = 0

    def __len__(self) -> int:
        return self.n

    def extend(self, frames: Sequence) -> None:
        if len(frames):
            self.parts.append(frames)
            self.n += len(frames)

    def joined(self) -> Sequence:
        """The frames in order: one :class:`FrameBatch` when every part is one, else a list."""
        parts = self.parts
        if len(parts) == 1:
            return parts[0]
        if parts and all(type(p) is FrameBatch for p in parts):
            return FrameBatch.join(cast(list[FrameBatch], parts))
        out: list = []
        for p in parts:
            out += p
        return out


def rms_fields(frames: Sequence[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(channel count, payload length, unwrapped t0) of each frame, as arrays: a batch's
    columns, or one C-level pass per field over a list of frames."""
    if type(frames) is FrameBatch:
        c = frames.cols
        return c.chan, c.end - c.start, c.t0_unwrapped
    n = len(frames)
    return (np.fromiter(map(attrgetter("chan"), frames), dtype=np.int64, count=n),
            np.fromiter(map(len, map(_PAYLOAD, frames)), dtype=np.int64, count=n),
            np.fromiter(map(attrgetter("t0_unwrapped"), frames), dtype=np.int64, count=n))


def build(cols: Columns, data: bytes, frame_cls: type, types: dict) -> list:
    """The frames of ``cols`` over ``data`` as tuples of ``frame_cls`` (type codes mapped by
    ``types``, payloads sliced out of ``data``)."""
    payloads = list(map(data.__getitem__, map(slice, cols.start.tolist(), cols.end.tolist())))
    return list(map(tuple.__new__, repeat(frame_cls), zip(
        map(types.__getitem__, cols.code.tolist()), cols.seq.tolist(), cols.t0.tolist(), cols.chan.tolist(),
        cols.flags.tolist(), payloads, cols.t0_unwrapped.tolist(), cols.offset.tolist(), cols.lost.tolist())))


def select(frames: Sequence[Any], mask: np.ndarray) -> Sequence[Any]:
    """The frames where ``mask``: a batch's columns taken (no frame built), else a list."""
    if type(frames) is FrameBatch:
        return frames if mask.all() else frames.take(np.flatnonzero(mask))
    return list(compress(frames, mask.tolist()))


def scanned_frames(out: list, data: bytes, make) -> list:
    """The frames and run columns of one decoder scan (in stream order) as a list of frames (the
    columns' payloads in ``data``, the scanned buffer; ``make`` as for :class:`FrameBatch`)."""
    if not data:                        # no columns: frames only
        return out
    frames: list = []
    for item in out:
        if type(item) is Columns:
            frames += make(item, data)
        else:
            frames.append(item)
    return frames


def scanned_batch(out: list, data: bytes, make) -> FrameBatch:
    """The frames and run columns of one decoder scan (in stream order) as one batch (the
    columns' payloads in ``data``, the scanned buffer)."""
    parts: list[FrameBatch] = []
    singles: list = []
    for item in out:
        if type(item) is Columns:
            if singles:
                parts.append(FrameBatch.of(singles, make))
                singles = []
            parts.append(FrameBatch(item, data, make))
        else:
            singles.append(item)
    if singles or not parts:
        parts.append(FrameBatch.of(singles, make))
    return FrameBatch.join(parts)
