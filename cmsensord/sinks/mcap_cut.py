"""What a file cut short lost, in one phrase (the report's and the summary's line on it).

A finished log ends with a Footer and the closing magic. One that ends before them (``head -c``,
a copy interrupted, a ``.part`` whose writer died) lost the record it ends inside: for a chunk,
all its messages, whose span of log time the chunk's header gives (a replay writes its whole
log in one or two chunks, so a cut loses all or half of it). A file shorter than the 8-byte
magic that starts every MCAP file holds no record: empty, cut inside the magic, or not MCAP at
all (:func:`short_text`).
"""

from __future__ import annotations

import struct

from cmsensord.sinks.mcap_chunks import MAGIC
from cmsensord.sinks.mcap_records import NOT_MCAP

__all__ = ["CUT_HEAD", "EMPTY", "cut_text", "is_unfinished_name", "short_text"]

#: what an empty file is
EMPTY = "empty file (0 bytes): no MCAP data"

#: bytes of the cut record that :func:`cut_text` reads: its opcode and length, a chunk's times
CUT_HEAD = 9 + 16
_OP_CHUNK = 0x06
#: a chunk whose messages span less than this [ns] holds one moment's (a capture, a decision)
MOMENT_NS = 50_000_000


def cut_text(head: bytes, pos: int, size: int) -> str:
    """One phrase on a file of ``size`` bytes that ends inside the record at byte ``pos``
    (``head``: the file's bytes from ``pos``, up to ``CUT_HEAD``), or, with ``pos == size``,
    just after its last complete record, before any Footer."""
    at = f"cut short at byte {size:,}"
    if pos >= size:
        return f"{at}, after its last complete record: no footer (anything written after it lost)"
    if len(head) < 9:
        return f"{at}, inside the header of the record at byte {pos:,} (anything from there on lost), no footer"
    opcode, length = struct.unpack_from("<BQ", head)
    part = f"{size - pos:,} of its {9 + length:,} bytes"
    if opcode != _OP_CHUNK:
        return f"{at}, inside the record at byte {pos:,} ({part}), no footer"
    if len(head) < CUT_HEAD:
        return f"{at}, inside the chunk at byte {pos:,} ({part}; all its messages lost), no footer"
    first, last = struct.unpack_from("<QQ", head, 9)
    if 0 <= last - first < MOMENT_NS:
        lost = "its messages of one moment of log time lost (a capture's waveform and spectra, say)"
    else:
        lost = f"its messages over {(last - first) / 1e9:.1f} s of log time lost" if last >= first else \
            "its messages over an unknown span of log time lost"
    return f"{at}, inside the chunk at byte {pos:,} ({part}; {lost}), no footer"


def short_text(head: bytes) -> str:
    """One phrase on a file shorter than the MCAP magic whose bytes are ``head``: :data:`EMPTY`,
    cut inside the magic (no record in it), or :data:`NOT_MCAP` when its bytes are not the
    magic's first ones."""
    if not head:
        return EMPTY
    if not MAGIC.startswith(head):
        return NOT_MCAP
    return f"cut short at byte {len(head)}, inside the {len(MAGIC)}-byte MCAP magic: no record in it"


def is_unfinished_name(name: str) -> bool:
    """Whether a file named ``name`` is one being written (``*.part``), which ends short as a
    matter of course, not a finished log cut short."""
    return name.endswith(".part")
