"""The serial wire protocol, version 1: the streaming decoder, and every name of the protocol.

Owns everything in docs/PROTOCOL.md ("the contract"); the frame layout and the
four payloads (``encode_*``, ``decode_*``, :class:`Frame`, :class:`Status`,
:class:`ProtocolError`) are :mod:`cmsensord.frame_codec`'s and importable from here;
this module implements the receiver rules in :class:`Decoder`:

  - rule 1: hunt for ``A5 5A``; a header with version != 1, an unknown type or
    len > 4096 is not a frame: drop the first sync byte and hunt again;
  - rule 2: wait for the whole frame; on a CRC mismatch drop only the first
    sync byte and hunt again (never skip ``len`` bytes, len may be the bad field);
  - rule 3: a seq gap of g (mod 65536) is g lost frames (``Frame.lost_before``,
    ``LinkCounters.frames_lost``); the first frame has no gap;
  - rule 4: t0 is unwrapped across 2^32 (``Frame.t0_unwrapped``);
  - rule 5: per-link counters (:class:`LinkCounters`).

The decoder is pure computation over bytes: it is fed bytes and returns frames
(the style of pyserial's threaded framers) and never reads a port or a file.
Byte accounting invariant, true after every ``feed``/``flush``::

    bytes_received == bytes in good frames + bytes_discarded + buffered()
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field

import numpy as np

from cmsensord.frame_batch import Columns, FrameBatch, build, scanned_batch, scanned_frames
from cmsensord.frame_codec import (
    _CRC,
    _HDR,
    _TYPE_BY_CODE,
    _TYPE_NAMES,
    _TYPES,
    COUNT_MAX,
    CRC_LEN,
    FLAG_CLIPPED,
    FLAG_OVERRUN,
    HEADER_LEN,
    MAX_BLOCKS_PER_S,
    MAX_FRAME,
    MAX_PAYLOAD,
    MAX_RAW_BLOCK,
    MODE_RAW,
    MODE_RMS,
    OVERHEAD,
    SETUP_FIELDS,
    SYNC,
    VERSION,
    Frame,
    FrameType,
    ProtocolError,
    Status,
    decode_raw,
    decode_rms,
    decode_rms_rows,
    decode_status,
    decode_tacho,
    decode_tacho_many,
    encode_frame,
    encode_raw,
    encode_rms,
    encode_status,
    encode_tacho,
)
from cmsensord.frame_repeats import Repeats
from cmsensord.frame_runs import MIN_BYTES, FrameRuns, run_columns
from cmsensord.wire_scan import WireScanner, have_kernel

__all__ = [
    "SYNC", "VERSION", "HEADER_LEN", "CRC_LEN", "OVERHEAD", "MAX_PAYLOAD", "MAX_FRAME",
    "MAX_RAW_BLOCK", "MAX_BLOCKS_PER_S", "COUNT_MAX", "SETUP_FIELDS",
    "FrameType", "FLAG_OVERRUN", "FLAG_CLIPPED", "MODE_RMS", "MODE_RAW",
    "Frame", "Status", "ProtocolError", "LinkCounters", "Decoder", "iter_frames",
    "encode_frame", "encode_status", "encode_rms", "encode_raw", "encode_tacho",
    "decode_status", "decode_rms", "decode_rms_rows", "decode_raw", "decode_tacho", "decode_tacho_many",
]

# -- Receiving -------------------------------------------------------------

def _zero_frames() -> dict[str, int]:
    return {name: 0 for name in _TYPE_NAMES.values()}


@dataclass
class LinkCounters:
    """Per-link counters (rule 5)."""

    bytes_received: int = 0
    bytes_discarded: int = 0  # while hunting, incl. rejected/bad-CRC sync bytes, and repeated frames
    crc_failures: int = 0
    header_rejects: int = 0  # sync found but version/type/len invalid
    frames: dict[str, int] = field(default_factory=_zero_frames)
    frames_lost: int = 0  # by seq gaps (rule 3)
    overruns: int = 0  # frames carrying FLAG_OVERRUN
    frames_repeated: int = 0  # frames received again, dropped (cmsensord.frame_repeats)

    def as_dict(self) -> dict[str, int]:
        d = {
            "bytes_received": self.bytes_received,
            "bytes_discarded": self.bytes_discarded,
            "crc_failures": self.crc_failures,
            "header_rejects": self.header_rejects,
        }
        for name, count in self.frames.items():
            d[f"frames_{name}"] = count
        d["frames_lost"] = self.frames_lost
        d["overruns"] = self.overruns
        d["frames_repeated"] = self.frames_repeated
        return d


@dataclass(slots=True)
class _Tally:
    """A scan's receiver state (rules 3-4) and what it counted."""

    last_seq: int | None
    last_t0: int
    last_unw: int
    discarded: int = 0
    rejects: int = 0
    crc_fail: int = 0
    lost: int = 0
    overruns: int = 0


