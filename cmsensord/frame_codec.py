"""The serial wire protocol's frame layout and its four payloads (docs/PROTOCOL.md).

The frame layout (sync ``A5 5A``, 14-byte header, payload, CRC-32 of bytes
2 .. 14+len-1 stored little-endian) and the four payloads (STATUS, RMS, RAW,
TACHO): ``encode_*`` build complete frames (shared with ``firmware_sim``),
``decode_*`` parse payloads and raise :class:`ProtocolError` naming the
expected vs the received length.  The receiver rules, the stream's framing, are
:class:`cmsensord.protocol.Decoder`'s.
"""

from __future__ import annotations

import enum
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from cmsensord.frame_batch import FrameBatch

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
