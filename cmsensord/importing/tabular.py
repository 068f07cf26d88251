"""CSV/TSV reader: separator and header detected, decimal commas accepted.

Text is UTF-8, or UTF-16 after its byte order mark (Excel's "Unicode Text"; read decoded
into memory, or a chunk of lines at a time when long). The numbers begin where
:mod:`.text_head` finds them (``#`` comments, blank lines and a
preamble of settings before them are skipped, comments and a preamble with a note). From the line
before them and their first rows:

* separator: tab, ``;``, ``,`` or ``|``, the first that occurs the same number
  of times (at least once) on every line; else runs of whitespace when a line
  has several fields; else one column;
* header: the line before the numbers is a header when one of its fields is not a
  number and it has a field for every column (LabVIEW's last name ``Comment``, a column
  the rows leave out, aside); its fields name the columns (``col0``, ``col1``, ...
  otherwise);
* decimal comma: with a ``;``, tab or whitespace separator, a comma inside the
  numbers is read as a decimal point (``0,552;-0,146``).

A column of times is found and marked (:mod:`.time_column`): it gives the
sampling rate and is no channel by default. A date and time in the preamble
(:mod:`.preamble`: LabVIEW's ``Date`` and ``Time``) is the file's snapshot time.

``separator`` / ``header`` override the detection (the command's
``--separator`` and ``--header``/``--no-header``). The numbers are parsed by
``numpy.loadtxt`` (C speed); a row that does not parse is an error naming the
file, its line in the file and the column.
"""

from __future__ import annotations

import io
import itertools
import re
import tempfile
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .errors import ImportFailure, cannot_write, no_room
from .preamble import preamble_start
from .table import Table
from .text_head import (
    DATETIME,
    SEPARATORS,
    UTF16,
    Head,
    decode_head,
    encoding_of,
    file_encoding,
    first_row,
    is_cell,
    read_head,
    split,
    unit_fields,
)
from .time_column import with_time_column

__all__ = ["LongText", "read_tabular", "sniff", "is_text_table"]

_SEP_NAMES = {"\t": "tab", ";": "';'", ",": "','", "|": "'|'", None: "whitespace"}
#: bytes :func:`is_text_table` looks at
_TEXT_PROBE_BYTES = 4096
#: lines of a long text table read at a time (:func:`_numbers_in_chunks`)
CHUNK_LINES = 1 << 16


def sniff(lines: list[str], separator: str | None = None,
          header: bool | None = None) -> tuple[str | None, bool, bool]:
    """(separator (None: whitespace), header present, decimal comma) of these first lines."""
    if separator is None:
        body = lines[1:] or lines  # the header may hold other characters
        sep: str | None = None
        for cand in SEPARATORS:
            counts = {line.count(cand) for line in body}
            if len(counts) == 1 and counts.pop() > 0 and cand in lines[0]:
                sep = cand
                break
        if sep is None and not any(len(line.split()) > 1 for line in lines):
            sep = ","  # one column: any separator that does not occur
    else:
        sep = None if separator in ("whitespace", " ") else separator
    if header is None:
        header = not all(is_cell(f, i == 0) for i, f in enumerate(split(lines[0], sep)) if f.strip())
    data = lines[1:] if header else lines
    decimal_comma = sep != "," and any("," in line for line in data) \
        and not any("." in line for line in data)
    return sep, header, decimal_comma


def is_text_table(path: str) -> bool:
    """Whether a file of no known extension is a text table of numbers (the IMS bearing rig's
    snapshot files, named by their date and time): its first 4 kB are text without NUL bytes,
    and three rows of numbers follow each other there (:func:`~.text_head.first_row`; a
    preamble before them may be), or its lines there are all rows of numbers."""
    try:
        with open(path, "rb") as f:
            head = f.read(_TEXT_PROBE_BYTES)
    except OSError:
        return False
    if not head or (b"\0" in head and encoding_of(head) != UTF16):
        return False
    text = decode_head(head)
    lines = text.splitlines()[:-1] or [text]
    return first_row(lines) is not None


