"""The healthy period the baselines were learned from, as the report shows it.

``cmsensord calibrate`` writes the period it learned from into the site file's ``commissioned``
section (``from_s``, ``to_s``: board seconds of the capture); a replay of that same capture
writes it into its log's ``cmsensord`` metadata (``healthy_period``, JSON ``{"from_s": ...,
"to_s": ...}``: :class:`~cmsensord.service.replay.RecordingHead`). On the axis of an imported
recording (:class:`~.time_axis.TimeAxis` with a timeline) the report shades it on every time
figure of that recording (:func:`.marks.healthy_span`), its ends where calibrate's ``healthy
period in the recording`` line places them: a start on a snapshot's start at that snapshot, an
end there at the end of the snapshot before. A log without it, or with a text that is no such
period, draws as without.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from cmsensord.importing.timeline import MAX_S
from cmsensord.report.runs import Recording
from cmsensord.report.time_axis import TimeAxis

__all__ = ["LEGEND", "healthy_period", "board_period"]

#: the legend entry of the shaded period
LEGEND = "healthy period (baselines)"


def board_period(text: object) -> tuple[float, float] | None:
    """(from_s, to_s) of a log's ``healthy_period`` text; None when it is none (absent, not JSON,
    not finite, negative, past ``MAX_S``, or not from before to)."""
    if not isinstance(text, str) or not text:
        return None
    try:
        d = json.loads(text)
        a, b = float(d["from_s"]), float(d["to_s"])
    except (ValueError, TypeError, KeyError, OverflowError, RecursionError):
        return None
    if not (math.isfinite(a) and math.isfinite(b) and 0.0 <= a < b < MAX_S):
        return None
    return a, b


def healthy_period(rec: Recording, heads: dict[Path, dict[str, dict[str, str]]],
                   axis: TimeAxis) -> tuple[int, int] | None:
    """The shown times (:meth:`TimeAxis.shown`) of the start and end of the healthy period that a
    file of ``rec`` drawn whole names (the first that names one; not a ``vkf`` run read for its
    batch orders only), on the axis of an imported recording; None without one, or on another
    axis (local time)."""
    if axis.timeline is None:
        return None
    for path, zero in zip(rec.paths, rec.zeros):
        period = board_period(heads[path].get("cmsensord", {}).get("healthy_period"))
        if path in rec.batch_only or zero is None or period is None:
            continue
        start = axis.shown(zero + int(round(period[0] * 1e9)), zero, begins=True)
        end = axis.shown(zero + int(round(period[1] * 1e9)), zero)
        return (start, end) if end > start else None
    return None
