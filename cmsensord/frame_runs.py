"""Runs of back-to-back frames in a receive buffer, checked and parsed in one numpy pass.

The receiver's fast path (:class:`cmsensord.protocol.Decoder`): in a healthy stream
every frame starts where the previous one ended, so instead of hunting, unpacking
and checking frame by frame in Python, :class:`FrameRuns` finds every candidate of
a buffer at once (sync ``A5 5A``, version 1, a known type, len <= 4096, complete)
and, from a candidate, follows the chain of candidates that start where the one
before ends.  :meth:`FrameRuns.take` returns the longest prefix of that chain whose
CRCs match (each frame's CRC checked on its own bytes, as docs/PROTOCOL.md rule 2
says) with their header fields as arrays; the first frame that is not a good
frame ends the run, and the decoder's frame-by-frame loop handles those bytes
exactly as before.  So the frames, byte offsets and counters are the same as
without it; only the Python work per frame is less.
"""

from __future__ import annotations

import zlib
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from cmsensord.frame_batch import Columns

__all__ = ["FrameRuns", "RunFields", "MIN_BYTES", "run_columns"]

#: buffers shorter than this are left to the frame-by-frame loop (the numpy pass costs
#: tens of microseconds: worth it for a replay's 64-KiB reads, not for a few live frames)
MIN_BYTES = 8192

_HEADER = 14
_OVERHEAD = 18

IntArray = npt.NDArray[np.int64]


class RunFields(NamedTuple):
    """The header fields of a run of good frames (one entry per frame, in stream order)."""

    pos: IntArray       # buffer offset of each frame's sync
    code: IntArray      # type code
    seq: IntArray
    t0: IntArray
    chan: IntArray
    flags: IntArray
    end_payload: IntArray   # buffer offset of each frame's CRC


def _every_offset(data: bytes, dtype: str) -> np.ndarray:
    """The little-endian integers of ``dtype`` starting at every byte offset of ``data`` (a
    read-only strided view: element i is bytes i .. i + size - 1)."""
    size = np.dtype(dtype).itemsize
    if len(data) < size:
        return np.empty(0, dtype=dtype)
    return np.ndarray((len(data) - size + 1,), dtype=dtype, buffer=data, strides=(1,))


class FrameRuns:
    """The candidate frames of ``data`` (a snapshot of the decoder's buffer), found once."""

    def __init__(self, data: bytes, version: int, max_type: int, max_payload: int):
        self.data = data
        a = np.frombuffer(data, dtype=np.uint8)
        n = a.size
        p = np.flatnonzero((a[:-1] == 0xA5) & (a[1:] == 0x5A)) if n >= 2 else np.empty(0, dtype=np.int64)
        p = p[p + _HEADER <= n]
        u16, u32 = _every_offset(data, "<u2"), _every_offset(data, "<u4")   # a field at any byte offset
        ver, code = a[p + 2].astype(np.int64), a[p + 3].astype(np.int64)
        ln = u16[p + 12].astype(np.int64)
        good = (ver == version) & (code >= 1) & (code <= max_type) & (ln <= max_payload) \
            & (p + _OVERHEAD + ln <= n)
        self.pos = p = p[good]
        self.code = code[good]
        self.seq = u16[p + 4].astype(np.int64)
        self.t0 = u32[p + 6].astype(np.int64)
        self.chan = a[p + 10].astype(np.int64)
        self.flags = a[p + 11].astype(np.int64)
        self.end_payload = p + _HEADER + ln[good]
        end = self.end_payload + 4
        j = np.searchsorted(p, end)
        jj = np.minimum(j, max(p.size - 1, 0))
        hit = (j < p.size) & (p[jj] == end) if p.size else np.zeros(0, dtype=bool)
        nxt = np.where(hit, j, -1)                  # the candidate starting where one ends
        self._next = nxt.tolist()
        self._breaks = np.flatnonzero(nxt != np.arange(1, nxt.size + 1))  # chains leave c -> c + 1 there
        self._crc = u32[end - 4].astype(np.int64)
        self._pos = self.pos.tolist()
        self._body = (self.pos + 2).tolist()                # each frame's CRC covers body .. endp
        self._endp = self.end_payload.tolist()

    def take(self, start: int) -> RunFields | None:
        """The good frames back to back from buffer offset ``start`` (None when there is
        no good frame there): the chain of candidates, up to the first bad CRC."""
        c = int(np.searchsorted(self.pos, start))
        pos = self._pos
        if c >= len(pos) or pos[c] != start:
            return None
        nxt, breaks, data = self._next, self._breaks, self.data
        get, crc32 = data.__getitem__, zlib.crc32
        spans = []
        while c >= 0:   # the chain goes c, c + 1, ... up to a break, then jumps (or ends)
            e = int(breaks[np.searchsorted(breaks, c)]) + 1
            crcs = np.fromiter(map(crc32, map(get, map(slice, self._body[c:e], self._endp[c:e]))),
                               dtype=np.int64, count=e - c)
            bad = np.flatnonzero(crcs != self._crc[c:e])
            if bad.size:
                spans.append(np.arange(c, c + int(bad[0])))
                break
            spans.append(np.arange(c, e))
            c = nxt[e - 1]
        k = np.concatenate(spans)
        if not k.size:
            return None
        return RunFields(self.pos[k], self.code[k], self.seq[k], self.t0[k], self.chan[k], self.flags[k],
                         self.end_payload[k])


def run_columns(run: RunFields, base: int, last_seq: int | None, last_t0: int,
                last_unw: int) -> tuple[Columns, int, int, int]:
    """The columns of a run of good back-to-back frames (receiver rules 3 and 4 as in the
    frame-by-frame loop: seq gaps, t0 unwrapped), and the new last seq, t0, unwrapped t0."""
    seq, t0 = run.seq, run.t0
    lost = np.empty(seq.size, dtype=np.int64)
    lost[1:] = (seq[1:] - seq[:-1] - 1) & 0xFFFF
    step = np.empty(seq.size, dtype=np.int64)
    step[1:] = ((t0[1:] - t0[:-1] + 0x80000000) & 0xFFFFFFFF) - 0x80000000
    if last_seq is None:
        lost[0] = 0
        first = int(t0[0])
    else:
        lost[0] = (int(seq[0]) - last_seq - 1) & 0xFFFF
        first = last_unw + (((int(t0[0]) - last_t0 + 0x80000000) & 0xFFFFFFFF) - 0x80000000)
    step[0] = first
    unw = np.cumsum(step)
    cols = Columns(run.code, seq, t0, run.chan, run.flags, run.pos + _HEADER, run.end_payload, unw,
                   run.pos + base, lost)
    return cols, int(seq[-1]), int(t0[-1]), int(unw[-1])