def _loadtxt_message(text: str, skip: int) -> str:
    """numpy.loadtxt's message with file lines (from 1; ``skip`` lines before the numbers) and
    columns (from 0, as --channels counts)."""
    msg = re.sub(r";? ?use `usecols`.*", "", " ".join(text.split())).rstrip(". ")
    m = re.search(r"could not convert string (.*) to float64 at row (\d+), column (\d+)", msg)
    if m:  # loadtxt: data row from 0, column from 1
        return f"line {int(m[2]) + 1 + skip}, column {int(m[3]) - 1}: {m[1]} is not a number"
    m = re.search(r"the number of columns changed from (\d+) to (\d+) at row (\d+)", msg)
    if m:  # loadtxt: data row from 1
        return f"line {int(m[3]) + skip}: {m[2]} column(s) where the lines before have {m[1]}"
    return msg


def _layout(head: Head, separator: str | None, header: bool | None) -> tuple[str | None, str | None, bool, int]:
    """(separator, the header line or None, decimal comma, lines before the numbers). The header
    candidate names the columns unless ``header`` is False; without a candidate, ``header`` True
    takes the first row."""
    candidate = head.header if header is not False else None
    lines = head.rows if candidate is None else [candidate, *head.rows]
    sep, has_header, decimal_comma = sniff(lines, separator, header)
    if has_header and candidate is None:
        return sep, head.rows[0], decimal_comma, head.skip + 1
    return sep, candidate if has_header else None, decimal_comma, head.skip


def _head_note(path: str, head: Head, names_kept: bool) -> str | None:
    """What was skipped before the numbers (``#`` comments, a preamble, a line of names that
    does not fit)."""
    skipped = head.skipped(names_kept)
    if not skipped:
        return None
    first = skipped[0].strip()
    first = first if len(first) <= 40 else first[:37] + "..."
    return (f"{Path(path).name}: {len(skipped)} line(s) before the {'column names' if names_kept else 'numbers'} "
            f"skipped (the first: {first!r})")


def _numbers(src: str | io.StringIO, sep: str | None, skip: int, line0: int, dated: bool,
             cols: range | None) -> np.ndarray:
    """float64 (rows, columns) of the text table ``src`` after its first ``skip`` lines, which
    begin at line ``line0`` of the file (a first column of dates as seconds since the Unix
    epoch; an empty cell is NaN, a missing value); a row that is not numbers is a ValueError
    naming its line in the file."""
    try:
        with warnings.catch_warnings():             # "input contained no data", blank lines: not the user's
            warnings.simplefilter("ignore", UserWarning)
            try:
                a = _loadtxt(src, sep, skip, cols, None)
            except ValueError as exc:
                if "convert string '' to" not in str(exc):
                    raise
                if isinstance(src, io.StringIO):
                    src.seek(0)
                a = _loadtxt(src, sep, skip, cols, _cell)   # cell by cell: slower, only for such a file
            return np.column_stack([_dates(src, sep, skip, line0), a]) if dated else a
    except UnicodeDecodeError:
        raise
    except ValueError as exc:
        raise ValueError(_loadtxt_message(str(exc), line0)) from None


def _loadtxt(src: str | io.StringIO, sep: str | None, skip: int, cols: range | None, cell) -> np.ndarray:
    return np.loadtxt(src, delimiter=sep, skiprows=skip, ndmin=2, dtype=np.float64, quotechar='"',
                      encoding="utf-8-sig", usecols=cols, converters=cell)


def _cell(text: str) -> float:
    """A cell's number; an empty cell (a logger's missing value) is NaN."""
    return float(text) if text.strip() else float("nan")


