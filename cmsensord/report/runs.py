"""Which logs a report draws, and together with which: one part a recording, of each imported
recording its newest replay and the batch orders of its newest ``vkf`` run.

A replay or a ``vkf`` run of an imported recording writes the recording's timeline, the real
path of the capture it read (``source``) and the log time of its board second 0
(``board_zero_ns``) into its log's ``cmsensord`` metadata
(:class:`~cmsensord.service.replay.RecordingHead`); the last differs from one run to the next.
The capture and the timeline tell the recording (a ``source`` that is no real path, of a log
written before there was one, is read as one from here); logs that are no run of an import (a
board's, a replay of a board's capture) are together one more. Each recording is drawn on its
own (:class:`Recording`): two machines' imports replayed into one directory, with the same
channel names, would otherwise be drawn as one trace running back and forth between them, over
times that overlap, and their events listed as one machine's.

Replaying the same capture again into the same directory (after a new calibration, say) gives
a second log over the same recording time: drawn together, each trace would run back from the
end of one replay to the start of the other, and every event would be listed twice. The report
draws the newest replay of each recording (the latest board second 0; all its files, as a
rotation splits them), which holds the configuration in use, and leaves the older ones out,
saying so in one line per recording (:attr:`Recording.notes`). Of its ``vkf`` runs (whose logs
say ``batch_vkf``) likewise the newest; beside a replay only that run's batch orders are read
(:attr:`Recording.batch_only`: the rest of its log is a replay's again), without one all of it.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cmsensord.importing.timeline import Timeline

__all__ = ["Recording", "plan_logs", "ident", "BOARD_LOGS"]

#: older replays named in a note; more are counted
NAMED = 3
#: the name of the part of the logs that are no replay of an import, beside recordings that are
BOARD_LOGS = "board logs"


@dataclass
class Recording:
    """One recording's logs: its name (the file name of the imported capture its logs read; ""
    for logs that are no run of an import), its :attr:`ident`, the files to draw with the log
    time of each one's board second 0 (None: not a run of an import, or its timeline cannot be
    read), of them those read for their batch orders only, and the files left out with why."""

    name: str = ""
    paths: list[Path] = field(default_factory=list)
    zeros: list[int | None] = field(default_factory=list)
    left_out: list[tuple[Path, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: the start of its HTML ids and PNG names, among several recordings: :func:`ident` of its
    #: name, numbered where another recording's is the same (``x y.bin`` and ``x-y.bin``)
    ident: str = ""
    #: files of a ``vkf`` run drawn beside a replay: only their batch orders are read
    batch_only: set[Path] = field(default_factory=set)


def ident(name: str) -> str:
    """A recording's name as the start of an HTML id and of a file name: letters, digits, ``.``,
    ``_`` and ``-``."""
    return re.sub(r"[^A-Za-z0-9._-]+", "-", name).strip("-") or "recording"


def plan_logs(paths: list[Path], metadata: list[dict[str, dict[str, str]]]) -> list[Recording]:
    """The :class:`Recording` s of ``paths`` whose head metadata is ``metadata`` (one dict per
    file), in the order of their first file; recordings of one name (one capture imported
    twice, with other snapshots) are told apart by a number (``b11.bin (2)``); the logs that
    are no run of an import are one, named :data:`BOARD_LOGS` beside others."""
    # recording -> run kind (replay, vkf) -> board zero -> files
    runs: dict[tuple[str, str] | None, dict[str, dict[int | None, list[int]]]] = {}
    for i, meta in enumerate(metadata):
        head = meta.get("cmsensord", {})
        parsed = Timeline.from_json(head.get("recording_timeline") or "")
        key = None if parsed is None else (_real(head.get("source", "")), parsed[0].to_json(0))
        kind = "vkf run" if parsed is not None and "batch_vkf" in head else "replay"
        runs.setdefault(key, {}).setdefault(kind, {}).setdefault(None if parsed is None else parsed[1], []).append(i)
    recordings = []
    named: dict[str, int] = {}
    for key, kinds in runs.items():
        name = "" if key is None else Path(key[0]).name or "an imported recording"
        named[name] = named.get(name, 0) + 1
        rec = Recording(name if named[name] == 1 else f"{name} ({named[name]})")
        dropped: dict[int, str] = {}
        for kind, by_zero in kinds.items():
            if len(by_zero) > 1 and key is not None:
                rec.notes.append(_left_out(rec.name, kind, by_zero, paths, dropped))
            for zero, files in by_zero.items():
                rec.paths.extend(paths[i] for i in files if i not in dropped)
                rec.zeros.extend(zero for i in files if i not in dropped)
                if kind == "vkf run" and "replay" in kinds:
                    rec.batch_only.update(paths[i] for i in files if i not in dropped)
        rec.left_out = [(paths[i], why) for i, why in sorted(dropped.items())]
        recordings.append(rec)
    if len(recordings) > 1:
        for rec in recordings:
            rec.name = rec.name or BOARD_LOGS
    _number_idents(recordings)
    return recordings


def _real(source: str) -> str:
    """A capture's path as one text however it was spelled (relative, through a link); one that
    is no path (a NUL in a damaged log's text) as it is."""
    try:
        return os.path.realpath(source) if source else ""
    except ValueError:
        return source


def _number_idents(recordings: list[Recording]) -> None:
    """Each recording's :attr:`Recording.ident`: :func:`ident` of its name, ``-2``, ``-3`` ... after
    it where a recording before took it."""
    taken: set[str] = set()
    for rec in recordings:
        base = rec.ident = ident(rec.name)
        n = 1
        while rec.ident in taken:
            n += 1
            rec.ident = f"{base}-{n}"
        taken.add(rec.ident)


def _left_out(name: str, kind: str, by_zero: dict[Any, list[int]], paths: list[Path], dropped: dict[int, str]) -> str:
    """The note on one recording replayed (``kind`` "replay") or run through vkf ("vkf run") more
    than once; its older runs' files into ``dropped``."""
    newest = max(by_zero)
    older = [i for zero in sorted(by_zero, reverse=True) if zero != newest for i in by_zero[zero]]
    for i in older:
        dropped[i] = f"left out: an older {kind} of {name}"
    names = ", ".join(paths[i].name for i in older[:NAMED]) + (
        f" and {len(older) - NAMED} more file(s)" if len(older) > NAMED else "")
    done = "replayed" if kind == "replay" else "run through vkf"
    subject = name[:1].upper() + name[1:] if name.startswith("an ") else name
    return (f"{subject} was {done} {len(by_zero)} times into these logs: the report draws the newest {kind} "
            f"({', '.join(paths[i].name for i in by_zero[newest])}) and leaves out "
            f"{'the older one' if len(by_zero) == 2 else f'the {len(by_zero) - 1} older ones'} ({names}).")
