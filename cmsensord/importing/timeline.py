"""Board seconds of an imported capture to times in the recording it came from.

``cmsensord import`` lays a recording's snapshots end to end on the board clock and lists
them in the capture's sidecar (:mod:`.capture_writer`): each snapshot's board start
``start_s`` and, when the recording says, its time in the recording ``source_time_s``
(seconds after ``source_start`` when that date is known). A board second ``t`` in snapshot
``k`` is ``source_time_s[k] + (t - start_s[k])`` seconds into the recording; a time on the
start of snapshot ``k`` is the end of snapshot ``k - 1`` (the daemon stamps an interval at
its end). One snapshot without a time (a continuous recording) starts at second 0.

Snapshots without times (files that give none, or mostly out of order) have no seconds in
the recording: their timeline places a board second by its share of the recorded signal
(``unit`` ``%``: ``100 t / end_s``, as the sidecar's ``pct_of_record``), the snapshots end to
end.

A snapshot whose time goes back against the snapshots before it (a logger's clock set wrong
for a few files: two of FEMTO Bearing1_1's 2803) is placed between its neighbours, by its
place in the file order, and counted (:attr:`Timeline.repaired`). A replay writes the timeline
into its MCAP log (:meth:`Timeline.to_json`, with the log time of board second 0), so that a
report can draw the log over the recording's own time.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import datetime

import numpy as np

__all__ = ["MAX_S", "Timeline"]

#: seconds beyond which a timeline read from a log is not one (about 3,000 years)
MAX_S = 1e11


@dataclass(frozen=True)
class Timeline:
    start_s: np.ndarray  # float64 (snapshots,): board second of each snapshot's start, increasing
    source_s: np.ndarray  # float64 (snapshots,): its time in the recording, non-decreasing
    source_start: str | None = None  # ISO 8601 date and time that source_s counts from, if known
    repaired: int = 0  # snapshots whose time went back, placed between their neighbours
    unit: str = "s"  # what at() gives: "s", seconds into the recording; "%", of the record
    end_s: float = 0.0  # board second where the last snapshot ends (0: unknown)

    @classmethod
    def from_sidecar(cls, meta: dict) -> Timeline | None:
        """The timeline of an import's sidecar ``meta``: in seconds when every snapshot has a
        time (or the only one has none), else in % of the record; None when ``meta`` is not an
        import's."""
        snaps = meta.get("snapshots") if meta.get("format") == "cmsensord import" else None
        if not snaps:
            return None
        start = np.array([float(s["start_s"]) for s in snaps])
        end = float(meta.get("board_seconds") or 0.0)
        given = [s.get("source_time_s") for s in snaps]
        if len(given) == 1:
            given = [given[0] or 0.0]
        if all(t is not None for t in given):
            times, repaired = _in_order(np.array(given, dtype=np.float64))
            if repaired * 2 <= len(snaps):
                return cls(start, times, _date(meta.get("source_start")), repaired, end_s=end)
        return cls(start, start, unit="%", end_s=end) if end > 0 else None

    def at(self, board_s: np.ndarray | float) -> np.ndarray:
        """Board second(s) ``board_s`` in the recording: seconds into it, or % of the record
        (:attr:`unit`; a time past the record's end, as its last decision's, is at 100 %)."""
        t = np.asarray(board_s, dtype=np.float64)
        if self.unit == "%":
            return 100.0 * np.minimum(t, self.end_s) / self.end_s
        k = np.clip(np.searchsorted(self.start_s, t, side="left") - 1, 0, self.start_s.size - 1)
        return self.source_s[k] + (t - self.start_s[k])

    @property
    def span(self) -> float:
        """The recording's length in :attr:`unit` (its first snapshot's start to its last's end)."""
        return float(self.at(max(self.end_s, float(self.start_s[-1]))) - self.at(float(self.start_s[0])))

    def to_json(self, board_zero_ns: int) -> str:
        """The timeline as one compact JSON text, with the log time of board second 0."""
        return json.dumps({"board_zero_ns": int(board_zero_ns), "source_start": self.source_start,
                           "repaired": self.repaired, "unit": self.unit, "end_s": round(self.end_s, 6),
                           "start_s": [round(float(v), 6) for v in self.start_s],
                           "source_time_s": [round(float(v), 6) for v in self.source_s]},
                          separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> tuple[Timeline, int] | None:
        """(timeline, log time of board second 0) from :meth:`to_json`'s text; None when the
        text is not one (a damaged or foreign log: board starts that go back, times past
        ``MAX_S``, a field of another type or past a float's range, JSON nested past the
        parser's depth)."""
        try:
            d = json.loads(text)
            start = np.asarray(d["start_s"], dtype=np.float64)
            times = np.asarray(d["source_time_s"], dtype=np.float64)
            zero = int(d["board_zero_ns"])
            unit, end = d.get("unit", "s"), float(d.get("end_s") or 0.0)
            repaired = int(d.get("repaired") or 0)
            ok = (start.ndim == 1 and start.shape == times.shape and start.size >= 1
                  and unit in ("s", "%") and 0 <= end < MAX_S and (unit == "s" or end > 0)
                  and bool(np.all(np.isfinite(start)) and np.all(np.isfinite(times)))
                  and bool(np.all(np.diff(start) >= 0)) and float(np.abs(times).max()) < MAX_S
                  and float(np.abs(start).max()) < MAX_S and abs(zero) < 2 ** 63)
        except (ValueError, TypeError, KeyError, AttributeError, OverflowError, RecursionError):
            return None
        if not ok:
            return None
        return cls(start, np.maximum.accumulate(times), _date(d.get("source_start")), repaired, unit, end), zero


def _in_order(times: np.ndarray) -> tuple[np.ndarray, int]:
    """``times`` with each one below the largest before it placed between its in-order
    neighbours (linear by index; after the last in-order one: that one's time), and how many."""
    ok = times >= np.maximum.accumulate(times)
    bad = int((~ok).sum())
    if not bad:
        return times, 0
    idx = np.arange(times.size)
    return np.interp(idx, idx[ok], times[ok]), bad


def _date(text: object) -> str | None:
    """An ISO 8601 date and time, or None when ``text`` is not one."""
    if not isinstance(text, str):
        return None
    try:
        datetime.fromisoformat(text)
    except ValueError:
        return None
    return text
