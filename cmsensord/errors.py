"""The one exception family of cmsensord, and the process exit codes.

Every error a user can cause (a bad configuration file, an unwritable output
directory, a serial port that is not there) is a :class:`CmsensordError` whose
``str()`` is one line naming the file, key or device and the reason; the CLI
prints that line and exits with a non-zero code instead of a traceback.
"""

from __future__ import annotations

import errno
import os
import stat
from collections.abc import Iterator
from typing import Any

__all__ = [
    "CmsensordError",
    "ConfigError",
    "SinkError",
    "CaptureFileError",
    "InstanceError",
    "LinkError",
    "Interrupted",
    "EXIT_USAGE",
    "EXIT_CONFIG",
    "EXIT_INTERRUPTED",
    "file_kind",
]

#: Exit code for a command-line usage error (as argparse uses).
EXIT_USAGE = 2
#: Exit code for a configuration error (EX_CONFIG of sysexits.h).
EXIT_CONFIG = 78
#: Exit code of a command stopped by Ctrl-C, as a shell reports a process ended by SIGINT.
EXIT_INTERRUPTED = 130

_NO_VALUE = object()
_MAX_VALUE_REPR = 60


def _one_line(text: str) -> str:
    """Collapse whitespace runs (newlines included) to single spaces."""
    return " ".join(str(text).split())


def _short_repr(value: object) -> str:
    """repr() of a value, on one line and at most ~60 characters.

    Lists, tuples, dicts and sets are written piece by piece and the writing stops once
    the text is long enough, so a value that shares one sub-list many times over (a
    YAML alias bomb) costs what is shown, not its full repr.
    """
    parts: list[str] = []
    length = 0
    check_at = _MAX_VALUE_REPR
    try:
        for piece in _repr_pieces(value, set()):
            parts.append(piece)
            length += len(piece)
            if length > check_at:           # whitespace collapses: measure the one-line text
                if len(_one_line("".join(parts))) > _MAX_VALUE_REPR:
                    break
                check_at = 2 * length
    except Exception:  # a broken __repr__ must not hide the config error
        parts = [f"<{type(value).__name__}>"]
    text = _one_line("".join(parts))
    if len(text) > _MAX_VALUE_REPR:
        text = text[: _MAX_VALUE_REPR - 3] + "..."
    return text


def _repr_pieces(value: Any, inside: set[int]) -> Iterator[str]:
    """repr(value) in pieces, the same text for the built-in containers (``[...]`` for a
    container inside itself)."""
    kind = type(value)
    if kind not in (list, tuple, dict, set, frozenset) or (kind in (set, frozenset) and not value):
        yield repr(value)
        return
    if id(value) in inside:
        yield "[...]" if kind is list else "{...}" if kind is dict else repr(value)
        return
    inside.add(id(value))
    brackets: dict[type, tuple[str, str]] = {list: ("[", "]"), tuple: ("(", ")"), dict: ("{", "}"), set: ("{", "}"),
                        frozenset: ("frozenset({", "})")}
    opening, closing = brackets[kind]
    yield opening
    if kind is dict:
        for i, (k, v) in enumerate(value.items()):
            yield ", " if i else ""
            yield from _repr_pieces(k, inside)
            yield ": "
            yield from _repr_pieces(v, inside)
    else:
        for i, item in enumerate(value):
            yield ", " if i else ""
            yield from _repr_pieces(item, inside)
        if kind is tuple and len(value) == 1:
            yield ","
    yield closing
    inside.discard(id(value))


def file_kind(mode: int) -> str:
    """What a file that is not a regular one is (``st_mode``), for the line refusing it: a FIFO, a
    character device (/dev/zero), ..."""
    for test, name in ((stat.S_ISDIR, "directory"), (stat.S_ISFIFO, "FIFO"), (stat.S_ISCHR, "character device"),
                       (stat.S_ISBLK, "block device"), (stat.S_ISSOCK, "socket")):
        if test(mode):
            return name
    return "special file"


def bad_link(name: str | os.PathLike[str], real: str = "the real file") -> str:
    """What is wrong with ``name`` when it is a symbolic link that leads nowhere: "a symlink loop
    (...): point it at ``real``" when following it comes back to itself, "a symlink to X, which is
    not there" when its target is missing; "" when it is no such link (not there at all, or a link
    that resolves)."""
    try:
        os.stat(name)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return f"a symlink loop (too many levels of symbolic links): point it at {real}"
        if os.path.islink(name):
            return f"a symlink to {os.readlink(name)}, which is not there"
    except ValueError:
        pass
    return ""


class CmsensordError(Exception):
    """Base class of every error cmsensord raises on purpose."""


class ConfigError(CmsensordError):
    """A configuration that cannot be used.

    Attributes:
        source: the file name (or ``"<dict>"``, ``"<code>"``) the settings came from.
        path: the key path, e.g. ``"channels[1].r_max"``; for an error about the
            file itself (missing, unreadable, YAML syntax) the file name.
        reason: what is wrong, e.g. ``"must be > 0"``.
        value: the offending value, if there is one (else absent from ``str()``).

    ``str()`` is one line: ``"FILE: KEY.PATH: reason (got VALUE)"``; for an
    error about the file itself: ``"FILE: reason"``.
    """

    def __init__(
        self,
        source: str,
        path: str | None,
        reason: str,
        value: object = _NO_VALUE,
    ) -> None:
        self.source = str(source)
        self.path = self.source if not path else str(path)
        self.reason = _one_line(reason)
        self.value = None if value is _NO_VALUE else value
        self.has_value = value is not _NO_VALUE
        super().__init__(self._format())

    def _format(self) -> str:
        head = self.source if self.path == self.source else f"{self.source}: {self.path}"
        text = f"{head}: {self.reason}"
        if self.has_value:
            text += f" (got {_short_repr(self.value)})"
        # a file name or key may hold a line break; the message stays one line
        return text.replace("\r", "\\r").replace("\n", "\\n")

    def __str__(self) -> str:
        return self._format()

    def relocated(self, source: str, prefix: str = "") -> ConfigError:
        """The same error seen from a containing document.

        ``prefix`` is prepended to the key path (``"channels[2]"`` + ``"r_max"``
        gives ``"channels[2].r_max"``); ``source`` replaces the file name.
        """
        if self.path == self.source:
            path = prefix or source
        elif prefix:
            path = f"{prefix}.{self.path}"
        else:
            path = self.path
        value = self.value if self.has_value else _NO_VALUE
        return ConfigError(source, path, self.reason, value)


class SinkError(CmsensordError):
    """An output (MCAP file, directory) that cannot be written."""


class CaptureFileError(SinkError):
    """A daemon's ``--capture`` file that cannot be written, or must not be (exit 78)."""


class InstanceError(CmsensordError):
    """Another daemon already runs on this output directory (exit 78: systemd does not restart)."""


class LinkError(CmsensordError):
    """A serial link or capture file that cannot be opened or read."""


class Interrupted(CmsensordError):
    """A one-shot command stopped by Ctrl-C (SIGINT); ``str()`` is one line saying how far it got
    and what it left on disk; exit status :data:`EXIT_INTERRUPTED`."""
