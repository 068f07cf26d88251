"""Where the severity levels a replay reached lie in the recording an imported capture came from.

``cmsensord import`` lays a recording's snapshots end to end on the board clock and lists
them in the capture's sidecar: each snapshot's source, where it starts in board seconds, its
share of the record (``pct_of_record``) and, when the recording says, its time in it
(``source_time_s``, after ``source_start`` when that date is known).  A replay's summary gives
the board second at which each channel first reached severity 0.1, 0.5 and 1; for an imported
recording of several snapshots, :func:`origin_lines` says which snapshot that was, and when;
and the same of each alarm's first alert and danger (:class:`FirstAlarms`).
"""

from __future__ import annotations

import bisect
from datetime import datetime, timedelta

from cmsensord.importing.timeline import Timeline

__all__ = ["FirstAlarms", "delay_lines", "origin_lines", "span_line"]

#: the alarm events whose first occurrence per alarm is placed in the recording
_ALARM_KINDS = {"alarm_alert": "alert", "alarm_danger": "danger"}


class FirstAlarms:
    """The stamp of each alarm's first alert and first danger, taken from the events an
    :class:`~cmsensord.monitor.events.EventLog` writes (its ``watch``, which it passes on)."""

    def __init__(self, log):
        self.first: dict[str, dict[str, int]] = {}      # alarm -> {"alert"|"danger": stamp_ns}
        self._then = log.watch
        log.watch = self

    def __call__(self, kind: str, channel: str | None, message: str, stamp_ns: int, fields: dict) -> None:
        level = _ALARM_KINDS.get(kind)
        if level is not None:
            self.first.setdefault(str(fields.get("alarm")), {}).setdefault(level, stamp_ns)
        if self._then is not None:
            self._then(kind, channel, message, stamp_ns, fields)

    def board_s(self, anchor_ns: int | None) -> dict[str, dict[str, float]]:
        """The firsts in board seconds of a capture whose board clock starts at 0 (an import's)
        and is stamped from ``anchor_ns``."""
        if anchor_ns is None:
            return {}
        return {alarm: {level: (ns - anchor_ns) / 1e9 for level, ns in levels.items()}
                for alarm, levels in self.first.items()}


def _snapshots(meta: dict) -> tuple[list[dict], list[float]] | None:
    """An import's snapshots and their board starts (None: not an import of several); each
    snapshot's ``source_time_s`` as the import's :class:`~cmsensord.importing.timeline.Timeline`
    has it (a time that goes back placed between its neighbours, as the report places it)."""
    snaps = meta.get("snapshots") if meta.get("format") == "cmsensord import" else None
    if not snaps or len(snaps) < 2:
        return None
    timeline = Timeline.from_sidecar(meta)
    if timeline is not None and timeline.repaired:
        snaps = [{**s, "source_time_s": float(t)} for s, t in zip(snaps, timeline.source_s)]
    return snaps, [float(s["start_s"]) for s in snaps]


def span_line(meta: dict, start_s: float, end_s: float) -> str | None:
    """``in the recording: SNAPSHOT (...) to [the end of] SNAPSHOT (...)``: the snapshots a span of
    board seconds begins and ends in, each with where in the record and when the span begins and
    ends (:func:`_point`; calibrate's healthy period); one snapshot, named once, when it begins and
    ends in the same; None unless ``meta`` is an import's sidecar of several snapshots."""
    found = _snapshots(meta)
    if found is None:
        return None
    snaps, starts = found
    first = _where(meta, snaps, starts, start_s, ending=False)
    if first == _where(meta, snaps, starts, end_s):
        return f"in the recording: {first}"
    return (f"in the recording: {_point(meta, snaps, starts, start_s, ending=False)} to "
            f"{_point(meta, snaps, starts, end_s, ending=True)}")


def origin_lines(meta: dict, views, alarms: dict[str, dict[str, float]] | None = None) -> list[str]:
    """One line per channel that reached a severity level (``views``: the Processor's channel
    views) and per alarm that rose (``alarms``: alarm -> {"alert"|"danger": board second}),
    naming the snapshot of each first; none unless ``meta`` is an import's sidecar of several
    snapshots."""
    found = _snapshots(meta)
    if found is None:
        return []
    snaps, starts = found
    lines = []
    for v in views:
        if v.judged and v.timeline.first:
            firsts = [(f"{level:g}", t) for level, t in sorted(v.timeline.first.items())]
            lines.append(f"  {v.name}: in the recording: {_placed(meta, snaps, starts, firsts)}")
    for alarm, levels in sorted((alarms or {}).items()):
        firsts = [(level, levels[level]) for level in ("alert", "danger") if level in levels]
        lines.append(f"  alarm {alarm}: in the recording: {_placed(meta, snaps, starts, firsts)}")
    return lines


