"""The one exception family of cmsensord, and the process exit codes.

Every error a user can cause (a bad configuration file, an unwritable output
directory, a serial port that is not there) is a :class:`CmsensordError` whose
``str()`` is one line naming the file, key or device and the reason; the CLI
prints that line and exits with a non-zero code instead of a traceback.
"""

from __future__ import annotations

__all__ = [
    "CmsensordError",
    "ConfigError",
    "SinkError",
    "LinkError",
    "EXIT_USAGE",
    "EXIT_CONFIG",
]

#: Exit code for a command-line usage error (as argparse uses).
EXIT_USAGE = 2
#: Exit code for a configuration error (EX_CONFIG of sysexits.h).
EXIT_CONFIG = 78

_NO_VALUE = object()
_MAX_VALUE_REPR = 60


def _one_line(text: str) -> str:
    """Collapse whitespace runs (newlines included) to single spaces."""
    return " ".join(str(text).split())


def _short_repr(value: object) -> str:
    """repr() of a value, on one line and at most ~60 characters."""
    try:
        text = repr(value)
    except Exception:  # a broken __repr__ must not hide the config error
        text = f"<{type(value).__name__}>"
    text = _one_line(text)
    if len(text) > _MAX_VALUE_REPR:
        text = text[: _MAX_VALUE_REPR - 3] + "..."
    return text


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


class LinkError(CmsensordError):
    """A serial link or capture file that cannot be opened or read."""
