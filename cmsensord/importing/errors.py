"""The import's one error: a single line naming the file, the column or variable, and the fix."""

from __future__ import annotations

from cmsensord.errors import CmsensordError

__all__ = ["CHOOSE", "ImportFailure", "cannot_write", "no_room"]

#: how an import leaves channels out
CHOOSE = "--channels, or --array / --variable for .npz / .mat"


class ImportFailure(CmsensordError):
    """A recording that cannot be imported as asked.

    ``str()`` is one line, ``"FILE: what is wrong; what to do"`` (whitespace
    runs, newlines included, collapse to one space). The command prints it after
    ``cmsensord import: `` and exits with status 2.
    """

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).split()))


def cannot_write(out: str | object, reason: str) -> ImportFailure:
    """The one error for an output the import cannot write (``reason``: the OS's words)."""
    return ImportFailure(f"{out}: cannot write the capture: {reason}; check that the directory exists, "
                         "is writable and has room")


def no_room(what: str, reason: str) -> ImportFailure:
    """The one error for a disk that cannot hold what the import keeps beside ``--out`` while it
    runs (``what``: where and what, ``reason``: the OS's words)."""
    return ImportFailure(f"{what}: {reason}; free space, give --out on another disk or hold more in memory "
                         "with --memory-mb")