class Decoder:
    """Push bytes in, frames out; never reads (pyserial's threaded framer style).

    Holds at most ``max_buffer`` bytes at any time (a large ``feed`` is processed
    in slices). After scanning, what stays buffered is either an incomplete
    candidate frame (< MAX_FRAME bytes) or, if no sync is present, at most the
    last byte when it is 0xA5.  With ``runs`` (the default), a buffer of at least
    :data:`~cmsensord.frame_runs.MIN_BYTES` decodes its runs of good back-to-back
    frames in one pass (:mod:`cmsensord.frame_runs`); ``runs=False`` is the plain
    frame-by-frame receiver, the reference it equals (same frames, same counters).  With
    ``kernel`` (None: when it is built; True: ImportError when it is not;
    :mod:`cmsensord.wire_scan`) the compiled wire kernel scans every buffer, of any size, in
    one call instead: the same frames and counters again (``runs=False`` never uses it).
    :meth:`feed_batch` and :meth:`flush_batch` return the frames of :meth:`feed` and
    :meth:`flush` as a :class:`~cmsensord.frame_batch.FrameBatch` (columns; the same frames
    when indexed or iterated): a replay's RMS frames reach the banks as arrays.
    """

    def __init__(self, max_buffer: int = 65536, runs: bool = True, kernel: bool | None = None):
        if max_buffer < MAX_FRAME:
            raise ValueError(
                f"max_buffer must hold the largest frame ({MAX_FRAME} bytes), got {max_buffer}")
        self.max_buffer = max_buffer
        self.runs = runs  # the one-pass path for runs of back-to-back frames (False: frame by frame)
        use_kernel = runs and (have_kernel() if kernel is None else kernel)   # True without it: ImportError
        self._kernel = WireScanner(VERSION, max(_TYPE_BY_CODE), MAX_PAYLOAD) if use_kernel else None
        self._scanner = self._scan_kernel if use_kernel else self._scan     # for batches
        self._scan_frames = self._kernel_frames if use_kernel else self._scan   # for lists of frames
        self.counters = LinkCounters()
        self._buf = bytearray()
        self._base = 0  # stream offset of self._buf[0]
        self._last_seq: int | None = None
        self._last_t0 = self._last_t0_unwrapped = 0
        self._repeats = Repeats(_make)

    def buffered(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame]:
        frames: list[Frame] = []
        for out, data_ in self._feed(data, self._scan_frames):
            frames += _frames(out, data_)
        return frames

    def feed_batch(self, data: bytes | bytearray | memoryview) -> FrameBatch:
        """:meth:`feed`'s frames as one batch of columns."""
        return FrameBatch.join([_batch(out, data_) for out, data_ in self._feed(data, self._scanner)])

    def flush(self) -> list[Frame]:
        """End of stream: incomplete candidates are not frames (drop their first sync
        byte and hunt on through the rest); whatever is left is discarded."""
        return _frames(*self._scan_once(self._scan_frames, final=True))

    def flush_batch(self) -> FrameBatch:
        """:meth:`flush`'s frames as a batch of columns."""
        return _batch(*self._scan_once(self._scanner, final=True))

    def give_up(self) -> list[Frame]:
        """A stalled link: incomplete candidates (a whole header) are no frames; the frames behind them."""
        frames: list[Frame] = []
        while len(self._buf) >= HEADER_LEN:     # rule 2: its first sync byte dropped, a CRC failure
            self._done(1, _Tally(self._last_seq, self._last_t0, self._last_t0_unwrapped, discarded=1, crc_fail=1))
            frames += self.feed(b"")
        return frames

    def _feed(self, data: bytes | bytearray | memoryview, scan) -> list[tuple[list, bytes]]:
        """The scans of ``data`` appended to the buffer (one, or one per ``max_buffer``)."""
        view = memoryview(data).cast("B")
        total = len(view)
        self.counters.bytes_received += total
        buf = self._buf
        room = self.max_buffer - len(buf)
        if total <= room:  # the common case: one append, one scan
            buf += view
            return [self._scan_once(scan, final=False)]
        scans = []
        start = 0
        while start < total:
            room = self.max_buffer - len(buf)
            buf += view[start:start + room]
            start += room
            scans.append(self._scan_once(scan, final=False))
        return scans

    def _scan_once(self, scan, final: bool) -> tuple[list, bytes]:
        """One scan (``scan``: :meth:`_scan` or :meth:`_scan_kernel`'s forms), the frames the
        link delivered again dropped and counted (:mod:`cmsensord.frame_repeats`)."""
        before, lost = self._last_seq, self.counters.frames_lost
        out, data = scan(final=final)
        rep = self._repeats
        out = rep.take(out, data, before, self._last_seq, self.counters.frames_lost - lost)
        if rep.dropped or rep.lost_removed:
            c = self.counters
            for f in rep.dropped:
                c.frames[_TYPE_NAMES[f.type]] -= 1
                c.overruns -= bool(f.flags & FLAG_OVERRUN)
                c.bytes_discarded += OVERHEAD + len(f.payload)
            c.frames_repeated += len(rep.dropped)
            c.frames_lost -= rep.lost_removed
        return out, data

    def _scan(self, final: bool) -> tuple[list, bytes]:
        """Frame every complete candidate in the buffer (docs/PROTOCOL.md receiver rules 1-3);
        with ``final``, incomplete candidates are dropped byte by byte.  Returns the frames,
        with the columns of each run of good back-to-back frames in their place, and the
        bytes of the buffer the runs' payloads are in.

        The receiver's loop without the compiled kernel (with it, :meth:`_scan_kernel`).
        """
        buf = self._buf
        n = len(buf)
        find = buf.find
        t = _Tally(self._last_seq, self._last_t0, self._last_t0_unwrapped)
        out: list = []      # frames, and the Columns of each run of good frames in its place
        pos = 0
        runs = FrameRuns(bytes(buf), VERSION, len(_TYPE_BY_CODE), MAX_PAYLOAD) if self.runs and n >= MIN_BYTES else None
        with memoryview(buf) as mv:
            while True:
                i = find(SYNC, pos)
                if i < 0:
                    # No sync: keep only a trailing 0xA5 (it may be half a sync).
                    keep = 1 if (not final and n > pos and buf[n - 1] == 0xA5) else 0
                    t.discarded += n - keep - pos
                    pos = n - keep
                    break
                t.discarded += i - pos
                pos = i
                if runs is not None and (run := runs.take(pos)) is not None:
                    # good frames back to back: in one pass (cmsensord/frame_runs.py)
                    cols, t.last_seq, t.last_t0, t.last_unw = run_columns(run, self._base, t.last_seq,
                                                                          t.last_t0, t.last_unw)
                    out.append(cols)
                    self._count_run(cols, t)
                    pos = int(run.end_payload[-1]) + CRC_LEN
                    continue
                step = self._candidate(mv, pos, final, t, out)
                if not step:
                    break   # rule 2: wait for the whole frame
                pos += step
        self._done(pos, t)
        return out, runs.data if runs is not None else b""

    def _candidate(self, mv: memoryview, pos: int, final: bool, t: _Tally, out: list) -> int:
        """The candidate at ``pos`` (a sync): a good frame is appended to ``out`` and its length
        returned; 0 while it is incomplete and more may come; else 1 (not a frame: its first sync
        byte is dropped, and counted in ``t``)."""
        buf = self._buf
        n = len(buf)
        if n - pos >= HEADER_LEN:
            ver, code, seq, t0, chan, flags, ln = _HDR.unpack_from(buf, pos + 2)
            ftype = _TYPE_BY_CODE.get(code) if (ver == VERSION and ln <= MAX_PAYLOAD) else None
            end_payload = pos + HEADER_LEN + ln
            if ftype is None:  # rule 1
                t.rejects += 1
            elif end_payload + CRC_LEN > n:
                if not final:
                    return 0    # (at the end: not a frame)
            elif zlib.crc32(mv[pos + 2:end_payload]) != _CRC.unpack_from(buf, end_payload)[0]:
                t.crc_fail += 1  # rule 2: drop only the first sync byte
            else:
                if t.last_seq is None:
                    lost, unw = 0, t0
                else:
                    lost = (seq - t.last_seq - 1) & 0xFFFF  # rule 3
                    unw = t.last_unw + (((t0 - t.last_t0 + 0x80000000) & 0xFFFFFFFF) - 0x80000000)
                t.last_seq, t.last_t0, t.last_unw = seq, t0, unw
                t.lost += lost
                t.overruns += bool(flags & FLAG_OVERRUN)
                self.counters.frames[_TYPE_NAMES[ftype]] += 1
                out.append(tuple.__new__(Frame, (ftype, seq, t0, chan, flags, bytes(mv[pos + HEADER_LEN:end_payload]),
                                                 unw, self._base + pos, lost)))
                return end_payload + CRC_LEN - pos
        elif not final:
            return 0
        t.discarded += 1
        return 1

    def _count_run(self, cols: Columns, t: _Tally) -> None:
        """A run's frames counted by type; its lost frames and overruns added to ``t``."""
        counts = self.counters.frames
        for code, k in enumerate(np.bincount(cols.code).tolist()):
            if k:
                counts[_TYPE_NAMES[_TYPE_BY_CODE[code]]] += k
        t.lost += int(cols.lost.sum())
        t.overruns += int(np.count_nonzero(cols.flags & FLAG_OVERRUN))

    def _kernel_frames(self, final: bool) -> tuple[list, bytes]:
        """:meth:`_scan_kernel` with the frames made by the kernel, as :meth:`_scan` returns them."""
        return self._scan_kernel(final, (Frame, _TYPES))

    def _scan_kernel(self, final: bool, make: tuple[type, tuple] | None = None) -> tuple[list, bytes]:
        """:meth:`_scan` in one call of the compiled wire kernel: the good frames as one
        :class:`~cmsensord.frame_batch.Columns` over the bytes scanned (``make``: as frames)."""
        assert self._kernel is not None
        buf = self._buf
        r = self._kernel.scan(buf, final, self._base, self._last_seq, self._last_t0, self._last_t0_unwrapped,
                              make)
        found, data = r.frames, b""
        if isinstance(found, Columns):          # their payloads: in the bytes scanned
            with memoryview(buf) as mv:
                data = bytes(mv[:r.consumed])
        counts = self.counters.frames
        for code, k in enumerate(r.by_code):
            if k:
                counts[_TYPE_NAMES[_TYPE_BY_CODE[code]]] += k
        self._done(r.consumed, _Tally(r.last_seq, r.last_t0, r.last_unw, r.discarded, r.header_rejects,
                                      r.crc_failures, r.lost, r.overruns))
        if isinstance(found, Columns):
            return [found], data
        return found or [], data

    def _done(self, pos: int, t: _Tally) -> None:
        """A scan's end: its ``pos`` bytes leave the buffer; the receiver's state and counters."""
        if pos:
            del self._buf[:pos]
        self._base += pos
        self._last_seq, self._last_t0, self._last_t0_unwrapped = t.last_seq, t.last_t0, t.last_unw
        c = self.counters
        c.bytes_discarded += t.discarded
        c.header_rejects += t.rejects
        c.crc_failures += t.crc_fail
        c.frames_lost += t.lost
        c.overruns += t.overruns


def _make(cols: Columns, data: bytes) -> list[Frame]:
    return build(cols, data, Frame, _TYPE_BY_CODE)


def _frames(out: list, data: bytes) -> list[Frame]:
    return scanned_frames(out, data, _make)


def _batch(out: list, data: bytes) -> FrameBatch:
    return scanned_batch(out, data, _make)


def iter_frames(data: bytes | bytearray | memoryview,
                max_buffer: int = 65536) -> tuple[list[Frame], LinkCounters]:
    """Decode a whole capture (feed + flush): all frames and the link counters."""
    dec = Decoder(max_buffer=max_buffer)
    frames = dec.feed(data)
    frames += dec.flush()
    return frames, dec.counters
