"""Where a text table's rows of numbers begin, and the lines before them.

Data loggers write lines before their numbers: ``#`` comments, blank lines, a preamble of
settings (``LabVIEW Measurement``, ``Sample rate: 25600 Hz``), then maybe a line of column
names. The rows of numbers begin at the first line that is a row of numbers (every field a
number, by one of the separators; the first may be a date and time) followed by two more
(or by the end of what is read); the last line before it that is neither blank nor a
comment is the header candidate; the lines before that, the preamble (with the ``#``
comments among them: the lead, which the import says it skipped). Only the file's first
``HEAD_BYTES`` are read here.

Text is UTF-8 (a byte order mark dropped; Latin-1 where it is not UTF-8), or UTF-16 when it
begins with UTF-16's byte order mark (Excel's "Unicode Text" export): :func:`encoding_of`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

from .errors import ImportFailure

__all__ = ["DATETIME", "HEAD_BYTES", "SEPARATORS", "UTF16", "Head", "decode_head", "encoding_of", "file_encoding",
           "filled_lines", "first_row", "is_cell", "is_number", "is_number_row", "read_head", "split", "unit_fields"]

SEPARATORS = ("\t", ";", ",", "|")
HEAD_BYTES = 1 << 16
#: rows of numbers handed to the separator and header detection
ROWS = 20


def is_number(text: str) -> bool:
    try:
        float(text.strip().strip('"').replace(",", "."))
        return True
    except ValueError:
        return False


#: a date and time as the first field of a row (ISO 8601, without a zone): ``2023-05-01 12:00:00.125``
DATETIME = re.compile(r'\s*"?\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(?::\d{2}(?:\.\d+)?)?"?\s*')


def is_cell(text: str, first: bool) -> bool:
    """A number, or (the row's first field) a date and time."""
    return is_number(text) or (first and DATETIME.fullmatch(text) is not None)


def split(line: str, sep: str | None) -> list[str]:
    return line.split() if sep is None else line.split(sep)


def is_number_row(line: str) -> bool:
    """Every field of the line is a number (the first may be a date and time), by whitespace
    or one of :data:`SEPARATORS`."""
    for sep in (None, *SEPARATORS):
        fields = [f for f in split(line, sep) if f.strip()]
        if fields and all(is_cell(f, i == 0) for i, f in enumerate(fields)):
            return True
    return False


#: a unit as loggers write one under a column's name (``s``, ``[g]``, ``(m/s^2)``, ``mm/s``, ``°C``, ``1/min``)
_UNIT = re.compile(r"[\[(]?\s*(?:[munkµ]?(?:s|g|V|A|N|Pa|Hz|m|W|Nm)|m/s(?:\^?2|²)?|mm/s2?|G|g0|rpm|RPM|"
                   r"1/min|min|h|%|°C|degC|K|bar|sec)\s*[\])]?")


def unit_fields(line: str, sep: str | None) -> list[str] | None:
    """The line's fields when every one is a unit or empty (and one at least a unit): the units
    line some loggers write under the column names; else None."""
    fields = [f.strip().strip('"').strip() for f in split(line, sep)]
    if not any(fields) or not all(not f or _UNIT.fullmatch(f) for f in fields):
        return None
    return [f.strip("[]()").strip() for f in fields]


@dataclass(frozen=True)
class Head:
    rows: list[str]  # the first rows of numbers (at most ROWS)
    skip: int  # physical lines before the first of them (numpy.loadtxt's skiprows)
    header: str | None = None  # the header candidate: the line before them, if it is not a row
    preamble: tuple[str, ...] = ()  # the lines before the candidate that are not blank or comments
    lead: tuple[str, ...] = ()  # the lines before the rows that are not blank: comments, preamble, candidate

    def names_above(self) -> Head:
        """This head with the preamble's last line (the column names above a units line, the
        candidate) no longer in ``preamble`` nor ``lead``."""
        return replace(self, preamble=self.preamble[:-1], lead=_without_filled(self.lead, 2))

    def skipped(self, names_kept: bool) -> list[str]:
        """The lines before the rows that the reader skips: ``lead`` but the candidate when it
        names the columns (``names_kept``)."""
        return list(_without_filled(self.lead, 1) if names_kept and self.header is not None else self.lead)


def _without_filled(lines: tuple[str, ...], back: int) -> tuple[str, ...]:
    """``lines`` without the ``back``-th last of them that is not a comment (1: the last)."""
    at = [i for i, ln in enumerate(lines) if not _is_comment(ln)][-back]
    return lines[:at] + lines[at + 1:]


#: the encoding :func:`encoding_of` gives text after a UTF-16 byte order mark
UTF16 = "utf-16"
#: UTF-16's byte order marks: little endian (Windows, Excel), big endian
_UTF16_BOMS = {b"\xff\xfe": "utf-16-le", b"\xfe\xff": "utf-16-be"}


def encoding_of(head: bytes) -> str:
    """The encoding of text that begins with ``head``: :data:`UTF16` after a UTF-16 byte order
    mark, else ``utf-8-sig``."""
    return UTF16 if head[:2] in _UTF16_BOMS else "utf-8-sig"


def file_encoding(path: str) -> str:
    """:func:`encoding_of` the file's first bytes."""
    with open(path, "rb") as f:
        return encoding_of(f.read(2))


def decode_head(head: bytes, bom: bytes | None = None) -> str:
    """Text of a file's bytes ``head`` (its first, or, with the file's first two bytes ``bom``, a
    stretch of it at an even offset): UTF-16 by the byte order mark, a character cut at the end
    as U+FFFD; else UTF-8 (its BOM dropped), or Latin-1 where it is not UTF-8."""
    order = _UTF16_BOMS.get((head if bom is None else bom)[:2])
    if order is not None:
        return head[2 if bom is None else 0:].decode(order, errors="replace").lstrip("\ufeff")
    try:
        return head.decode("utf-8-sig")
    except UnicodeDecodeError:
        return head.decode("latin-1")


def _physical_lines(path: str) -> list[str]:
    try:
        with open(path, "rb") as f:
            head = f.read(HEAD_BYTES)
            whole = not f.read(1)
    except OSError as exc:
        raise ImportFailure(f"{path}: cannot read: {exc.strerror or exc}") from None
    lines = decode_head(head).split("\n")
    if not whole and len(lines) > 1:
        lines = lines[:-1]                  # cut inside a line
    return [ln.rstrip("\r") for ln in lines]


def _is_comment(line: str) -> bool:
    return line.lstrip().startswith("#")


def filled_lines(lines: list[str]) -> list[int]:
    """The indices of the lines that are neither blank nor ``#`` comments."""
    return [i for i, ln in enumerate(lines) if ln.strip() and not _is_comment(ln)]


def first_row(lines: list[str], filled: list[int] | None = None) -> int | None:
    """The line where the rows of numbers begin: a row, and so are the next two filled lines
    (``filled``: :func:`filled_lines`, computed when not given); None when there is none."""
    if filled is None:
        filled = filled_lines(lines)
    number: dict[int, bool] = {}

    def row(i: int) -> bool:
        if i not in number:
            number[i] = is_number_row(lines[i])
        return number[i]

    for k in range(len(filled)):
        if all(row(i) for i in filled[k:k + 3]):
            return filled[k]
    return None


def read_head(path: str) -> Head:
    """The file's :class:`Head`; a file without a line that is not blank or a comment is a
    one-line ImportFailure. Where no three rows of numbers follow each other, the rows are
    the first filled lines as they come (the reader then says which line is not numbers)."""
    lines = _physical_lines(path)
    filled = filled_lines(lines)
    if not filled:
        raise ImportFailure(f"{path}: no data (empty file)")
    start = first_row(lines, filled)
    if start is None:
        return Head(rows=[lines[i] for i in filled][:ROWS], skip=filled[0])
    before = [i for i in filled if i < start]
    first = [lines[i] for i in filled if i >= start][:ROWS]
    lead = tuple(ln for ln in lines[:start] if ln.strip())
    if not before:
        return Head(rows=first, skip=start, lead=lead)
    return Head(rows=first, skip=start, header=lines[before[-1]],
                preamble=tuple(lines[i] for i in before[:-1]), lead=lead)
