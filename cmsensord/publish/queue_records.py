"""The records of the MQTT store-and-forward queue's segment files (:mod:`.disk_queue`):
``<u32 body length><u32 CRC-32 of body>`` + body ``<u64 seq><u8 retain><u16 topic length>
topic payload``; a record encoded, one checked at an offset, and a segment's bytes read past
damaged records (reading goes on at the next offset where a length and a CRC check out, with a
higher seq; a run of zeros is skipped)."""

from __future__ import annotations

import re
import struct
import zlib
from dataclasses import dataclass

__all__ = ["Record", "Scan", "SHORTEST", "MAX_RECORD", "encode", "read_records"]

_HEAD = struct.Struct("<II")          # body length, CRC-32 of the body
_BODY = struct.Struct("<QBH")         # seq, retain, topic length
#: every record body is smaller than this (a torn length field reads as garbage beyond it)
MAX_RECORD = 16 << 20
#: the fewest bytes a record takes (an empty topic and payload)
SHORTEST = _HEAD.size + _BODY.size
_NONZERO = re.compile(rb"[^\0]")


@dataclass(frozen=True)
class Record:
    """One queued message."""

    seq: int
    topic: str
    payload: bytes
    retain: bool


def encode(rec: Record) -> bytes:
    topic = rec.topic.encode()
    body = _BODY.pack(rec.seq, int(rec.retain), len(topic)) + topic + rec.payload
    return _HEAD.pack(len(body), zlib.crc32(body)) + body


def _record_at(data: bytes, pos: int) -> tuple[Record, int] | None:
    """The record whose header is at ``pos`` and where it ends, or None when its length or
    CRC check fails there."""
    if pos + _HEAD.size > len(data):
        return None
    length, crc = _HEAD.unpack_from(data, pos)
    end = pos + _HEAD.size + length
    if length < _BODY.size or length >= MAX_RECORD or end > len(data):
        return None
    body = data[pos + _HEAD.size:end]
    if zlib.crc32(body) != crc:
        return None
    seq, retain, tlen = _BODY.unpack_from(body)
    topic = body[_BODY.size:_BODY.size + tlen].decode(errors="replace")
    return Record(seq, topic, body[_BODY.size + tlen:], bool(retain)), end


def _resync(data: bytes, start: int, after: int) -> int:
    """The offset of the first valid record at or after ``start`` whose seq is above ``after``
    (past a damaged one), else the end of ``data``. A record's length is below
    :data:`MAX_RECORD` and above 0, so its fourth byte is 0 and one of the three before is
    not: only those offsets are tried (a run of zeros, as a power cut can leave, is skipped)."""
    zero = data.find(b"\0", start + 3)
    while zero != -1:
        if data[zero - 3:zero] == b"\0\0\0":
            more = _NONZERO.search(data, zero)
            zero = data.find(b"\0", more.start()) if more else -1
            continue
        found = _record_at(data, zero - 3)
        if found is not None and found[0].seq > after:
            return zero - 3
        zero = data.find(b"\0", zero + 1)
    return len(data)


@dataclass
class Scan:
    """A segment's bytes read: its valid records with their offsets, its damaged spans
    ``(start, end)`` (a record failing its length or CRC check up to the next valid record,
    or to the end of the data), and where its last valid record ends."""

    records: list[tuple[int, Record]]
    damaged: list[tuple[int, int]]
    valid: int


def read_records(data: bytes, after: int = 0) -> Scan:
    """The records of a segment's bytes whose first seq is above ``after``: a damaged record
    is skipped, reading on from the next valid record (its length and CRC right, its seq
    above the last one read)."""
    out: list[tuple[int, Record]] = []
    damaged: list[tuple[int, int]] = []
    pos = valid = 0
    while pos < len(data):
        found = _record_at(data, pos)
        if found is None:
            end = _resync(data, pos + 1, out[-1][1].seq if out else after)
            damaged.append((pos, end))
            pos = end
            continue
        out.append((pos, found[0]))
        pos = valid = found[1]
    return Scan(out, damaged, valid)
