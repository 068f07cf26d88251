"""Where the severity levels a replay reached lie in the recording an imported capture came from.

``cmsensord import`` lays a recording's snapshots end to end on the board clock and lists
them in the capture's sidecar: each snapshot's source, where it starts in board seconds, its
share of the record (``pct_of_record``) and, when the recording says, its time in it
(``source_time_s``, after ``source_start`` when that date is known).  A replay's summary gives
the board second at which each channel first reached severity 0.1, 0.5 and 1; for an imported
recording of several snapshots, :func:`origin_lines` says which snapshot that was, and when.
"""

from __future__ import annotations

import bisect
from datetime import datetime, timedelta

__all__ = ["origin_lines"]


def origin_lines(meta: dict, views) -> list[str]:
    """One line per channel that reached a level (``views``: the Processor's channel views),
    naming the snapshot of each first; none unless ``meta`` is an import's sidecar of several
    snapshots."""
    snaps = meta.get("snapshots") if meta.get("format") == "cmsensord import" else None
    if not snaps or len(snaps) < 2:
        return []
    starts = [float(s["start_s"]) for s in snaps]
    lines = []
    for v in views:
        if not (v.judged and v.timeline.first):
            continue
        at: dict[str, list[str]] = {}       # snapshot -> the levels first reached in it, in order
        for level, t in sorted(v.timeline.first.items()):
            at.setdefault(_where(meta, snaps, starts, t), []).append(f"{level:g}")
        firsts = "; ".join(f"{' and '.join(levels)} at {where}" for where, levels in at.items())
        lines.append(f"  {v.name}: in the recording: {firsts}")
    return lines


def _where(meta: dict, snaps: list[dict], starts: list[float], t_s: float) -> str:
    """The snapshot whose samples end the decision ending at board second ``t_s``."""
    s = snaps[max(0, bisect.bisect_right(starts, t_s - 1e-6) - 1)]
    when = f"{s['pct_of_record']:.1f} % of the record"
    if s.get("source_time_s") is not None:
        start = meta.get("source_start")
        at = timedelta(seconds=float(s["source_time_s"]))
        clock = (datetime.fromisoformat(start) + at).strftime("%Y-%m-%d %H:%M:%S") if start else None
        when += f", {clock}" if clock else f", {at.total_seconds() / 3600:.4g} h in"
    return f"{s['source']} ({when})"
