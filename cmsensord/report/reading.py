"""The logs of a report: the files named or found in directories, read leniently into a LogData.

A directory stands for its ``*.mcap`` and ``*.mcap.part`` files (salvaged
files included), in the order they were opened
(:func:`~cmsensord.sinks.log_names.order_key`). Every file is read with the lenient
reader (:class:`~cmsensord.report.fast_read.FastScan`), so a ``.part``
file of a crashed daemon or a damaged file gives what it holds up to the
damage. Of an imported recording replayed more than once, only the newest replay is read
(:mod:`.runs`).
"""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import TextIO

from cmsensord.report.fast_read import FastScan, head_metadata
from cmsensord.report.log_data import FileInfo, LogData
from cmsensord.report.progress import Progress
from cmsensord.report.runs import plan_logs
from cmsensord.report.time_axis import TimeAxis
from cmsensord.sinks.log_names import log_paths

__all__ = ["log_paths", "read_logs"]


def read_logs(paths: list[Path], progress_stream: TextIO) -> LogData:
    """The messages of ``paths`` into one :class:`LogData`, a progress bar on a terminal; the
    messages of a replayed import in the recording's own time (:mod:`.time_axis`); of an import
    replayed more than once, only its newest replay (:mod:`.runs`; the others listed as left out).
    Each message is placed at its publish time (its own stamp; on an imported recording's axis an
    indicator record, and the alarm transitions it raised, at its interval's start:
    :mod:`.log_data`), the events listed in time order."""
    data = LogData()
    heads = {p: head_metadata(p) for p in paths}
    plan = plan_logs(paths, [heads[p] for p in paths])
    data.axis = TimeAxis.of_logs([heads[p] for p in plan.paths])
    data.notes = plan.notes
    sizes = [p.stat().st_size for p in plan.paths]
    progress = Progress(sum(sizes), progress_stream)
    done = 0
    data.records_at_start = data.axis.timeline is not None
    for path, size, zero in zip(plan.paths, sizes, plan.zeros):
        info = FileInfo(str(path), size)
        data.begin_file(heads[path].get("cmsensord", {}))
        scan = FastScan(path)
        if data.axis.timeline is not None:
            data.place = partial(data.axis.shown, board_zero_ns=zero)
        for topic, t, raw, offset in scan.messages():
            data.add(topic, t, raw)
            info.messages += 1
            if info.messages % 4096 == 0:
                progress.update(done + offset)
        info.complete, info.error, info.skipped, info.cut = scan.complete, scan.error, scan.skipped, scan.cut
        info.unreadable, info.foreign, info.foreign_topics = data.unreadable, data.foreign, data.foreign_topics
        data.files.append(info)
        done += size
    progress.close()
    data.events.sort(key=lambda e: e[0])
    data.files.extend(FileInfo(str(path), path.stat().st_size, left_out=why) for path, why in plan.left_out)
    return data
