"""The names of a sink's log files in a directory, and their order: the order they were opened.

A file is named ``<prefix>-<UTC yyyymmddTHHMMSSZ>.mcap`` after the wall clock when it is
opened, with ``-1``, ``-2``, ... (:func:`next_name`) when the name of that second is taken.
A new name never sorts before a name of the same prefix already in the directory: when the
wall clock is behind the newest stamp there (it stepped back: an NTP sync, a board without
an RTC battery), the file takes the newest stamp with the next number instead of its own
(``cmsensord-20261130T132741Z-1.mcap`` after ``cmsensord-20261130T132741Z.mcap``, though
the clock says 12:27). So the names' order (:func:`order_key`: by stamp, then number,
``-2`` before ``-10``; ``ls -v`` shows it) is the order the files were opened, across
restarts too, and retention's "oldest" is the file opened first whatever the clock did.
Files left by older versions, named by the wall clock alone, keep their names' order, and
every file opened after them sorts after them.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from cmsensord.errors import CmsensordError, bad_link, file_kind

__all__ = ["KEPT", "SALVAGED", "empty_files", "log_files", "log_name", "log_paths", "next_name", "order_key",
           "salvaged_path"]

SALVAGED = ".salvaged"
_STAMP = r"\d{8}T\d{6}Z"


#: what salvage renames a ``.part`` it keeps to (damaged; nothing recoverable, not MCAP)
KEPT = (".damaged", ".unreadable")


def log_name(prefix: str) -> re.Pattern[str]:
    """File names a sink writes with ``prefix``: finished, salvaged and .part, and a .part salvage
    kept (groups: the stamp, the number or None, ``.part`` or None, a :data:`KEPT` suffix or None)."""
    kept = "|".join(re.escape(k) for k in KEPT)
    return re.compile(
        rf"{re.escape(prefix)}-({_STAMP})(?:-(\d+))?(?:{re.escape(SALVAGED)})?\.mcap(?:(\.part)({kept})?)?"
    )


_ANY = re.compile(rf"(.*)-({_STAMP})(?:-(\d+))?((?:{re.escape(SALVAGED)})?\.mcap(?:\.part)?)")


def order_key(name: str) -> tuple:
    """A key that sorts log file names (any prefix) in the order they were opened: by
    prefix, stamp, then number (``-2`` before ``-10``, no number first); other names by
    name, after the logs of a prefix they start with."""
    m = _ANY.fullmatch(name)
    if m is None:
        return (name, "~")
    return (m.group(1), m.group(2), int(m.group(3) or 0), m.group(4))


def log_files(out_dir: str | Path, prefix: str, *, kept: bool = False) -> tuple[list[Path], list[Path]]:
    """(finished ``*.mcap``, unfinished ``*.mcap.part``) files of ``prefix`` in ``out_dir``,
    each oldest first (the order they were opened: :func:`order_key`). Only names this sink
    writes count: another prefix's files, or other files, are never listed. A missing
    directory has none. ``kept``: the ``.part`` files salvage kept (``*.mcap.part.damaged``,
    ``*.mcap.part.unreadable``) are among the finished ones (retention's), else in neither.
    """
    pattern = log_name(prefix)
    finished: list[tuple[str, int, str]] = []
    parts: list[tuple[str, int, str]] = []
    try:
        names = os.listdir(out_dir)
    except FileNotFoundError:
        return [], []
    for name in names:
        m = pattern.fullmatch(name)
        if m is None or (m.group(4) and not kept):
            continue
        (parts if m.group(3) and not m.group(4) else finished).append((m.group(1), int(m.group(2) or 0), name))
    return ([Path(out_dir) / n for *_key, n in sorted(finished)],
            [Path(out_dir) / n for *_key, n in sorted(parts)])


def next_name(out_dir: Path, prefix: str, stamp: str) -> tuple[str, int]:
    """The stamp and the first number for a new file of ``prefix`` opened at ``stamp``: after
    the newest name of the directory (finished, salvaged or .part). ``stamp`` with 0 when it
    is newer than every name there; else the newest stamp with its number + 1 (the same
    second, or a clock that stepped back). An unreadable directory: ``stamp``, 0."""
    pattern = log_name(prefix)
    newest: tuple[str, int] | None = None
    try:
        for name in os.listdir(out_dir):
            m = pattern.fullmatch(name)
            if m is not None:
                key = (m.group(1), int(m.group(2) or 0))
                newest = key if newest is None or key > newest else newest
    except OSError:
        pass  # the open reports an unusable directory
    if newest is None or stamp > newest[0]:
        return stamp, 0
    return newest[0], newest[1] + 1


def salvaged_path(part: str | Path) -> Path:
    """``<stem>.mcap.part`` -> ``<stem>.salvaged.mcap`` (the name of its salvaged file)."""
    part = Path(part)
    name = part.name
    stem = name[: -len(".mcap.part")] if name.endswith(".mcap.part") else name
    return part.with_name(stem + SALVAGED + ".mcap")


def log_paths(names: list[str]) -> list[Path]:
    """The files of ``names`` (files, or directories of logs), in order, each once.

    Raises CmsensordError (one line) for a name that does not exist, is no regular file
    (a FIFO is never opened: nothing waits for a writer) or a directory without logs.
    """
    out: list[Path] = []
    for name in names:
        p = Path(name)
        if p.is_dir():
            found = sorted((f for f in p.iterdir() if f.is_file() and f.name.endswith((".mcap", ".mcap.part"))),
                           key=lambda f: order_key(f.name))
            if not found:
                raise CmsensordError(f"{name}: no MCAP logs (*.mcap, *.mcap.part) in this directory")
            out.extend(found)
        elif p.is_file():
            out.append(p)
        else:
            raise CmsensordError(_not_a_log(name))
    seen: set[Path] = set()
    return [p for p in out if not (p.resolve() in seen or seen.add(p.resolve()))]   # type: ignore[func-returns-value]


#: the names a line on empty files gives before the count of the rest
EMPTY_SHOWN = 5


def empty_files(paths: list[str]) -> str:
    """One phrase on the empty files ``paths`` (0 bytes, no MCAP data): their count and the first
    :data:`EMPTY_SHOWN` names (``3,000 empty file(s) (0 bytes): a.mcap, b.mcap, ... (2,995 more)``);
    thousands of them (a crash loop that opened a log each time) are one line, not one each."""
    more = f", ... ({len(paths) - EMPTY_SHOWN:,} more)" if len(paths) > EMPTY_SHOWN else ""
    return f"{len(paths):,} empty file(s) (0 bytes): {', '.join(map(str, paths[:EMPTY_SHOWN]))}{more}"


def _not_a_log(name: str) -> str:
    """The line on ``name``, neither a directory nor a regular file: not there, or what it is."""
    try:
        mode = os.stat(name).st_mode
    except (OSError, ValueError):
        return f"{name}: {bad_link(name) or 'file not found'}"
    return f"{name}: not a regular file (a {file_kind(mode)}): give an MCAP log or a directory of them"
