"""An ``--out`` that names one of the command's own inputs is refused before anything is read:
writing it would destroy the input (an import over its WAV, a report over its log); so is a
daemon's ``--capture`` that names its configuration, or a file that is no regular file (the
port's bytes appended to a device), an ``--out`` file that cannot be made where it is named
(a directory given, or a directory that does not exist), and one that is a device or a FIFO
(a file written beside it and renamed over it would replace it)."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable
from pathlib import Path

from cmsensord.errors import file_kind

__all__ = ["capture_refused", "not_a_file", "out_file_refused", "overwritten_input", "with_sidecars"]


def overwritten_input(out: str | os.PathLike, inputs: Iterable[str | os.PathLike],
                      option: str = "--out") -> str | None:
    """One line saying that ``out`` (given as ``option``) is one of ``inputs`` (the same file, by
    any path or link), or None when it is none of them."""
    for src in inputs:
        try:
            same = os.path.samefile(out, src)
        except OSError:                     # one of them does not exist: not the same file
            continue
        if same:
            return (f"{out}: is the input {src}: writing it would destroy it; give {option} another "
                    "file name")
    return None


def out_file_refused(out: str | os.PathLike, example: str, option: str = "--out") -> str | None:
    """One line saying why the file ``out`` (given as ``option``) cannot be written where it is
    named: it is a directory (the fix names ``example`` in it), or its directory does not exist;
    None otherwise."""
    path = Path(out)
    if path.is_dir():
        return f"{out}: is a directory; give {option} a file name, e.g. {path / example}"
    if not path.parent.is_dir():
        return f"{out}: no directory {path.parent}: give {option} a file in a directory that exists"
    return None


def not_a_file(out: str | os.PathLike, what: str) -> str | None:
    """One line saying that ``out`` is there and no regular file (a device, a FIFO; a directory is
    the caller's), which ``what``, written beside it and renamed over it, would replace; None
    when it is a regular file or not there."""
    try:
        mode = os.stat(out).st_mode
    except OSError:                         # not there (or not to be looked at): the write says why
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    return f"{out}: is a {file_kind(mode)}, not a regular file: {what} would replace it; give --out a file name"


def capture_refused(path: str, inputs: Iterable[str | os.PathLike]) -> str | None:
    """One line saying why the ``--capture`` file ``path`` (the port's bytes appended to it) is
    refused: one of ``inputs`` (the configuration and the files it names), or there and no
    regular file (a device, a directory, a FIFO); None when it is neither."""
    try:
        mode = os.stat(path).st_mode
    except OSError:                         # not there: made by the open (which says why it cannot)
        return None
    if not stat.S_ISREG(mode):
        return (f"{path}: is a {file_kind(mode)}, not a regular file: --capture takes a file to append the "
                "port's bytes to")
    return overwritten_input(path, inputs, option="--capture")


def with_sidecars(captures: Iterable[str]) -> list[str]:
    """The captures and the sidecars beside them (an import's ``CAPTURE.json``), which a command
    reading a capture reads too."""
    return [p for c in captures for p in (c, f"{c}.json")]
