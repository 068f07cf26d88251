"""Which logs a report draws, and together with which: one part a recording, of each imported
recording its newest replay.

A replay of an imported recording writes the recording's timeline, the capture it read
(``source``) and the log time of its board second 0 (``board_zero_ns``) into its log's
``cmsensord`` metadata; the last differs from one replay to the next. The capture and the
timeline tell the recording; logs that are no replay of an import (a board's, a replay of a
board's capture) are together one more. Each recording is drawn on its own
(:class:`Recording`): two machines' imports replayed into one directory, with the same channel
names, would otherwise be drawn as one trace running back and forth between them, over times
that overlap, and their events listed as one machine's.

Replaying the same capture again into the same directory (after a new calibration, say) gives
a second log over the same recording time: drawn together, each trace would run back from the
end of one replay to the start of the other, and every event would be listed twice. The report
draws the newest replay of each recording (the latest board second 0; all its files, as a
rotation splits them), which holds the configuration in use, and leaves the older ones out,
saying so in one line per recording (:attr:`Recording.notes`).
"""

from __future__ import annotations

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
    """One recording's logs: its name (the imported capture the replays read, as the replay was
    given it; "" for logs that are no replay of an import), the files to draw with the log time
    of each one's board second 0 (None: not a replay of an import, or its timeline cannot be
    read), and the files left out with why."""

    name: str = ""
    paths: list[Path] = field(default_factory=list)
    zeros: list[int | None] = field(default_factory=list)
    left_out: list[tuple[Path, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)



def ident(name: str) -> str:
    """A recording's name as the start of an HTML id and of a file name: letters, digits, ``.``,
    ``_`` and ``-``."""
    return re.sub(r"[^A-Za-z0-9._-]+", "-", name).strip("-") or "recording"


def plan_logs(paths: list[Path], metadata: list[dict[str, dict[str, str]]]) -> list[Recording]:
    """The :class:`Recording` s of ``paths`` whose head metadata is ``metadata`` (one dict per
    file), in the order of their first file; recordings of one name (one capture imported
    twice, with other snapshots) are told apart by a number (``b11.bin (2)``); the logs that
    are no replay of an import are one, named :data:`BOARD_LOGS` beside others."""
    runs: dict[tuple[str, str] | None, dict[int | None, list[int]]] = {}   # recording -> board zero -> files
    for i, meta in enumerate(metadata):
        head = meta.get("cmsensord", {})
        parsed = Timeline.from_json(head.get("recording_timeline") or "")
        key = None if parsed is None else (head.get("source", ""), parsed[0].to_json(0))
        runs.setdefault(key, {}).setdefault(None if parsed is None else parsed[1], []).append(i)
    recordings = []
    named: dict[str, int] = {}
    for key, by_zero in runs.items():
        name = "" if key is None else Path(key[0]).name or "an imported recording"
        named[name] = named.get(name, 0) + 1
        rec = Recording(name if named[name] == 1 else f"{name} ({named[name]})")
        dropped: dict[int, str] = {}
        if len(by_zero) > 1 and key is not None:
            rec.notes.append(_left_out(key[0], by_zero, paths, dropped))
        for zero, files in by_zero.items():
            rec.paths.extend(paths[i] for i in files if i not in dropped)
            rec.zeros.extend(zero for i in files if i not in dropped)
        rec.left_out = [(paths[i], why) for i, why in sorted(dropped.items())]
        recordings.append(rec)
    if len(recordings) > 1:
        for rec in recordings:
            rec.name = rec.name or BOARD_LOGS
    return recordings


def _left_out(source: str, by_zero: dict[Any, list[int]], paths: list[Path], dropped: dict[int, str]) -> str:
    """The note on one recording replayed more than once; its older replays' files into ``dropped``."""
    newest = max(by_zero)
    older = [i for zero in sorted(by_zero, reverse=True) if zero != newest for i in by_zero[zero]]
    for i in older:
        dropped[i] = f"left out: an older replay of {source or 'the same recording'}"
    names = ", ".join(paths[i].name for i in older[:NAMED]) + (
        f" and {len(older) - NAMED} more file(s)" if len(older) > NAMED else "")
    return (f"{source or 'One imported recording'} was replayed {len(by_zero)} times into these logs: the "
            f"report draws the newest replay ({', '.join(paths[i].name for i in by_zero[newest])}) and "
            f"leaves out {'the older one' if len(by_zero) == 2 else f'the {len(by_zero) - 1} older ones'} ({names}).")
