"""The logs of a report: the files named or found in directories, read leniently into one
LogData a recording.

A directory stands for its ``*.mcap`` and ``*.mcap.part`` files (salvaged
files included), in the order they were opened
(:func:`~cmsensord.sinks.log_names.order_key`). Every file is read with the lenient
reader (:class:`~cmsensord.report.fast_read.FastScan`), so a ``.part``
file of a crashed daemon or a damaged file gives what it holds up to the
damage. The logs of each recording are read apart (:mod:`.runs`: each imported recording, and
the logs that are no run of an import); of an imported recording replayed more than once,
only the newest replay; of its ``vkf`` runs the newest, beside a replay only its batch orders
(the rest of its log repeats the replay's).
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path
from typing import TextIO

from cmsensord.report.fast_read import FastScan, head_metadata
from cmsensord.report.healthy import healthy_period
from cmsensord.report.log_data import FileInfo, LogData
from cmsensord.report.progress import Progress
from cmsensord.report.runs import Recording, plan_logs
from cmsensord.report.time_axis import TimeAxis
from cmsensord.sinks.log_names import log_paths

__all__ = ["log_paths", "read_logs"]


def read_logs(paths: list[Path], progress_stream: TextIO) -> list[LogData]:
    """The messages of ``paths``, one :class:`LogData` a recording (:mod:`.runs`), in the order
    of their first files, a progress bar on a terminal; the messages of a replayed import in the
    recording's own time (:mod:`.time_axis`); of an import replayed more than once, only its
    newest replay (the others listed as left out); the healthy period its baselines were learned
    from, when its replay names it (:mod:`.healthy`). Each message is placed at its publish time (its
    own stamp; on an imported recording's axis an indicator record, and the alarm transitions it
    raised, at its interval's start: :mod:`.log_data`), the events listed in time order."""
    heads = {p: head_metadata(p) for p in paths}
    recordings = plan_logs(paths, [heads[p] for p in paths])
    sizes = {p: p.stat().st_size for rec in recordings for p in rec.paths}
    progress = Progress(sum(sizes.values()), progress_stream)
    parts, done = [], 0
    for rec in recordings:
        data = _read_recording(rec, heads, sizes, progress, done, len(recordings) > 1)
        done += sum(sizes[p] for p in rec.paths)
        parts.append(data)
    progress.close()
    return parts


def _read_recording(rec: Recording, heads: dict[Path, dict[str, dict[str, str]]], sizes: dict[Path, int],
                    progress: Progress, done: int, named: bool) -> LogData:
    """The files of one recording into a :class:`LogData` (``done``: bytes read before them;
    ``named``: one of several recordings, which its name tells apart)."""
    data = LogData()
    data.recording = rec.name if named else ""
    data.recording_id = rec.ident if named else ""
    data.axis = TimeAxis.of_logs([heads[p] for p in rec.paths])
    data.healthy = healthy_period(rec, heads, data.axis)
    data.notes = rec.notes
    data.records_at_start = data.axis.timeline is not None
    for path, zero in zip(rec.paths, rec.zeros):
        info = FileInfo(str(path), sizes[path], batch_only=path in rec.batch_only)
        data.begin_file(heads[path].get("cmsensord", {}))
        scan = FastScan(path)
        if data.axis.timeline is not None:
            data.place = partial(data.axis.shown, board_zero_ns=zero)
        for seen, (topic, t, raw, offset) in enumerate(scan.messages(), start=1):
            if seen % 4096 == 0:
                progress.update(done + offset)
            if info.batch_only and not _batch_orders(topic, raw):
                continue
            data.add(topic, t, raw)
            info.messages += 1
        info.complete, info.error, info.skipped, info.cut = scan.complete, scan.error, scan.skipped, scan.cut
        info.unreadable, info.foreign, info.foreign_topics = data.unreadable, data.foreign, data.foreign_topics
        data.files.append(info)
        done += sizes[path]
    data.events.sort(key=lambda e: e[0])
    data.files.extend(FileInfo(str(path), path.stat().st_size, left_out=why) for path, why in rec.left_out)
    return data


def _batch_orders(topic: str, raw: bytes) -> bool:
    """Whether a message is one of the batch VKF's /orders (``method`` "batch")."""
    if not topic.endswith("/orders") or b'"batch"' not in raw:
        return False
    try:
        msg = json.loads(raw)
    except (ValueError, RecursionError):
        return False
    return isinstance(msg, dict) and msg.get("method") == "batch"
