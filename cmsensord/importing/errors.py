"""The import's one error: a single line naming the file, the column or variable, and the fix."""

from __future__ import annotations

from cmsensord.errors import CmsensordError

__all__ = ["ImportFailure"]


class ImportFailure(CmsensordError):
    """A recording that cannot be imported as asked.

    ``str()`` is one line, ``"FILE: what is wrong; what to do"`` (whitespace
    runs, newlines included, collapse to one space). The command prints it after
    ``cmsensord import: `` and exits with status 2.
    """

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).split()))
