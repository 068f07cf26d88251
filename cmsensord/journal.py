"""Where the log goes: stderr, with sd-daemon priority prefixes when stderr is the journal.

Levels: the daemon logs INFO and up by default, one-shot subcommands WARNING
and up (they print their own summary); each ``-v`` shows one level more:

=========  ======================  ==================================================
option     daemon                  subcommands
=========  ======================  ==================================================
(none)     INFO                    WARNING
``-v``     VERBOSE (15): also the  INFO
           per-AKF anomaly flags
``-vv``    DEBUG: also the status  DEBUG
           line once a second,
           the log files' chunks
=========  ======================  ==================================================

Under systemd (``JOURNAL_STREAM`` names the device and inode of stderr, as
systemd sets it for a unit whose output is the journal) every line written to
stderr starts with its sd-daemon priority prefix (sd-daemon(3)): ``<3>`` error,
``<4>`` warning, ``<5>`` notice, ``<6>`` info, ``<7>`` debug; so ``journalctl -p
warning -u cmsensord`` finds the warnings and errors. Log records get the prefix
of their level; lines printed to stderr without a prefix (the run summary)
get ``<6>``; the one-line errors of the command line are written with
:func:`error_line` (``<3>``).
"""

from __future__ import annotations

import logging
import os
import sys
from typing import TextIO

from cmsensord.terminal_bar import erase_line

__all__ = ["VERBOSE", "PRIORITY", "under_journal", "setup_logging", "error_line", "JournalStream"]

#: between INFO and DEBUG: what ``-v`` adds to the daemon's log
VERBOSE = 15
logging.addLevelName(VERBOSE, "VERBOSE")

#: sd-daemon(3) priorities of the logging levels
PRIORITY = ((logging.ERROR, 3), (logging.WARNING, 4), (logging.INFO, 6), (VERBOSE, 7), (logging.DEBUG, 7))


def priority(level: int) -> int:
    """The syslog priority (3 error .. 7 debug) of a logging level."""
    for floor, prio in PRIORITY:
        if level >= floor:
            return prio
    return 7


def under_journal(stream: TextIO | None = None, env: dict[str, str] | None = None) -> bool:
    """True when ``stream`` (stderr) is the journal's stream: ``JOURNAL_STREAM`` is
    ``<device>:<inode>`` of that file descriptor (systemd.exec(5))."""
    value = (os.environ if env is None else env).get("JOURNAL_STREAM", "")
    stream = sys.stderr if stream is None else stream
    try:
        dev, ino = (int(x) for x in value.split(":"))
        st = os.fstat(stream.fileno())
    except (ValueError, OSError, AttributeError):
        return False
    return (st.st_dev, st.st_ino) == (dev, ino)


class JournalStream:
    """A text stream that gives every line written to it a priority prefix (``<6>`` unless
    the line has one), for the lines printed to stderr rather than logged."""

    def __init__(self, raw: TextIO, default: int = 6):
        self.raw = raw
        self.default = default
        self._at_line_start = True

    def write(self, text: str) -> int:
        out = []
        for piece in text.splitlines(keepends=True):
            if self._at_line_start and not _has_prefix(piece):
                out.append(f"<{self.default}>")
            out.append(piece)
            self._at_line_start = piece.endswith("\n")
        self.raw.write("".join(out))
        return len(text)

    def flush(self) -> None:
        self.raw.flush()

    def fileno(self) -> int:
        return self.raw.fileno()

    def isatty(self) -> bool:
        return False

    def __getattr__(self, name: str):
        return getattr(self.raw, name)


def _has_prefix(line: str) -> bool:
    return len(line) >= 3 and line[0] == "<" and line[1].isdigit() and line[2] == ">"


class _PrefixFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        prefix = f"<{priority(record.levelno)}>"
        return "\n".join(prefix + line for line in text.split("\n"))


class _BarHandler(logging.StreamHandler):
    """Records to a stream, each on a line of its own: a progress bar's line is erased first."""

    def emit(self, record: logging.LogRecord) -> None:
        erase_line()
        super().emit(record)


def level_for(verbose: int, daemon: bool) -> int:
    """The logging level for ``verbose`` (the count of ``-v``) of the daemon or a subcommand."""
    if daemon:
        return (logging.INFO, VERBOSE, logging.DEBUG)[min(verbose, 2)]
    return (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]


def setup_logging(verbose: int, daemon: bool = True) -> bool:
    """The ``cmsensord`` logger to stderr at the level of ``verbose`` (see the module
    docstring); under the journal with priority prefixes, and sys.stderr wrapped in a
    :class:`JournalStream`. Returns whether stderr is the journal."""
    journal = under_journal()
    handler = _BarHandler(sys.stderr)
    fmt = "%(levelname)s %(message)s"
    handler.setFormatter(_PrefixFormatter(fmt) if journal else logging.Formatter(fmt))
    root = logging.getLogger()
    for old in list(root.handlers):
        root.removeHandler(old)
    root.addHandler(handler)
    root.setLevel(level_for(verbose, daemon))
    if journal and not isinstance(sys.stderr, JournalStream):
        sys.stderr = JournalStream(sys.stderr)
    return journal


def error_line(text: str) -> None:
    """One error line on stderr (``<3>`` under the journal)."""
    prefix = "<3>" if isinstance(sys.stderr, JournalStream) else ""
    print(prefix + text, file=sys.stderr)
