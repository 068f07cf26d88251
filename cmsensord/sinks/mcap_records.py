"""The top-level records of an MCAP file, read one by one: :class:`RecordWalker` checks each
record's length before anything parses it, so a file that ends inside a record (a ``.part``
file of a crashed process) or claims an absurd length (corruption) ends the walk without an
exception; :func:`parse_record` parses one.  Salvage (:mod:`cmsensord.sinks.mcap_salvage`),
the chunk check and the lenient readers (:mod:`cmsensord.sinks.mcap_read`) walk files with it.
"""

from __future__ import annotations

import io
import os
import stat
import struct
from collections.abc import Iterator
from typing import Any, BinaryIO

from mcap.opcode import Opcode
from mcap.stream_reader import StreamReader

from cmsensord.sinks.mcap_chunks import MAGIC

__all__ = ["NOT_MCAP", "RECORD_LIMIT", "KNOWN_OPCODES", "RecordWalker", "is_capture", "not_mcap_text", "parse_record"]

#: summarize()'s ``error`` for a file that does not start with the MCAP magic
NOT_MCAP = "not an MCAP file (bad magic)"


def is_capture(path: str | os.PathLike[str]) -> bool:
    """Whether the file at ``path`` is a capture of the board's serial stream: its first 64 KB hold
    a frame the decoder takes (False for a file that cannot be read, and for one that is not a
    regular file: a FIFO, opened without waiting for a writer, and a device are not read)."""
    from cmsensord.protocol import Decoder

    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except (OSError, ValueError):
        return False
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        head = os.read(fd, 1 << 16)
    except OSError:
        return False
    finally:
        os.close(fd)
    return bool(Decoder().feed(head))


def not_mcap_text(path: str | os.PathLike[str]) -> str:
    """What a file without the MCAP magic is, for the line that refuses it: :data:`NOT_MCAP`, or,
    for a capture (:func:`is_capture`), that it is one and the command that makes logs of it."""
    if not is_capture(path):
        return NOT_MCAP
    return (f"a capture of the board's serial stream, not an MCAP log: `cmsensord replay {path} --out DIR` "
            "processes it into the logs that summary and report read")


# A record longer than this in a file we wrote means corruption, not data
# (chunks are ~1 MiB); reading it would only waste memory.
RECORD_LIMIT = 256 * 1024 * 1024
_HEAD = struct.Struct("<BQ")  # opcode, record length
KNOWN_OPCODES = frozenset(int(op) for op in Opcode)


class RecordWalker:
    """The top-level records of an MCAP file open in ``f``, read sequentially.

    :meth:`records` reads the magic, then yields ``(offset, opcode, raw)`` for
    every complete record (``raw``: opcode, length and body, as in the file).
    It stops, never raising on the content, when the file ends or a record
    claims more than ``RECORD_LIMIT`` bytes, and then sets :attr:`end`:

    * ``NOT_MCAP``: the file does not start with the magic;
    * ``IN_MAGIC``: the file ends inside the magic (or is empty);
    * ``AT_END``: the file ends just after a complete record;
    * ``IN_RECORD``: the file ends inside a record;
    * ``TOO_LONG``: a record claims too many bytes (:attr:`error` says which).

    :attr:`end` stays None when the caller stops first. :attr:`valid_bytes` is
    the offset after the magic and the last complete record read (0 without
    the magic).
    """

    NOT_MCAP = "not_mcap"
    IN_MAGIC = "in_magic"
    AT_END = "at_end"
    IN_RECORD = "in_record"
    TOO_LONG = "too_long"

    def __init__(self, f: BinaryIO) -> None:
        self._f = f
        self.end: str | None = None
        self.error: str | None = None
        self.valid_bytes = 0

    def records(self, start: int | None = None) -> Iterator[tuple[int, int, bytes]]:
        """(offset, opcode, raw record) of each complete record, in file order.

        ``start``: the offset of a record to resume at (after damage); the
        magic is then not read again.
        """
        f = self._f
        if start is None:
            magic = f.read(len(MAGIC))
            if magic != MAGIC:
                self.end = self.IN_MAGIC if MAGIC.startswith(magic) else self.NOT_MCAP
                return
            start = len(MAGIC)
        else:
            f.seek(start)
        self.end = self.error = None
        pos = self.valid_bytes = start
        while True:
            head = f.read(_HEAD.size)
            if len(head) < _HEAD.size:
                self.end = self.IN_RECORD if head else self.AT_END
                return
            opcode, length = _HEAD.unpack(head)
            if length > RECORD_LIMIT:
                self.end = self.TOO_LONG
                self.error = f"record at byte {pos} claims {length} bytes"
                return
            body = f.read(length)
            if len(body) < length:
                self.end = self.IN_RECORD
                return
            self.valid_bytes = pos + _HEAD.size + length
            yield pos, opcode, head + body
            pos = self.valid_bytes

    def closing_magic(self) -> bool:
        """After the Footer record has been yielded: whether the closing magic follows."""
        return self._f.read(len(MAGIC)) == MAGIC


def parse_record(raw: bytes) -> Any:
    """One complete record (from :meth:`RecordWalker.records`) as an mcap record object.

    A chunk stays a Chunk. Raises whatever mcap's parser raises on bad content.
    """
    return next(iter(StreamReader(io.BytesIO(raw), skip_magic=True, emit_chunks=True).records))