def _numbers_in_chunks(path: str, sep: str | None, skip: int, decimal_comma: bool, dated: bool, cols: range | None,
                       long: LongText, cut: bool = False, encoding: str = "utf-8-sig") -> np.ndarray:
    """:func:`_numbers` of the whole file (text in ``encoding``), read ``CHUNK_LINES`` lines at a
    time into an unnamed file in ``long.spill_dir`` (gone with the map), as a read-only memory
    map (rows, columns)."""
    spill_dir, size, read = long.spill_dir, max(1, Path(path).stat().st_size), 0
    done, columns = 0, 0
    try:
        store = tempfile.TemporaryFile(dir=spill_dir)
    except OSError as exc:
        raise cannot_write(spill_dir, exc.strerror or str(exc)) from None
    char_bytes = 2 if encoding == UTF16 else 1
    with store, open(path, encoding=encoding, errors="replace") as f:
        for _ in itertools.islice(f, skip):
            pass
        line0 = skip
        while lines := list(itertools.islice(f, CHUNK_LINES)):
            if cut and not lines[-1].endswith("\n"):      # the file's last line, cut short: left out
                lines.pop()
            text = "".join(lines)
            a = _numbers(io.StringIO(text.replace(",", ".") if decimal_comma else text), sep, 0, line0, dated, cols)
            if a.size and columns and a.shape[1] != columns:
                at = line0 + next(i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#"))
                raise ValueError(f"line {at + 1}: {a.shape[1]} column(s) where the lines before have {columns}")
            if a.size:
                columns = a.shape[1]
                _spill(store, a, spill_dir, path)
                done += a.shape[0]
            line0 += len(lines)
            read += len(text) * char_bytes
            if long.progress is not None:
                long.progress(min(1.0, read / size))
        if not done:
            return np.empty((0, max(columns, 1)))
        _spill(store, None, spill_dir, path)
        return np.memmap(store, dtype=np.float64, mode="r", shape=(done, columns))


def _spill(store, a: np.ndarray | None, spill_dir: str, path: str) -> None:
    """``a`` written to the end of ``store`` (None: what is buffered, flushed); a disk without
    room is one line."""
    try:
        if a is None:
            store.flush()
        else:
            store.write(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    except OSError as exc:
        raise no_room(f"{path}: no room in {spill_dir} for the numbers of this long text file (held there while "
                      "it is read, 8 bytes a value)", exc.strerror or str(exc)) from None


def _dates(src: str | io.StringIO, sep: str | None, skip: int, line0: int) -> np.ndarray:
    """The first column's dates and times as seconds since the Unix epoch (float64); ``line0``:
    the file's line of the first row."""
    if isinstance(src, io.StringIO):
        src.seek(0)
    text = np.loadtxt(src, delimiter=sep, skiprows=skip, ndmin=1, dtype=str, quotechar='"',
                      encoding="utf-8-sig", usecols=0)
    try:
        stamps = np.char.strip(text).astype("datetime64[us]")
    except ValueError:
        bad = next(i for i, v in enumerate(text) if not _is_date(v))
        raise ValueError(f"line {bad + 1 + line0}, column 0: {str(text[bad])!r} is not a date and time") from None
    return (stamps - np.datetime64(0, "us")).astype(np.float64) / 1e6


def _is_date(text: str) -> bool:
    try:
        np.datetime64(text.strip())
    except ValueError:
        return False
    return DATETIME.fullmatch(text) is not None


#: bytes at a file's end read for its last line
_TAIL_BYTES = 1 << 16


def _cut_short(path: str, sep: str | None, width: int) -> str | None:
    """A note when the file's last line is cut short: no line end, and fewer values than the
    rows (``width``), as a logger leaves a file it was writing when it stopped; else None."""
    with open(path, "rb") as f:
        bom = f.read(2)
        f.seek(0, 2)
        size = f.tell()
        f.seek(max(0, size - _TAIL_BYTES))
        tail = decode_head(f.read(), bom) if encoding_of(bom) == UTF16 else f.read().decode("latin-1")
    if not tail or tail.endswith(("\n", "\r")) or "\n" not in tail:
        return None
    last = tail[tail.rfind("\n") + 1:]
    n = len([v for v in split(last, sep) if v.strip()])
    if not last.strip() or n >= width:
        return None
    return (f"{Path(path).name}: its last line is cut short ({n} of {width} values and no line end, as a "
            "file left when its writing stopped); the lines before it are imported")


@dataclass(frozen=True)
class LongText:
    """How a text table larger than ``memory_mb`` is read (:func:`_numbers_in_chunks`): its
    numbers wait in ``spill_dir``; ``progress(fraction of the file)`` after each chunk."""

    spill_dir: str
    memory_mb: float
    progress: Callable[[float], None] | None = None


def _read_numbers(path: str, sep: str | None, skip: int, decimal_comma: bool, dated: bool, cols: range | None,
                  long: LongText | None, cut: str | None, encoding: str) -> np.ndarray:
    """The table's numbers, its text read in ``encoding`` (a UnicodeDecodeError when it is not)."""
    if long is not None and Path(path).stat().st_size > long.memory_mb * 1e6:
        return _numbers_in_chunks(path, sep, skip, decimal_comma, dated, cols, long, cut is not None, encoding)
    src: str | io.StringIO = path
    if decimal_comma or cut is not None or encoding != "utf-8-sig":
        text = Path(path).read_text(encoding=encoding, errors="strict" if encoding == "utf-8-sig" else "replace")
        text = text[:text.rfind("\n") + 1] if cut is not None else text
        src = io.StringIO(text.replace(",", ".") if decimal_comma else text)
    return _numbers(src, sep, skip, skip, dated, cols)


def read_tabular(path: str, separator: str | None = None, header: bool | None = None,
                 long: LongText | None = None) -> Table:
    """The text table's numbers; with ``long``, a file larger than ``long.memory_mb`` is read a
    chunk of lines at a time into an unnamed file in ``long.spill_dir``, its numbers a memory
    map of it, so that a long recording's text does not need its float64 table in memory."""
    head = read_head(path)
    encoding = file_encoding(path)
    sep, header_line, decimal_comma, skip = _layout(head, separator, header)
    first = split(head.rows[0], sep) if head.rows else []
    dated = bool(first) and DATETIME.fullmatch(first[0]) is not None
    trailing = sep is not None and len(first) > 1 and all(split(r, sep)[-1].strip() == "" for r in head.rows)
    width = len(first) - trailing               # lines that end with the separator: no last column
    cols = range(1 if dated else 0, width) if dated or trailing else None   # a date column: read apart
    cut = _cut_short(path, sep, width)
    notes = [cut] if cut else []
    try:
        try:
            a = _read_numbers(path, sep, skip, decimal_comma, dated, cols, long, cut, encoding)
        except UnicodeDecodeError:
            a = _read_numbers(path, sep, skip, decimal_comma, dated, cols, long, cut, "latin-1")
            notes.append(f"{Path(path).name}: not UTF-8 text: read as Latin-1 (ISO 8859-1)")
    except ValueError as exc:                       # its message names the line (_numbers)
        raise ImportFailure(f"{path}: {exc} (separator {_SEP_NAMES.get(sep, repr(sep))}, "
                            f"{'a header line' if header_line is not None else 'no header'}); fix the file, "
                            "or set --separator / --header / --no-header") from None
    if a.shape[0] == 0:
        raise ImportFailure(f"{path}: a header but no rows of numbers")
    names = None
    units = unit_fields(header_line, sep) if header_line is not None and head.preamble else None
    if units is not None and len(split(head.preamble[-1], sep)) == len(units):
        header_line, head = head.preamble[-1], head.names_above()   # names, then units
    else:
        units = None
    if header_line is not None:
        names = [f.strip().strip('"').strip() or f"col{i}" for i, f in enumerate(split(header_line, sep))]
        if units is not None:
            names = [f"{n} ({u})" if u else n for n, u in zip(names, units)]
            notes.append(f"{Path(path).name}: the line under the column names gives their units: "
                         f"{', '.join(n for n, u in zip(names, units) if u)}")
        if trailing and len(names) == a.shape[1] + 1 and not split(header_line, sep)[-1].strip():
            names = names[:-1]              # the header ends with the separator too
        if len(names) == a.shape[1] + 1 and names[-1].lower() == "comment":
            names = names[:-1]              # LabVIEW's comment column, which rows of numbers leave out
        if len(names) != a.shape[1]:
            if header is True:
                raise ImportFailure(f"{path}: the header names {len(names)} columns, the rows hold "
                                    f"{a.shape[1]}; fix the header or use --no-header")
            names = None                    # a preamble's last line, not the columns' names
    note = _head_note(path, head, names is not None)
    t = with_time_column(Table(path=path, data=a[None], columns=names or [f"col{i}" for i in range(a.shape[1])],
                               kind="column", head_note=note, notes=notes), names is not None,
                         dated=dated)
    start = preamble_start(head.preamble + (() if names is not None or head.header is None else (head.header,)))
    return t if start is None or t.times is not None else replace(t, times=np.array([start]), dated=True)
