"""``cmsensord summary LOG ...``: what MCAP logs (or truncated .mcap.part files, or the logs of a
directory) hold."""

from __future__ import annotations

import json
import os
import sys
from typing import TYPE_CHECKING

from cmsensord.errors import EXIT_USAGE, CmsensordError
from cmsensord.report.localtime import iso_local
from cmsensord.sinks.log_names import empty_files, log_paths
from cmsensord.sinks.mcap_records import not_mcap_text
from cmsensord.sinks.mcap_sink import NOT_MCAP, summarize

if TYPE_CHECKING:
    from cmsensord.report.time_axis import TimeAxis


def summary_of(names: list[str], *, as_json: bool = False) -> int:
    """The summary of each log of ``names`` (files, or directories of logs: a rotated set, in
    the order its files were opened), each after a ``== FILE`` line when there are several
    (JSON: a list of them); the exit status is the worst. A name that is neither is one line
    and exit status 2. Among several, the empty files (0 bytes) are left out, said in one line
    (:func:`~cmsensord.sinks.log_names.empty_files`); all of them empty, that line is the error."""
    try:
        paths = [str(p) for p in log_paths(names)]
    except CmsensordError as exc:
        print(f"cmsensord: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if len(paths) > 1:
        empty = [p for p in paths if _empty(p)]
        gone = set(empty)
        if len(empty) == len(paths):
            print(f"cmsensord: {empty_files(empty)}: no MCAP data in them", file=sys.stderr)
            return EXIT_USAGE
        if empty:
            print(f"cmsensord: summary: {empty_files(empty)}: left out", file=sys.stderr)
            paths = [p for p in paths if p not in gone]
    if len(paths) == 1:
        return summary(paths[0], as_json=as_json)
    if as_json:
        infos = [summarize(p) for p in paths]
        print(json.dumps(infos, indent=2, default=str), flush=True)
        return max(_tell_damage(i) if i["error"] != NOT_MCAP else _not_mcap(i["path"]) for i in infos)
    status = 0
    for k, p in enumerate(paths):
        print(("\n" if k else "") + f"== {p}", flush=True)
        status = max(status, summary(p))
    return status


def _empty(path: str) -> bool:
    """``path`` holds no byte (gone since it was listed: not empty, its summary says so)."""
    try:
        return os.stat(path).st_size == 0
    except OSError:
        return False


def _not_mcap(path: str) -> int:
    print(f"cmsensord: {path}: {not_mcap_text(path)}", file=sys.stderr)
    return EXIT_USAGE


def summary(path: str, *, as_json: bool = False) -> int:
    """Print the summary of the file ``path`` (text or JSON); exit status 2 if it is not an
    MCAP file. Damage that ended the read (a finished file cut short, say) is also one line on
    stderr (:func:`_tell_damage`): an error with exit status 2 when no message could be read."""
    info = summarize(path)
    if info["error"] == NOT_MCAP:
        return _not_mcap(path)
    try:
        print(json.dumps(info, indent=2, default=str) if as_json else format_summary(info), flush=True)
    except BrokenPipeError:     # `cmsensord summary FILE | head`: the reader has enough
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return _tell_damage(info)


def _tell_damage(info: dict) -> int:
    """The damage that ended the read as one line on stderr: a warning naming the messages read
    before it (status 0), or, when there are none, the error (status 2)."""
    if not info["error"]:
        return 0
    if not info["messages"]:
        print(f"cmsensord: {info['path']}: {info['error']}", file=sys.stderr)
        return EXIT_USAGE
    print(f"cmsensord: summary: {info['path']}: {info['error']}; the summary holds its {info['messages']:,} "
          "message(s) before that", file=sys.stderr)
    return 0


def format_summary(info: dict) -> str:
    """The summary as text: times as ISO 8601 local time, one line per event
    (``time kind [channel]: message``; for a replayed import also its time in the recording,
    :mod:`cmsensord.report.time_axis`), other lists and dicts one item a line, a metadata
    value past 120 characters shortened (the recording's timeline to its span)."""
    from cmsensord.report.time_axis import TimeAxis  # here: the replay imports this module too

    axis = TimeAxis.of_logs([info.get("metadata") or {}])
    lines = []
    for k, v in info.items():
        if k in ("start_ns", "end_ns"):
            lines.append(f"{k[:-3]}: {iso_local(v, ms=True)}{_in_recording(axis, v)}")
        elif k == "events":
            lines.append(f"events: {len(v)} shown")
            lines.extend(f"  {event_line(e, axis)}" for e in v)
        elif k == "metadata":
            lines.append("metadata:")
            for name, values in v.items():
                healthy = _healthy_line(values, axis) if name == "cmsensord" else ""
                shown = {kk: vv for kk, vv in values.items() if kk != "healthy_period"} if healthy else values
                lines.append(f"  {name}: {_metadata(shown, axis)}")
                lines.extend([f"  {healthy}"] if healthy else [])
        elif k == "cut" and v == info.get("error"):
            continue                    # said as the error
        elif isinstance(v, dict):
            lines.append(f"{k}:")
            for kk, vv in v.items():
                lines.append(f"  {kk}: {vv}")
        elif isinstance(v, list):
            lines.append(f"{k}: {len(v)} item(s)")
            for item in v[:50]:
                lines.append(f"  {item}")
        else:
            lines.append(f"{k}: {v}")
    return "\n".join(lines)


def _in_recording(axis: TimeAxis, ns: int | None) -> str:
    """`` (TIME in the recording)`` (or `` (P % of the record)``) for a replayed import's log
    time ``ns``; else nothing."""
    if axis.timeline is None or ns is None:
        return ""
    return f" ({axis.text(axis.shown(int(ns)))} {'of the record' if axis.kind == 'record' else 'in the recording'})"


def _healthy_line(values: dict, axis: TimeAxis) -> str:
    """The healthy period a replay's ``cmsensord`` metadata names (``healthy_period``, the
    commissioned one: :class:`~cmsensord.service.replay.RecordingHead`) as a line: its board
    seconds of the capture and, for an import, its ends in the recording (as the report shades
    it); empty when it names none or one that is no period (then shown as it is)."""
    from cmsensord.report.healthy import LEGEND, board_period

    period = board_period(values.get("healthy_period"))
    if period is None:
        return ""
    line = f"{LEGEND}: {round(period[0], 3)}-{round(period[1], 3)} board s of the capture"
    said = " (the site file's commissioned section)"
    if axis.timeline is None:
        return line + said
    start = axis.shown(axis.board_zero_ns + int(round(period[0] * 1e9)), begins=True)
    end = axis.shown(axis.board_zero_ns + int(round(period[1] * 1e9)))
    where = "of the record" if axis.kind == "record" else "in the recording"
    return line + f", {axis.text(start)} to {axis.text(end)} {where}{said}"


def _metadata(values: dict, axis: TimeAxis) -> dict:
    """A metadata record's map, each value past 120 characters shortened."""
    out, tl = {}, axis.timeline
    for key, value in values.items():
        if key == "recording_timeline" and tl is not None and tl.unit == "%":
            out[key] = f"{tl.start_s.size} snapshot(s) without times, {tl.end_s:g} s of signal end to end"
        elif key == "recording_timeline" and tl is not None:
            start, end = tl.source_s[0], tl.source_s[-1]
            out[key] = (f"{tl.start_s.size} snapshots over {(end - start) / 3600:.4g} h of the "
                        f"recording" + (f" from {tl.source_start}" if tl.source_start else ""))
        else:
            out[key] = value if len(str(value)) <= 120 else f"{str(value)[:100]}... ({len(str(value)):,} characters)"
    return out


def event_line(event: dict, axis: TimeAxis | None = None) -> str:
    """One event of :func:`~cmsensord.sinks.mcap_read.summarize` as a line:
    ``2026-11-26T17:47:02.522+00:00 anomaly_onset ch0: message`` (for a replayed import,
    its time in the recording after the time)."""
    channel, message = event.get("channel"), event.get("message") or ""
    where = f" {channel}" if channel and not message.startswith(f"{channel}:") else ""
    if not where and channel:
        where, message = f" {channel}", message[len(channel) + 2:]
    when = iso_local(event.get("time_ns"), ms=True) + (_in_recording(axis, event.get("time_ns")) if axis else "")
    return f"{when} {event.get('kind')}{where}: {message}"
