"""Which logs a report draws: of each imported recording its newest replay, and every other log.

A replay of an imported recording writes the recording's timeline, the capture it read
(``source``) and the log time of its board second 0 (``board_zero_ns``) into its log's
``cmsensord`` metadata; the last differs from one replay to the next. Replaying the same
capture again into the same directory (after a new calibration, say) gives a second log over
the same recording time: drawn together, each trace would run back from the end of one replay
to the start of the other, and every event would be listed twice. The report draws the newest
replay of each recording (the latest board second 0; all its files, as a rotation splits
them), which holds the configuration in use, and leaves the older ones out, saying so in one
line per recording (:attr:`LogPlan.notes`). Logs of a board, and replays of other recordings,
are all drawn.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from cmsensord.importing.timeline import Timeline

__all__ = ["LogPlan", "plan_logs"]

#: older replays named in a note; more are counted
NAMED = 3


@dataclass
class LogPlan:
    """The files to draw with the log time of each one's board second 0 (None: not a replay of
    an import, or its timeline cannot be read), and the files left out with why."""

    paths: list[Path] = field(default_factory=list)
    zeros: list[int | None] = field(default_factory=list)
    left_out: list[tuple[Path, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def plan_logs(paths: list[Path], metadata: list[dict[str, dict[str, str]]]) -> LogPlan:
    """The :class:`LogPlan` of ``paths`` whose head metadata is ``metadata`` (one dict per file)."""
    zeros: list[int | None] = []
    runs: dict[tuple[str, str], dict[int, list[int]]] = {}   # recording -> board zero -> files
    for i, meta in enumerate(metadata):
        head = meta.get("cmsensord", {})
        parsed = Timeline.from_json(head.get("recording_timeline") or "")
        zeros.append(None if parsed is None else parsed[1])
        if parsed is not None:
            key = (head.get("source", ""), parsed[0].to_json(0))
            runs.setdefault(key, {}).setdefault(parsed[1], []).append(i)
    dropped: dict[int, str] = {}
    plan = LogPlan()
    for (source, _), by_zero in runs.items():
        if len(by_zero) > 1:
            plan.notes.append(_left_out(source, by_zero, paths, dropped))
    for i, path in enumerate(paths):
        if i in dropped:
            plan.left_out.append((path, dropped[i]))
        else:
            plan.paths.append(path)
            plan.zeros.append(zeros[i])
    return plan


def _left_out(source: str, by_zero: dict[int, list[int]], paths: list[Path], dropped: dict[int, str]) -> str:
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
