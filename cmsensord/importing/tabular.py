"""CSV/TSV reader: separator and header detected, decimal commas accepted.

From the first lines of the file (up to 20, blank and ``#`` lines skipped):

* separator: tab, ``;``, ``,`` or ``|``, the first that occurs the same number
  of times (at least once) on every line; else runs of whitespace when a line
  has several fields; else one column;
* header: the first line is a header when one of its fields is not a number;
  its fields name the columns (``col0``, ``col1``, ... otherwise);
* decimal comma: with a ``;``, tab or whitespace separator, a comma inside the
  numbers is read as a decimal point (``0,552;-0,146``).

A column of times is found and marked (:mod:`.time_column`): it gives the
sampling rate and is no channel by default.

``separator`` / ``header`` override the detection (the command's
``--separator`` and ``--header``/``--no-header``). The numbers are parsed by
``numpy.loadtxt`` (C speed); a row that does not parse is an error naming the
file, the row and the column.
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np

from .errors import ImportFailure
from .table import Table
from .time_column import with_time_column

__all__ = ["read_tabular", "sniff", "is_text_table"]

_SEPARATORS = ("\t", ";", ",", "|")
_SEP_NAMES = {"\t": "tab", ";": "';'", ",": "','", "|": "'|'", None: "whitespace"}
_SNIFF_BYTES = 1 << 16
#: bytes :func:`is_text_table` looks at
_TEXT_PROBE_BYTES = 4096


def _is_number(text: str) -> bool:
    try:
        float(text.strip().strip('"').replace(",", "."))
        return True
    except ValueError:
        return False


def _split(line: str, sep: str | None) -> list[str]:
    return line.split() if sep is None else line.split(sep)


def sniff(lines: list[str], separator: str | None = None,
          header: bool | None = None) -> tuple[str | None, bool, bool]:
    """(separator (None: whitespace), header present, decimal comma) of these first lines."""
    if separator is None:
        body = lines[1:] or lines  # the header may hold other characters
        sep: str | None = None
        for cand in _SEPARATORS:
            counts = {line.count(cand) for line in body}
            if len(counts) == 1 and counts.pop() > 0 and cand in lines[0]:
                sep = cand
                break
        if sep is None and not any(len(line.split()) > 1 for line in lines):
            sep = ","  # one column: any separator that does not occur
    else:
        sep = None if separator in ("whitespace", " ") else separator
    if header is None:
        header = not all(_is_number(f) for f in _split(lines[0], sep) if f.strip())
    data = lines[1:] if header else lines
    decimal_comma = sep != "," and any("," in line for line in data) \
        and not any("." in line for line in data)
    return sep, header, decimal_comma


def _first_lines(path: str) -> list[str]:
    try:
        with open(path, "rb") as f:
            head = f.read(_SNIFF_BYTES)
    except OSError as exc:
        raise ImportFailure(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        text = head.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = head.decode("latin-1")
    lines = [ln.rstrip("\r") for ln in text.split("\n")[:-1] or text.split("\n")]
    lines = [ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ImportFailure(f"{path}: no data (empty file)")
    return lines[:20]


def is_text_table(path: str) -> bool:
    """Whether a file of no known extension is a text table of numbers (the IMS bearing rig's
    snapshot files, named by their date and time): its first 4 kB are text without NUL bytes,
    and a line among the first two that are not blank or ``#`` is a row of numbers."""
    try:
        with open(path, "rb") as f:
            head = f.read(_TEXT_PROBE_BYTES)
    except OSError:
        return False
    if not head or b"\0" in head:
        return False
    lines = [ln for ln in head.decode("latin-1").splitlines()[:-1] or [head.decode("latin-1")]
             if ln.strip() and not ln.lstrip().startswith("#")][:2]
    return any(_is_number_row(ln) for ln in lines)


def _is_number_row(line: str) -> bool:
    """Every field of the line is a number, by any of the separators :func:`sniff` knows."""
    for sep in (None, *_SEPARATORS):
        fields = [f for f in _split(line, sep) if f.strip()]
        if fields and all(_is_number(f) for f in fields):
            return True
    return False


def _loadtxt_message(text: str, header: int) -> str:
    """numpy.loadtxt's message with file lines (from 1) and columns (from 0, as --channels counts)."""
    msg = re.sub(r";? ?use `usecols`.*", "", " ".join(text.split())).rstrip(". ")
    m = re.search(r"could not convert string (.*) to float64 at row (\d+), column (\d+)", msg)
    if m:  # loadtxt: data row from 0, column from 1
        return f"line {int(m[2]) + 1 + header}, column {int(m[3]) - 1}: {m[1]} is not a number"
    m = re.search(r"the number of columns changed from (\d+) to (\d+) at row (\d+)", msg)
    if m:  # loadtxt: data row from 1
        return f"line {int(m[3]) + header}: {m[2]} column(s) where the lines before have {m[1]}"
    return msg


def read_tabular(path: str, separator: str | None = None, header: bool | None = None) -> Table:
    lines = _first_lines(path)
    sep, has_header, decimal_comma = sniff(lines, separator, header)
    if has_header:
        names = [f.strip().strip('"').strip() for f in _split(lines[0], sep)]
        names = [n or f"col{i}" for i, n in enumerate(names)]
    try:
        if decimal_comma:
            text = Path(path).read_text(encoding="utf-8-sig", errors="replace").replace(",", ".")
            src: str | io.StringIO = io.StringIO(text)
        else:
            src = path
        a = np.loadtxt(src, delimiter=sep, skiprows=1 if has_header else 0, ndmin=2,
                       dtype=np.float64, quotechar='"', encoding="utf-8-sig")
    except ValueError as exc:
        msg = _loadtxt_message(str(exc), int(has_header))
        raise ImportFailure(f"{path}: {msg} (separator {_SEP_NAMES.get(sep, repr(sep))}, "
                            f"{'a header line' if has_header else 'no header'}); fix the file, or set "
                            "--separator / --header / --no-header") from None
    if a.shape[0] == 0:
        raise ImportFailure(f"{path}: a header but no rows of numbers")
    if not has_header:
        names = [f"col{i}" for i in range(a.shape[1])]
    elif len(names) != a.shape[1]:
        raise ImportFailure(f"{path}: the header names {len(names)} columns, the rows hold {a.shape[1]}; "
                            "fix the header or use --no-header")
    return with_time_column(Table(path=path, data=a[None], columns=names, kind="column"), has_header)
