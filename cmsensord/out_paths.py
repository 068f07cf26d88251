"""An ``--out`` that names one of the command's own inputs is refused before anything is read:
writing it would destroy the input (an import over its WAV, a report over its log)."""

from __future__ import annotations

import os
from collections.abc import Iterable

__all__ = ["overwritten_input", "with_sidecars"]


def overwritten_input(out: str | os.PathLike, inputs: Iterable[str | os.PathLike]) -> str | None:
    """One line saying that ``out`` is one of ``inputs`` (the same file, by any path or link),
    or None when it is none of them."""
    for src in inputs:
        try:
            same = os.path.samefile(out, src)
        except OSError:                     # one of them does not exist: not the same file
            continue
        if same:
            return (f"{out}: is the input {src}: writing it would destroy it; give --out another "
                    "file name")
    return None


def with_sidecars(captures: Iterable[str]) -> list[str]:
    """The captures and the sidecars beside them (an import's ``CAPTURE.json``), which a command
    reading a capture reads too."""
    return [p for c in captures for p in (c, f"{c}.json")]
