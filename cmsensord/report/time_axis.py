"""The report's time: local wall-clock time, or the time of the recording a replayed import came from.

A daemon's log, or a replay of a capture, is drawn in local time (``local``). A replay of an
imported recording carries the import's :class:`~cmsensord.importing.timeline.Timeline` in
its ``cmsensord`` metadata (``recording_timeline``): its log times are then shown as the
recording's own, where the board clock ran on through the gaps between snapshots. With the
recording's date (the import read it from the file names) the times are that date and time
(``recording``, as the file names give them: not converted to this machine's zone, nor
shifted by its daylight saving); without it, time into the recording (``elapsed``: hours, or
seconds for a recording shorter than ten minutes); for snapshots without times, the share of
the recorded signal (``record``: % of the record, the snapshots end to end). The report
draws each recording's logs apart (:mod:`.runs`), each on its own axis; logs given together
whose timelines differ, or some of an import and some not, or a timeline that cannot be read,
stay in local time, and :attr:`TimeAxis.note` says why.
"""

from __future__ import annotations

from datetime import datetime, timezone

import numpy as np

from cmsensord.importing.timeline import Timeline
from cmsensord.report.localtime import iso_local, local_datetime, local_text

__all__ = ["TimeAxis"]

_HOUR_NS = 3_600_000_000_000
#: a recording shorter than this is shown in seconds into it, a longer one in hours
SECONDS_UNTIL_S = 600.0
#: how much later than its board second the start of a record is placed (:meth:`TimeAxis.shown`)
BEGINS_S = 1e-6


class TimeAxis:
    """Log times to the times the report shows (:meth:`shown`), and how to write and label them."""

    def __init__(self, timeline: Timeline | None = None, board_zero_ns: int = 0, note: str = ""):
        self.timeline, self.board_zero_ns = timeline, board_zero_ns
        self.kind = ("local" if timeline is None else "record" if timeline.unit == "%"
                     else "recording" if timeline.source_start else "elapsed")
        self.unit_ns = 1e9 if self.kind == "record" or (
            self.kind == "elapsed" and timeline is not None and timeline.span < SECONDS_UNTIL_S) else _HOUR_NS
        self._epoch_s = datetime.fromisoformat(timeline.source_start).replace(tzinfo=timezone.utc).timestamp() \
            if timeline is not None and timeline.source_start else 0.0
        self.note = note

    @classmethod
    def of_logs(cls, metadata: list[dict[str, dict[str, str]]]) -> TimeAxis:
        """The axis of logs whose head metadata is ``metadata`` (one dict per file)."""
        texts = [m.get("cmsensord", {}).get("recording_timeline") for m in metadata]
        if not any(texts):
            return cls()
        parsed = [Timeline.from_json(text) if text else None for text in texts]
        if any(text and p is None for text, p in zip(texts, parsed)):
            return cls(note="The logs' recording timeline cannot be read: local time is shown.")
        # replays of one recording differ only in the log time of board second 0 (each file's own)
        if any(p is None for p in parsed) or len({p[0].to_json(0) for p in parsed if p is not None}) > 1:
            return cls(note="The logs are not all of one imported recording: local time is shown.")
        timeline, zero = parsed[0]   # type: ignore[misc]
        fixed = (f" {timeline.repaired} snapshot(s) whose recorded time went back are placed between "
                 "their neighbours." if timeline.repaired else "")
        axis = cls(timeline, zero)
        if axis.kind == "record":
            axis.note = ("A replay of an imported recording whose snapshots have no times: places are "
                         "% of the record (the share of its recorded signal, snapshots end to end).")
        else:
            where = (f"the recording's own date and time (from {timeline.source_start})"
                     if timeline.source_start else axis.label())
            gaps = ", gaps between its snapshots included" if timeline.start_s.size > 1 else ""
            axis.note = f"A replay of an imported recording: times are {where}{gaps}.{fixed}"
        return axis

    def shown(self, log_ns: int, board_zero_ns: int | None = None, *, begins: bool = False) -> int:
        """The time shown for a message logged at ``log_ns`` by a replay whose board second 0 was
        logged at ``board_zero_ns`` (default: the first log's): ns since the Unix epoch
        (``local``; ``recording``: the recording's clock read as UTC), ns into the recording
        (``elapsed``), or 1e-9 % of the record (``record``).  A board second on a snapshot's start
        is the end of the snapshot before (:meth:`Timeline.at`); with ``begins`` (the start of an
        indicator record) it is the start of that snapshot: taken ``BEGINS_S`` later, past the
        microsecond the timeline's snapshot starts are rounded to and the nanosecond of a start
        computed from an end (in seconds; % of the record runs on through the snapshots).  A time
        before the recording's first sample is at that sample."""
        if self.timeline is None:
            return log_ns
        zero = self.board_zero_ns if board_zero_ns is None else board_zero_ns
        board_s = (log_ns - zero) / 1e9 + (BEGINS_S if begins and self.timeline.unit == "s" else 0.0)
        s = float(self.timeline.at(max(board_s, float(self.timeline.start_s[0]))))
        return int(round((self._epoch_s + s) * 1e9))

    def text(self, ns: int | None, *, ms: bool = False) -> str:
        """A shown time for a table or a card; ``None`` gives ``-``."""
        if ns is None or self.kind == "local":
            return local_text(ns, ms=ms)
        if self.kind == "record":
            return f"{ns / 1e9:.{3 if ms else 1}f} %"
        if self.kind == "elapsed" and self.unit_ns == _HOUR_NS:
            return f"{ns / _HOUR_NS:.{5 if ms else 3}f} h"
        if self.kind == "elapsed":
            return f"{ns / 1e9:.{3 if ms else 1}f} s"
        return self.reading(ns).isoformat(sep=" ", timespec="milliseconds" if ms else "seconds")

    def reading(self, ns: int) -> datetime:
        """A shown time (not ``elapsed``) as the clock reading it stands for, without a zone."""
        if self.kind == "recording":
            return datetime.fromtimestamp(ns / 1e9, timezone.utc).replace(tzinfo=None)
        return local_datetime(ns).replace(tzinfo=None)

    @property
    def column(self) -> str:
        """The heading of a column of shown times."""
        if self.kind == "elapsed":
            return "hours in" if self.unit_ns == _HOUR_NS else "seconds in"
        return {"local": "local time", "recording": "recording time", "record": "% of the record"}[self.kind]

    def caption(self, start_ns: int | None) -> str:
        """The page's line on its times."""
        if self.kind == "local":
            return (f"Times are local time, UTC{iso_local(start_ns)[19:] or ''}. " + self.note).strip()
        return self.note

    def is_dates(self) -> bool:
        return self.kind in ("local", "recording")

    def numbers(self, t_ns: np.ndarray) -> np.ndarray:
        """Shown times as the x of an axis that is not dates: hours or seconds into the
        recording (``elapsed``), % of the record (``record``)."""
        return np.asarray(t_ns, dtype=np.float64) / self.unit_ns

    def label(self) -> str:
        """The x label of a time axis."""
        if self.kind == "local":
            offset = datetime.now().astimezone().strftime("%z")
            return f"local time (UTC{offset[:3]}:{offset[3:]})"
        if self.kind == "recording":
            return "recording time (from the import)"
        if self.kind == "record":
            return "% of the record (snapshots end to end; the import has no times)"
        return "hours into the recording" if self.unit_ns == _HOUR_NS else "seconds into the recording"
