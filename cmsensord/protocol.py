"""The serial wire protocol, version 1: frame encoding and the streaming decoder.

Owns everything in docs/PROTOCOL.md ("the contract"):

* the frame layout (sync ``A5 5A``, 14-byte header, payload, CRC-32 of bytes
  2 .. 14+len-1 stored little-endian) and the four payloads (STATUS, RMS, RAW,
  TACHO): ``encode_*`` build complete frames (shared with ``firmware_sim``),
  ``decode_*`` parse payloads and raise :class:`ProtocolError` naming the
  expected vs the received length;
* the receiver rules, implemented by :class:`Decoder`:

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

import enum
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from cmsensord.frame_batch import Columns, FrameBatch, build, scanned_batch, scanned_frames
from cmsensord.frame_repeats import Repeats
from cmsensord.frame_runs import MIN_BYTES, FrameRuns, run_columns
from cmsensord.wire_scan import WireScanner, have_kernel

__all__ = [
    "SYNC", "VERSION", "HEADER_LEN", "CRC_LEN", "OVERHEAD", "MAX_PAYLOAD", "MAX_FRAME",
    "FrameType", "FLAG_OVERRUN", "FLAG_CLIPPED", "MODE_RMS", "MODE_RAW",
    "Frame", "Status", "ProtocolError", "LinkCounters", "Decoder", "iter_frames",
    "encode_frame", "encode_status", "encode_rms", "encode_raw", "encode_tacho",
    "decode_status", "decode_rms", "decode_raw", "decode_tacho", "decode_tacho_many",
]

SYNC = b"\xa5\x5a"
VERSION = 1
HEADER_LEN = 14
CRC_LEN = 4
OVERHEAD = HEADER_LEN + CRC_LEN  # 18
MAX_PAYLOAD = 4096
MAX_RAW_BLOCK = MAX_PAYLOAD // 2  # u16 counts in one RAW payload
MAX_BLOCKS_PER_S = 100_000  # fs / block_len the daemon takes (its buffers follow it; the board: 100)
MAX_FRAME = OVERHEAD + MAX_PAYLOAD  # 4114, the largest frame the decoder must hold

FLAG_OVERRUN = 0x01  # ADC overrun since the previous frame
FLAG_CLIPPED = 0x02  # a sample of this block clipped (0 or 4095)
COUNT_MAX = 4095  # the largest RAW count: the ADC's 12 bits

MODE_RMS, MODE_RAW = 1, 2


class FrameType(enum.IntEnum):
    STATUS = 1
    RMS = 2
    RAW = 3
    TACHO = 4


class ProtocolError(ValueError):
    """A malformed payload (wrong length for its type) or an unencodable value."""


# Header after the sync: version u8, type u8, seq u16, t0 u32, chan u8, flags u8, len u16.
_HDR = struct.Struct("<BBHIBBH")
_CRC = struct.Struct("<I")
_FRAME_HEAD = struct.Struct("<2sBBHIBBH")  # sync + header, for encoding
# STATUS fixed part: fw u16, mode u8, C u8, fs u32, block_len u16, tacho u8, ppr u8,
# overruns u32, uptime u32 (20 bytes), then C x (scale f32, offset f32).
_STATUS = struct.Struct("<HBBIHBBII")
_U16 = struct.Struct("<H")

_TYPE_BY_CODE = {int(t): t for t in FrameType}
_TYPES = tuple(map(_TYPE_BY_CODE.get, range(max(_TYPE_BY_CODE) + 1)))   # by code (the wire kernel's)
_TYPE_NAMES = {t: t.name.lower() for t in FrameType}


class _FrameFields(NamedTuple):
    type: FrameType
    seq: int  # u16 as on the wire
    t0: int  # u32 as on the wire
    chan: int
    flags: int
    payload: bytes
    t0_unwrapped: int  # set by the Decoder (rule 4); defaults to t0 for frames built by hand
    offset: int  # stream byte offset of the frame's first sync byte (Decoder); -1 if built by hand
    lost_before: int  # frames lost by seq gap just before this frame (rule 3)


class Frame(_FrameFields):
    """One frame as on the wire, plus what the decoder derived (rules 3 and 4).

    An immutable named tuple: the decoder makes one per frame, ~10^5 a second
    in a replay, and a tuple costs a quarter of what a frozen dataclass does.
    """

    __slots__ = ()

    def __new__(cls, type: FrameType, seq: int, t0: int, chan: int, flags: int, payload: bytes,
                t0_unwrapped: int | None = None, offset: int = -1, lost_before: int = 0) -> Frame:
        return tuple.__new__(cls, (type, seq, t0, chan, flags, payload,
                                   t0 if t0_unwrapped is None else t0_unwrapped, offset, lost_before))


#: the STATUS fields that describe the board's set-up (its time base, channels, mode and tacho)
SETUP_FIELDS = ("fs", "block_len", "n_channels", "mode", "tacho_inputs", "tacho_ppr")


@dataclass(frozen=True, slots=True)
class Status:
    """STATUS payload fields (docs/PROTOCOL.md, STATUS)."""

    fw_version: int  # major << 8 | minor
    mode: int  # MODE_RMS or MODE_RAW
    n_channels: int
    fs: int
    block_len: int
    tacho_inputs: int
    tacho_ppr: int
    overruns: int
    uptime_s: int
    scale: tuple[float, ...]  # m/s^2 per count, one per channel
    offset: tuple[float, ...]  # counts at 0 m/s^2, one per channel


# -- Encoding --------------------------------------------------------------

def encode_frame(ftype: int, seq: int, t0: int, chan: int, flags: int, payload: bytes) -> bytes:
    """A complete frame (sync .. crc). seq is masked to u16 and t0 to u32."""
    n = len(payload)
    if n > MAX_PAYLOAD:
        raise ProtocolError(f"payload of {n} bytes exceeds the maximum of {MAX_PAYLOAD}")
    if not 0 <= chan <= 0xFF:
        raise ProtocolError(f"chan must fit in u8 (0..255), got {chan}")
    if not 0 <= flags <= 0xFF:
        raise ProtocolError(f"flags must fit in u8 (0..255), got {flags}")
    ftype = FrameType(ftype)  # ValueError for an unknown type
    head = _FRAME_HEAD.pack(SYNC, VERSION, ftype, seq & 0xFFFF, t0 & 0xFFFFFFFF, chan, flags, n)
    body = head[2:] + bytes(payload)
    return SYNC + body + _CRC.pack(zlib.crc32(body))


def encode_status(seq: int, t0: int, status: Status, flags: int = 0) -> bytes:
    c = status.n_channels
    if len(status.scale) != c or len(status.offset) != c:
        raise ProtocolError(
            f"STATUS needs n_channels={c} scale and offset values, "
            f"got {len(status.scale)} scale and {len(status.offset)} offset"
        )
    fixed = _STATUS.pack(
        status.fw_version, status.mode, c, status.fs, status.block_len,
        status.tacho_inputs, status.tacho_ppr,
        status.overruns & 0xFFFFFFFF, status.uptime_s & 0xFFFFFFFF,
    )
    per_chan = np.empty((c, 2), dtype="<f4")
    per_chan[:, 0] = status.scale
    per_chan[:, 1] = status.offset
    return encode_frame(FrameType.STATUS, seq, t0, 0, flags, fixed + per_chan.tobytes())


def encode_rms(seq: int, t0: int, rms: Sequence[float] | np.ndarray, flags: int = 0) -> bytes:
    """RMS frame; chan = number of channels, payload C x f32."""
    values = np.asarray(rms, dtype="<f4")
    if values.ndim != 1:
        raise ProtocolError(f"RMS values must be 1-D (one per channel), got shape {values.shape}")
    return encode_frame(FrameType.RMS, seq, t0, values.size, flags, values.tobytes())


def encode_raw(seq: int, t0: int, chan: int, counts: np.ndarray, flags: int = 0) -> bytes:
    """RAW frame; payload block_len x u16 counts."""
    a = np.asarray(counts)
    if a.ndim != 1:
        raise ProtocolError(f"RAW counts must be 1-D, got shape {a.shape}")
    if a.size and a.dtype.kind not in "iub":
        raise ProtocolError(f"RAW counts must be integers, got dtype {a.dtype}")
    if a.size and (int(a.min()) < 0 or int(a.max()) > 0xFFFF):
        raise ProtocolError(f"RAW counts must fit in u16, got range {a.min()}..{a.max()}")
    return encode_frame(FrameType.RAW, seq, t0, chan, flags, a.astype("<u2").tobytes())


def encode_tacho(seq: int, t0: int, chan: int, edges: Sequence[int] | np.ndarray,
                 flags: int = 0) -> bytes:
    """TACHO frame; payload u16 N then N x u32 edge offsets from t0 in 1/256 sample."""
    a = np.asarray(edges)
    if a.ndim != 1:
        raise ProtocolError(f"TACHO edges must be 1-D, got shape {a.shape}")
    if a.size and a.dtype.kind not in "iu":
        raise ProtocolError(f"TACHO edges must be integers (1/256 sample), got dtype {a.dtype}")
    if a.size and (int(a.min()) < 0 or int(a.max()) > 0xFFFFFFFF):
        raise ProtocolError(f"TACHO edges must fit in u32, got range {a.min()}..{a.max()}")
    payload = _U16.pack(a.size) + a.astype("<u4").tobytes()
    return encode_frame(FrameType.TACHO, seq, t0, chan, flags, payload)


# -- Payload decoding ------------------------------------------------------

def decode_status(payload: bytes) -> Status:
    n = len(payload)
    if n < _STATUS.size:
        raise ProtocolError(
            f"STATUS payload: expected at least {_STATUS.size} bytes, got {n}")
    fw, mode, c, fs, block_len, tacho, ppr, overruns, uptime = _STATUS.unpack_from(payload)
    expected = _STATUS.size + 8 * c
    if n != expected:
        raise ProtocolError(
            f"STATUS payload: expected {expected} bytes (20 + 8 x {c} channels), got {n}")
    per_chan = struct.unpack_from(f"<{2 * c}f", payload, _STATUS.size)   # float32 -> Python floats
    return Status(
        fw_version=fw, mode=mode, n_channels=c, fs=fs, block_len=block_len,
        tacho_inputs=tacho, tacho_ppr=ppr, overruns=overruns, uptime_s=uptime,
        scale=per_chan[0::2],
        offset=per_chan[1::2],
    )


def decode_rms(frame: Frame) -> np.ndarray:
    """float32 array of shape (frame.chan,), m/s^2."""
    n = len(frame.payload)
    expected = 4 * frame.chan
    if n != expected:
        raise ProtocolError(
            f"RMS payload: expected {expected} bytes (4 x {frame.chan} channels), got {n}")
    return np.frombuffer(frame.payload, dtype="<f4").astype(np.float32)


def decode_rms_rows(frames: Sequence[Frame], n_channels: int) -> np.ndarray:
    """float32 array (len(frames), n_channels), m/s^2: the RMS frames of one channel count in
    one pass (:func:`decode_rms` of each, stacked)."""
    expected = 4 * n_channels
    batch = frames if type(frames) is FrameBatch else None      # the payloads are in the batch's bytes
    payloads = [] if batch is not None else [f.payload for f in frames]
    lengths = set(batch.payload_lengths().tolist() if batch is not None else map(len, payloads))
    if lengths - {expected}:
        raise ProtocolError(f"RMS payload: expected {expected} bytes (4 x {n_channels} channels), "
                            f"got {max(lengths - {expected})}")
    if batch is not None:
        return batch.rms_values(n_channels)
    rows = np.frombuffer(b"".join(payloads), dtype="<f4")
    return rows.reshape(len(frames), n_channels).astype(np.float32)


def decode_raw(payload: bytes) -> np.ndarray:
    """uint16 ADC counts."""
    n = len(payload)
    if n % 2:
        raise ProtocolError(
            f"RAW payload: expected an even number of bytes (2 per sample), got {n}")
    return np.frombuffer(payload, dtype="<u2").astype(np.uint16)


def decode_tacho(payload: bytes) -> np.ndarray:
    """uint32 edge offsets from t0 in 1/256 sample."""
    n = len(payload)
    if n < 2:
        raise ProtocolError(f"TACHO payload: expected at least 2 bytes (u16 N), got {n}")
    (count,) = _U16.unpack_from(payload)
    expected = 2 + 4 * count
    if n != expected:
        raise ProtocolError(
            f"TACHO payload: expected {expected} bytes (2 + 4 x N={count} edges), got {n}")
    return np.frombuffer(payload, dtype="<u4", offset=2).astype(np.uint32)


def decode_tacho_many(payloads: Sequence[bytes]) -> tuple[np.ndarray, np.ndarray, list[tuple[int, str]]]:
    """The TACHO payloads of many frames in one pass: (edges per payload (F,) int64, all
    edge offsets in payload order (sum,) uint32, [(index, message)] of the malformed ones).

    Each payload is what :func:`decode_tacho` would give (a malformed one has no edges and
    its message is that ProtocolError's)."""
    F = len(payloads)
    lens = np.fromiter(map(len, payloads), dtype=np.int64, count=F)
    blob = np.frombuffer(b"".join(payloads), dtype=np.uint8).astype(np.int64)
    starts = np.cumsum(lens) - lens
    count = np.zeros(F, dtype=np.int64)
    has = np.flatnonzero(lens >= 2)
    count[has] = blob[starts[has]] | (blob[starts[has] + 1] << 8)
    good = (lens >= 2) & (lens == 2 + 4 * count)
    bad = []
    for i in np.flatnonzero(~good).tolist():
        try:
            decode_tacho(payloads[i])
        except ProtocolError as exc:
            bad.append((i, str(exc)))
    count[~good] = 0
    total = int(count.sum())
    frame = np.repeat(np.arange(F), count)
    k = np.arange(total) - np.repeat(np.cumsum(count) - count, count)     # edge index in its frame
    at = starts[frame] + 2 + 4 * k
    offsets = (blob[at] | (blob[at + 1] << 8) | (blob[at + 2] << 16) | (blob[at + 3] << 24)).astype(np.uint32)
    return count, offsets, bad


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
