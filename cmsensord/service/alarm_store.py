"""The alarm state file: latches and acknowledgements kept over a daemon's restart.

``<output.dir>/<output.prefix>-alarms.json`` holds, per alarm showing a level or holding a
latch, the saved record of :mod:`cmsensord.alarms.saved`::

    {"format": "cmsensord-alarms", "version": 1, "saved_ns": ..., "alarms": {"sev/ch0": {...}}}

It belongs to the daemon holding the output directory's lock (:mod:`.instance`): the live
daemon reads it at start and writes it whenever the saved state changes (an alarm's level,
latch or acknowledgement; not with each message).  A write is atomic: a temporary file in
the same directory, fsync, rename over the file, fsync of the directory; a crash leaves the
old file or the new one, whole.  ``cmsensord replay`` and ``--simulate`` never touch it.

A file that cannot be read or is not a whole state file (truncated, edited) is one
``alarm_state_error`` event (a warning) and is kept aside as ``<file>.bad``; the daemon then
starts with no alarm state restored.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from pathlib import Path
from typing import Any

from cmsensord.alarms.saved import check

__all__ = ["AlarmStore", "StateFileError", "state_path", "keep_alarm_state"]

FORMAT = "cmsensord-alarms"
VERSION = 1


class StateFileError(Exception):
    """The state file is there but not a state file this daemon reads (why: the message)."""


def state_path(out_dir: str | os.PathLike, prefix: str) -> Path:
    """The alarm state file of a daemon writing to ``out_dir`` with file prefix ``prefix``."""
    return Path(out_dir) / f"{prefix}-alarms.json"


class AlarmStore:
    """Reads and writes one alarm state file (see module docstring)."""

    def __init__(self, path: Path):
        self.path = path

    def load(self) -> dict[str, dict[str, Any]]:
        """The saved records by alarm name ({} when there is no file); StateFileError when it
        cannot be read or is not a whole state file (truncated, edited, another format)."""
        try:
            text = self.path.read_bytes()
        except FileNotFoundError:
            return {}
        except OSError as exc:
            raise StateFileError(f"cannot read it ({exc.strerror or exc})") from None
        try:
            doc = json.loads(text)
        except ValueError as exc:
            raise StateFileError(f"not JSON (truncated?): {exc}") from None
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise StateFileError(f"not a {FORMAT} file")
        if doc.get("version") != VERSION:
            raise StateFileError(f"version {doc.get('version')!r}, this daemon reads {VERSION}")
        try:
            return check(doc.get("alarms"))
        except ValueError as exc:
            raise StateFileError(str(exc)) from None

    def save(self, alarms: dict[str, dict[str, Any]]) -> None:
        """Replace the file with ``alarms``, atomically (see module docstring); OSError if not."""
        data = json.dumps({"format": FORMAT, "version": VERSION, "saved_ns": time.time_ns(),
                           "alarms": alarms}, indent=1, sort_keys=True).encode() + b"\n"
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o644)
            try:
                view = memoryview(data)
                while view:
                    view = view[os.write(fd, view):]
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(tmp, self.path)
        except OSError:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise
        dfd = os.open(self.path.parent, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


def keep_alarm_state(cfg, proc) -> None:
    """The live daemon's alarm state: what the state file of ``cfg.output`` holds goes back into
    ``proc``'s alarms (with their first message), which keep it there from now on."""
    store = AlarmStore(state_path(cfg.output.dir, cfg.output.prefix))
    try:
        saved = store.load()
    except StateFileError as exc:
        bad = store.path.with_name(store.path.name + ".bad")
        try:
            os.replace(store.path, bad)
            aside = f"kept as {bad.name}"
        except OSError as err:
            aside = f"not moved aside ({err.strerror or err})"
        proc.event("alarm_state_error", None, f"{store.path}: {exc}: {aside}; no latch or acknowledgement "
                   "is restored", details={"file": str(store.path), "kept": str(bad)})
        saved = {}
    proc.log.add(proc.alarms.keep(store, saved))
