"""What the rotating sink's disk and salvage events say (:class:`~cmsensord.sinks.rotating.RotatingSink`):
the text and fields of a file abandoned after an error, a file removed while open, logging
resumed, a failed disk operation and a salvage's result; retention's are
:mod:`cmsensord.sinks.retention`'s.

A salvage that the full disk refuses (:data:`FULL`), of a file abandoned during this run or of an
earlier run's leftover at start, does not give the file up: it waits in the sink's list of
abandoned files and is tried again when logging resumes and after each rotation
(:func:`salvage_abandoned`, :func:`refused`); at a stop it is left for the next start.

A disk event is a ``disk_error`` event (:data:`~cmsensord.sinks.retention.DISK_EVENT`) told
apart by ``details["action"]``; a function here returns ``(message, fields)`` for the sink's
``emit``, but :func:`salvage_result`, which queues its event on the sink itself.
"""

from __future__ import annotations

import errno
import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cmsensord.sinks.mcap_file import SinkIOError
from cmsensord.sinks.mcap_salvage import SalvageResult, salvage
from cmsensord.sinks.retention import DISK_EVENT, errno_name, still_there

if TYPE_CHECKING:
    from cmsensord.sinks.rotating import RotatingSink

log = logging.getLogger("cmsensord")
#: the kind of a salvage's event (a value of ``event_schema.EVENT_KINDS``); outages and their end are
#: ``disk_error`` events told apart by ``details["action"]``, retention's deletions ``retention`` ones
SALVAGE_EVENT = "salvage"
#: errno values of a full disk: a file abandoned for them is salvaged again once there is room
FULL = frozenset({errno.ENOSPC, errno.EDQUOT})


def error_details(action: str, err: SinkIOError, file: Path | str, **more: Any) -> dict[str, Any]:
    """``details`` of an event about the failed operation ``err`` on ``file``."""
    return {"action": action, "op": err.op, "errno": errno_name(err.errno), **more, "file": str(file)}


def dir_fsync_failed(sink: RotatingSink, err: SinkIOError, file: Path) -> None:
    """The directory fsync after creating or finishing ``file`` failed: one failed operation and
    its event; the file is written (or finished) all the same."""
    sink.disk_errors += 1
    sink.emit(DISK_EVENT, str(err), details=error_details("dir_fsync_failed", err, file))


def abandoned(err: SinkIOError, kept: Path | None, had_file: bool, lost: int, unsure: int,
              retry_s: float) -> tuple[str, dict[str, Any]]:
    """The first error of an outage: the file kept for salvage (``kept``) or removed; ``lost``
    messages, ``unsure`` more maybe not on disk. With no file (``had_file`` False: none could
    be opened) one line says that nothing is logged and how often it is tried again."""
    if not had_file:                     # no file could be opened (at start, or after a rotation)
        return (f"not logging: {err}; retrying every {retry_s:g} s",
                {"count": lost, "details": error_details("abandoned", err, err.path, unsynced=unsure)})
    what = f"file kept as {kept.name} for salvage" if kept is not None else "file removed (no complete chunk)"
    unsure_text = f" ({unsure} more written since the last good fsync may not be on the disk)" if unsure else ""
    return (f"{err}; {what}; {lost} message(s) lost{unsure_text}; trying a new file at once, then "
            f"every {retry_s:g} s",
            {"count": lost, "details": error_details("abandoned", err, kept or err.path, unsynced=unsure)})


def removed(part: Path, lost: int) -> tuple[str, dict[str, Any]]:
    """The open file was removed under the sink, with the ``lost`` messages written to it."""
    return (f"{part} was removed while open (output directory deleted?): {lost} message(s) written to "
            "it lost; logging goes on in a new file", {"count": lost, "details": {"action": "removed",
                                                                                 "file": str(part)}})


def resumed(where: str, outage: dict[str, Any], seconds: float) -> tuple[str, dict[str, Any]]:
    """Logging is back in ``where`` after an outage of ``seconds``."""
    return (f"logging resumed in {where} after {seconds:.1f} s: {outage['dropped']} message(s) could "
            f"not be logged ({outage['errors']} failed disk operation(s); first: {outage['error']})",
            {"count": outage["dropped"], "details": {"action": "resumed", "errors": outage["errors"]}})


def outage_state(outage: dict[str, Any], now: float) -> str:
    """The outage in progress, for the status line: since when, what failed, what was dropped."""
    return (f"disk: not logging for {now - outage['start']:.0f} s ({outage['error']}); "
            f"{outage['dropped']} message(s) dropped")


def salvage_abandoned(sink: RotatingSink, parts: list[Path]) -> list[Path]:
    """Salvage the files an outage abandoned, once logging is back: each one's event, and a
    salvaged file joins ``sink.paths``. Returns those a full disk refused (:data:`FULL`): they
    wait, tried again later; each failure is counted in ``sink.disk_errors``, the first of a
    file is an event. A file no longer there (an operator removed it) is dropped, quietly."""
    waiting = []
    for part in still_there(parts):
        try:
            result: SalvageResult | SinkIOError = salvage(part)
        except SinkIOError as err:
            result = err
        if isinstance(result, SinkIOError) and result.errno in FULL and still_there([part]):
            waiting.append(part)
            refused(sink, result, part)
            continue
        salvage_result(sink, result)
        if isinstance(result, SalvageResult) and result.path is not None and result.action == "salvaged":
            sink.paths = [*still_there(sink.paths), result.path]
    sink._salvage_told.difference_update(set(parts) - set(waiting))
    return waiting


def refused(sink: RotatingSink, err: SinkIOError, part: Path) -> None:
    """The full disk refused ``part``'s salvage (``err``, :data:`FULL`), which waits: counted in
    ``sink.disk_errors``; the first refusal of a file is an event, the next ones are not."""
    sink.disk_errors += 1
    if part not in sink._salvage_told:
        sink._salvage_told.add(part)
        sink.emit(DISK_EVENT, f"{err}; tried again after the next rotation",
                  details=error_details("salvage_failed", err, part))


def left_waiting(parts: list[Path]) -> None:
    """At a stop: the abandoned files not salvaged yet (``parts``, those still there), one
    journal line; the next start salvages them."""
    parts = still_there(parts)
    if parts:
        log.info("%d log file(s) kept for salvage and not salvaged yet: %s; left for the next start",
                 len(parts), ", ".join(p.name for p in parts))


def salvage_result(sink: RotatingSink, result: SalvageResult | SinkIOError) -> None:
    """A salvage's result as the ``sink``'s event: a ``salvage`` event or a ``disk_error`` one
    (counted in ``sink.disk_errors``); none for a file another writer has open, nor for a salvage
    a stop interrupted (the journal says so). Called by the thread that writes only (the salvage
    thread hands its results over, :meth:`~.disk_outage.DiskOutages._take_salvaged`)."""
    if isinstance(result, SinkIOError):
        sink.disk_errors += 1
        sink.emit(DISK_EVENT, f"{result}; left for the next start",
                  details=error_details("salvage_failed", result, result.path))
        return
    if result.action == "busy":
        return                           # another writer's open file
    if result.action == "interrupted":   # stopping: the journal says so, the file is intact
        log.info("%s", result.message())
        return
    sink.emit(SALVAGE_EVENT, result.message(), count=result.messages, details=result.event_details())
