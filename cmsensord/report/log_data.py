"""What a report shows, gathered from the messages of MCAP logs in one pass with bounded memory.

:class:`LogData` takes (topic, time [ns], JSON bytes) one message at a time
(:meth:`LogData.add`) and keeps per channel: the severity index and the anomaly
flags (:class:`~cmsensord.report.trend.Trend`), each indicator's trend (each bearing's defect lines
too, as ``<bearing>.<line>``, the alarm rules' names for them) with the latest ISO zone
boundaries, the velocity bands and the alarm level, each alarm rule's newest alert and
danger levels, the order RMS per 10-rpm speed bin, and at most ``MAX_CAPTURES``
captured waveforms with their spectra; for the whole log: the events (the first
``MAX_EVENTS``, counts of all), the link counters (summed over daemon runs),
the largest processing lag and queue depth, and the files read. The fields drawn are read from
each message by :mod:`.fields`, which checks their types: a message with one of a wrong type
is left out and counted, as one that is no JSON object is (:class:`FileInfo`). The link counters are
summed over the runs the files hold (:mod:`.link_runs`: told by each file's metadata, not by
the order the files come in). Nothing grows with
the length of the log beyond these bounds.

Messages come with their log time (their stamp) and are kept at the time the report shows
(:attr:`LogData.place`: local time, or the place in an imported recording). On the axis of an
imported recording (:attr:`LogData.records_at_start`) an indicator record, stamped at the end of
its interval, is kept at its interval's start (``stamp - interval_s``): a record of a snapshot at
the snapshot's start, where the replay's summary names it (``OF.mat[0] (0.0 % of the record)``),
not at the start of the next one; and so are the alarm transitions the record raised (an
``alarm_alert``, ``alarm_danger`` or ``alarm_clear`` of its channel with its stamp, of a rule
that watches a record's value).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from cmsensord.report import fields
from cmsensord.report.link_runs import LinkRuns
from cmsensord.report.time_axis import TimeAxis
from cmsensord.report.trend import Trend

__all__ = ["LogData", "ChannelData", "Capture", "FileInfo", "INDICATOR_FIELDS", "MAX_EVENTS", "MAX_CAPTURES"]

MAX_EVENTS = 2000
MAX_CAPTURES = 12
SPEED_BIN_RPM = 10.0
#: indicator fields drawn as trends (name, unit)
INDICATOR_FIELDS = (("velocity_rms_mm_s", "mm/s"), ("accel_rms", "m/s²"), ("envelope_rms", "m/s²"),
                    ("kurtosis", ""), ("crest_factor", ""))
#: the most velocity bands a channel keeps (one per speed range: 2-1000 or 10-1000 Hz)
MAX_VELOCITY_BANDS = 4
_FAST_KINDS = frozenset(("severity", "indicators"))
#: indicator records kept per channel for the alarm transitions they raised (an event is written
#: up to the reorder window's lag after its record: seconds, tens of records at most)
RECORDS_KEPT = 256
#: the alarm events that a value moved (kept where the record that moved them is)
_TRANSITIONS = frozenset(("alarm_alert", "alarm_danger", "alarm_clear"))
_TRENDS = frozenset(name for name, _ in INDICATOR_FIELDS)
#: topics not cmsensord's named in a line about a file
SHOWN_TOPICS = 3
_CAPTURE_PARTS = {"capture_waveform": "waveform", "capture_spectrum": "spectrum",
                  "capture_envelope": "envelope"}


@dataclass
class Capture:
    """One capture: its time as the report shows times (its messages' stamp, the trigger's moment,
    through :class:`.TimeAxis` as every message's) and the messages of its parts (waveform,
    spectrum, envelope)."""

    channel: str
    time_ns: int
    parts: dict[str, dict[str, Any]] = field(default_factory=dict)
    recording: str = ""             # its recording's name, among others (:attr:`LogData.recording`)
    recording_id: str = ""          # and its ident (:attr:`LogData.recording_id`)


@dataclass
class ChannelData:
    """Per channel: severity, anomaly flags, indicators, orders versus speed, captures."""

    name: str
    recording: str = ""             # its recording's name, among others (:attr:`LogData.recording`)
    recording_id: str = ""          # and its ident (:attr:`LogData.recording_id`)
    severity: Trend = field(default_factory=Trend)
    anomaly: Trend = field(default_factory=Trend)
    level: Trend = field(default_factory=Trend)      # the combined severity's level / baseline
    level_limits: tuple[float, float] | None = None  # its level_alert and level_danger, the newest
    indicators: dict[str, Trend] = field(default_factory=dict)
    zone_boundaries: list[float] | None = None
    velocity_bands: list[tuple[float, float]] = field(default_factory=list)   # each one the log gave
    velocity_alarm: float | None = None
    # order name ("1x"; "1x (batch)", "1x (smoothed)" for those methods) -> speed bin -> [sum, n]
    orders: dict[str, dict[int, list[float]]] = field(default_factory=dict)
    # name -> speed bin -> [sum of freq_hz, sum of rms, n]: the Campbell diagram
    campbell: dict[str, dict[int, list[float]]] = field(default_factory=dict)
    captures: list[Capture] = field(default_factory=list)
    captures_omitted: int = 0
    # alarm rule -> (indicator, (alert, danger)): the levels in force the log last gave
    alarm_levels: dict[str, tuple[str, tuple[float | None, float | None]]] = field(default_factory=dict)


@dataclass
class FileInfo:
    """One file read: its path, size and how far it could be read (``skipped``: the damage
    read past; ``error``: the damage that ended the read, ``cut``: what ending before the footer lost);
    ``left_out``: why it was not read; ``batch_only``: only its batch VKF orders were read (a
    ``vkf`` run beside a replay of its recording: :mod:`.runs`)."""

    path: str
    bytes: int
    messages: int = 0
    unreadable: int = 0             # of them, on cmsensord's topics but not its JSON objects (:mod:`.fields`)
    foreign: int = 0                # of them, on topics not cmsensord's
    foreign_topics: list[str] = field(default_factory=list)     # (a few of) those topics
    complete: bool = False
    error: str | None = None
    skipped: list[str] = field(default_factory=list)
    left_out: str | None = None
    cut: str | None = None          # what ending before the footer lost (a .part's too)
    batch_only: bool = False

    def not_read(self) -> str:
        """Its messages left out and why, in words; "" when none is."""
        parts = []
        if self.foreign:
            more = ", ..." if len(self.foreign_topics) > SHOWN_TOPICS else ""
            parts.append(f"{self.foreign:,} on topics not cmsensord's "
                         f"({', '.join(self.foreign_topics[:SHOWN_TOPICS])}{more})")
        if self.unreadable:
            parts.append(f"{self.unreadable:,} on cmsensord's topics that are not its JSON objects")
        return "; ".join(parts)


class LogData:
    """Everything a report draws, filled message by message (see the module docstring)."""

    def __init__(self) -> None:
        self.channels: dict[str, ChannelData] = {}
        self.events: list[tuple[int, dict[str, Any]]] = []
        self.event_counts: dict[str, int] = {}
        self.messages = 0
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.files: list[FileInfo] = []
        self.notes: list[str] = []      # lines on the logs left out (:mod:`.runs`)
        #: the recording's name when the logs hold more than one (:mod:`.runs`), else ""
        self.recording = ""
        #: its ident among several recordings (:attr:`.runs.Recording.ident`: ids, PNG names), else ""
        self.recording_id = ""
        self.axis = TimeAxis()          # how times are shown
        #: the healthy period the baselines were learned from, as shown (:mod:`.healthy`), or None
        self.healthy: tuple[int, int] | None = None
        #: a log time to the time shown, ``begins``: a record's start (the file's :meth:`TimeAxis.shown`)
        self.place: Callable[..., int] = lambda t_ns, begins=False: t_ns
        #: records kept at their interval's start (an imported recording's axis: see module docstring)
        self.records_at_start = False
        self._records: dict[str, dict[int, int]] = {}      # channel -> its newest records' stamp -> shown start
        self.link_runs = LinkRuns()
        self.max_lag_s = 0.0
        self.max_queue_depth = 0
        #: of the file being read (:meth:`begin_file`): messages on cmsensord's topics (``/cm/...``)
        #: that are not its JSON objects, messages on other topics, and (a few of) those topics
        self.unreadable = 0
        self.foreign = 0
        self.foreign_topics: list[str] = []

    def channel(self, name: str) -> ChannelData:
        ch = self.channels.get(name)
        if ch is None:
            ch = self.channels[name] = ChannelData(name, self.recording, self.recording_id)
        return ch

    def begin_file(self, metadata: dict[str, str]) -> None:
        """The messages added next are of a file whose ``cmsensord`` metadata is ``metadata``
        (its ``run`` tells the daemon run its link counters count)."""
        self.link_runs.begin(metadata)
        self.unreadable = self.foreign = 0
        self.foreign_topics = []

    def add(self, topic: str, stamp_ns: int, data: bytes) -> None:
        """One message of any topic, at its log time ``stamp_ns``; topics the report does not draw
        only count; one on a topic not cmsensord's (not ``/cm/...``), or on cmsensord's that is
        not a JSON object or has a field drawn of a wrong type (:mod:`.fields`), counts as such
        (:attr:`foreign`, :attr:`unreadable`) and is not drawn (one whose channel record was lost
        to damage, ``<channel N>``, only counts: the line on the damage covers it)."""
        self.messages += 1
        if not topic.startswith(("/cm/", "<channel ")):
            self.foreign += 1
            if topic not in self.foreign_topics and len(self.foreign_topics) <= SHOWN_TOPICS:
                self.foreign_topics.append(topic)
            return
        parts = topic.split("/")
        kind = parts[-1]
        if kind in ("akf", "vibration_estimate") or len(parts) == 1:
            self._span(self.place(stamp_ns))
            return                      # 100 Hz traces: not drawn, not decoded; or its topic lost
        if topic == "/cm/diagnostics" or (kind in _FAST_KINDS and len(parts) == 4):
            self._scalar_message(parts, kind, stamp_ns, data)
            return
        try:
            msg = json.loads(data)
        except (ValueError, RecursionError):
            msg = None
        msg = fields.checked(kind, msg) if isinstance(msg, dict) else None
        t_ns = self.place(stamp_ns)
        self._span(t_ns)
        if msg is None:
            self.unreadable += 1
        elif topic == "/cm/events":
            start = self._about_record(stamp_ns, msg)
            self._event(t_ns if start is None else start, msg)
        elif topic == "/cm/alarms":
            self._alarms(msg)
        elif len(parts) == 4 and parts[1] == "cm":
            self._channel_message(parts[2], kind, t_ns, msg)

    def _span(self, t_ns: int) -> None:
        """The time span of the messages, to one at ``t_ns`` (as shown)."""
        if self.start_ns is None or self.end_ns is None:
            self.start_ns = self.end_ns = t_ns
        elif t_ns > self.end_ns:
            self.end_ns = t_ns
        elif t_ns < self.start_ns:
            self.start_ns = t_ns

    def _record_start(self, channel: str, stamp_ns: int, interval: float | None) -> int:
        """The shown time of the start of an indicator record of ``channel`` stamped ``stamp_ns``
        (its end) over ``interval`` seconds, noted for the alarm transitions it raises
        (:meth:`_about_record`)."""
        start = self.place(stamp_ns - int(round(interval * 1e9)), begins=True) if interval else self.place(stamp_ns)
        kept = self._records.setdefault(channel, {})
        kept[stamp_ns] = start
        if len(kept) > RECORDS_KEPT:
            del kept[next(iter(kept))]             # the oldest: its events came long ago
        return start

    def _about_record(self, stamp_ns: int, msg: dict[str, Any]) -> int | None:
        """The shown start of the indicator record an alarm transition ``msg`` is about (one of its
        channel stamped as it, among its newest RECORDS_KEPT: the event may come after newer
        records, written later by the reorder window; of a rule on a record's value), else None."""
        start = self._records.get(str(msg.get("channel")), {}).get(stamp_ns)
        if start is None or msg.get("kind") not in _TRANSITIONS:
            return None
        ch = self.channels.get(str(msg.get("channel")))
        rule = str(msg.get("alarm") or "").partition("/")[0]
        watched = ch.alarm_levels.get(rule, ("",))[0] if ch is not None else ""
        return None if watched == "severity_index" or watched.startswith("order.") else start

    def _scalar_message(self, parts: list[str], kind: str, stamp_ns: int, data: bytes) -> None:
        """A severity, indicators or diagnostics message, read by the fields drawn (:mod:`.fields`);
        counted as :attr:`unreadable` when it is surely no JSON object or one of them has a wrong type."""
        read = fields.diagnostics if kind == "diagnostics" else fields.severity if kind == "severity" \
            else fields.indicators
        got = read(data) if data[:1] == b"{" else None
        t_ns = self.place(stamp_ns)
        self._span(t_ns)
        if got is not None and kind == "indicators" and self.records_at_start:
            t_ns = self._record_start(parts[2], stamp_ns, got.get("interval_s"))
        if got is None:
            self.unreadable += 1
        elif kind == "diagnostics":
            self._diagnostics(t_ns, got)
        elif kind == "severity":
            ch = self.channel(parts[2])
            ch.severity.add(t_ns, got.get("severity_index"))
            ch.anomaly.add(t_ns, got.get("anomaly", 0.0))
            _level(ch, t_ns, got)
        else:
            self._indicators(self.channel(parts[2]), t_ns, got)

    def _channel_message(self, name: str, kind: str, t_ns: int, msg: dict[str, Any]) -> None:
        if kind == "orders":
            self._orders(self.channel(name), msg)
        elif kind in _CAPTURE_PARTS:
            self._capture(self.channel(name), _CAPTURE_PARTS[kind], t_ns, msg)

    def _event(self, t_ns: int, msg: dict[str, Any]) -> None:
        kind = str(msg.get("kind"))
        self.event_counts[kind] = self.event_counts.get(kind, 0) + 1
        if len(self.events) < MAX_EVENTS:
            self.events.append((t_ns, {"kind": kind, "channel": msg.get("channel"),
                                       "message": msg.get("message") or ""}))

    def _alarms(self, msg: dict[str, Any]) -> None:
        """An alarm table: each rule's alert and danger levels in force, on each channel it
        watches (a level the table leaves out keeps the one it gave before)."""
        for row in msg.get("alarms") or ():
            if not isinstance(row, dict) or not isinstance(row.get("rule"), str):
                continue
            names = [row["channel"]] if isinstance(row.get("channel"), str) else \
                [c for c in row.get("channels") or () if isinstance(c, str)]
            given = [v if isinstance(v, int | float) else None
                     for v in (row.get("alert_level"), row.get("danger_level"))]
            for name in names:
                ch = self.channel(name)
                old = ch.alarm_levels.get(row["rule"], ("", (None, None)))[1]
                levels = (given[0] if given[0] is not None else old[0], given[1] if given[1] is not None else old[1])
                ch.alarm_levels[row["rule"]] = (str(row.get("indicator")), levels)

    def _diagnostics(self, t_ns: int, got: dict[str, Any]) -> None:
        """Largest lag and queue depth; the message's counters (:func:`.fields.diagnostics`) to
        those of its run."""
        link = got.get("link", {})
        self.link_runs.add(t_ns, got.get("uptime_s", 0.0), link.get("bytes_received", 0.0),
                           (link, got.get("queue_drops", 0.0)))
        self.max_lag_s = max(self.max_lag_s, got.get("lag_s", 0.0))
        self.max_queue_depth = max(self.max_queue_depth, int(got.get("queue_depth", 0)))

    def link_counters(self) -> dict[str, int]:
        """The link counters over the whole log (summed over the daemon runs: :mod:`.link_runs`)."""
        return self.link_runs.totals()[0]

    def total_queue_drops(self) -> int:
        """Frames the daemons' queues dropped over the whole log."""
        return self.link_runs.totals()[1]

    def runs(self) -> int:
        """The daemon runs (starts, replays) whose link counters the totals sum."""
        return self.link_runs.totals()[2]

    @staticmethod
    def _indicators(ch: ChannelData, t_ns: int, msg: dict[str, Any]) -> None:
        """An indicator record's fields as :meth:`LogData._scalar_message` reads them: the trends
        of INDICATOR_FIELDS and of the bearing lines (``<bearing>.<line>``), the zone boundaries,
        the velocity band, the ISO alarm level."""
        for name, value in msg.items():
            if (name in _TRENDS or "." in name) and isinstance(value, int | float):
                trend = ch.indicators.get(name)
                if trend is None:
                    trend = ch.indicators[name] = Trend()
                trend.add(t_ns, float(value))
        if msg.get("zone_boundaries_mm_s"):
            ch.zone_boundaries = [float(x) for x in msg["zone_boundaries_mm_s"]]
        band = msg.get("velocity_band_hz")
        if isinstance(band, list) and len(band) == 2 and len(ch.velocity_bands) < MAX_VELOCITY_BANDS:
            pair = (float(band[0]), float(band[1]))
            if pair not in ch.velocity_bands:
                ch.velocity_bands.append(pair)
        if isinstance(msg.get("velocity_alarm_mm_s"), int | float):
            ch.velocity_alarm = float(msg["velocity_alarm_mm_s"])

    @staticmethod
    def _orders(ch: ChannelData, msg: dict[str, Any]) -> None:
        speed = msg.get("speed_rpm")
        if not msg.get("valid") or not isinstance(speed, int | float):
            return
        b = int(speed // SPEED_BIN_RPM)
        method = msg.get("method")
        tail = f" ({method})" if isinstance(method, str) and method != "recursive" else ""
        for order in msg.get("orders") or ():
            rms = order.get("rms")
            if isinstance(rms, int | float):
                name = f"{order.get('name')}{tail}"
                bins = ch.orders.setdefault(name, {})
                acc = bins.setdefault(b, [0.0, 0.0])
                acc[0] += rms
                acc[1] += 1
                freq = order.get("freq_hz")
                if isinstance(freq, int | float):
                    cell = ch.campbell.setdefault(name, {}).setdefault(b, [0.0, 0.0, 0.0])
                    cell[0] += freq
                    cell[1] += rms
                    cell[2] += 1

    @staticmethod
    def _capture(ch: ChannelData, part: str, t_ns: int, msg: dict[str, Any]) -> None:
        kind = (msg.get("trigger") or {}).get("kind")
        for cap in ch.captures:
            first = next(iter(cap.parts.values()))
            if cap.time_ns == t_ns and (first.get("trigger") or {}).get("kind") == kind and part not in cap.parts:
                cap.parts[part] = msg
                return
        if len(ch.captures) >= MAX_CAPTURES:
            ch.captures_omitted += part == "waveform"
            return
        ch.captures.append(Capture(ch.name, t_ns, {part: msg}, ch.recording, ch.recording_id))


def _level(ch: ChannelData, t_ns: int, msg: dict[str, Any]) -> None:
    """A combined severity message's level / baseline and its alert and danger ratios."""
    ch.level.add(t_ns, msg.get("level_ratio"))
    alert, danger = msg.get("level_alert"), msg.get("level_danger")
    if isinstance(alert, (int, float)) and isinstance(danger, (int, float)):
        ch.level_limits = (float(alert), float(danger))