def _placed(meta: dict, snaps: list[dict], starts: list[float], firsts: list[tuple[str, float]]) -> str:
    """``0.1 and 0.5 at SNAPSHOT (...); 1 at SNAPSHOT (...)``: the levels first reached in each
    snapshot (``firsts``: (level, board second), in order)."""
    at: dict[str, list[str]] = {}
    for level, t in firsts:
        at.setdefault(_where(meta, snaps, starts, t), []).append(level)
    return "; ".join(f"{' and '.join(levels)} at {where}" for where, levels in at.items())


def _snapshot_of(starts: list[float], t_s: float, ending: bool) -> int:
    """The index of the snapshot whose samples end what ends at board second ``t_s``, or with
    ``ending`` False begin what begins there."""
    return max(0, bisect.bisect_right(starts, t_s - 1e-6 if ending else t_s + 1e-6) - 1)


def _where(meta: dict, snaps: list[dict], starts: list[float], t_s: float, ending: bool = True) -> str:
    """The snapshot whose samples end what ends at board second ``t_s`` (a decision, an
    indicator interval), or with ``ending`` False begin what begins there: its name, where it
    starts in the record and when."""
    s = snaps[_snapshot_of(starts, t_s, ending)]
    return f"{s['source']} ({_when(meta, s, float(s['pct_of_record']), 0.0)})"


def _point(meta: dict, snaps: list[dict], starts: list[float], t_s: float, ending: bool) -> str:
    """Board second ``t_s`` where a span begins (``ending`` False) or ends: the snapshot it lies in,
    and where ``t_s`` is in the record and when; a span that ends with a snapshot's last sample is
    said to end at ``the end of`` it.  The snapshot's start where the sidecar gives no rate,
    length or record length."""
    k = _snapshot_of(starts, t_s, ending)
    s, offset = snaps[k], t_s - starts[k]
    fs, total = meta.get("fs"), meta.get("board_seconds")
    if not (isinstance(fs, (int, float)) and fs > 0 and isinstance(total, (int, float)) and total > 0
            and isinstance(s.get("length"), (int, float))):
        return f"{s['source']} ({_when(meta, s, float(s['pct_of_record']), 0.0)})"
    whole = ending and offset >= s["length"] / fs - 1e-6
    return f"{'the end of ' if whole else ''}{s['source']} ({_when(meta, s, 100.0 * t_s / total, offset)})"


def _when(meta: dict, s: dict, pct: float, offset: float) -> str:
    """``P % of the record``, and the time in the recording (its date and time, or the hours
    into it) ``offset`` seconds into snapshot ``s``, when the sidecar knows its time."""
    when = f"{pct:.1f} % of the record"
    if s.get("source_time_s") is not None:
        start = meta.get("source_start")
        at = timedelta(seconds=float(s["source_time_s"]) + offset)
        clock = (datetime.fromisoformat(start) + at).strftime("%Y-%m-%d %H:%M:%S") if start else None
        when += f", {clock}" if clock else f", {at.total_seconds() / 3600:.4g} h in"
    return when


def delay_lines(meta: dict, cfg) -> list[str]:
    """One line when the alarm delays of ``cfg`` span much more of the recording than they say:
    they count the capture's (board) seconds, and an import of snapshots lays them end to end
    (FEMTO's 0.1-s snapshots every 10 s: one board second is 100 s of the recording)."""
    timeline = Timeline.from_sidecar(meta)
    if timeline is None or timeline.unit != "s" or len(timeline.start_s) < 2:
        return []
    ratio = (float(timeline.source_s[-1] - timeline.source_s[0])
             / float(timeline.start_s[-1] - timeline.start_s[0]))      # from the first snapshot to the last
    rules = cfg.alarms.rules if cfg.alarms.enabled else ()
    delay = max([0.0] + [max(r.on_delay_s, r.off_delay_s) for r in rules])
    if ratio < 1.5 or delay <= 0:
        return []
    return [f"  alarm delays count the capture's seconds, one of which is {ratio:.3g} s of the recording here "
            f"(its snapshots end to end): a delay of {delay:g} s spans {delay * ratio:,.0f} s of it"]
