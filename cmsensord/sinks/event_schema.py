"""The JSON schemas of ``/cm/events`` (cmsensord.Event) and ``/cm/log`` (foxglove.Log, the
events again for Foxglove's Log panel): every kind of event, the further fields by kind, the
log levels.  :mod:`.schemas` registers them with the other topics' schemas."""

from __future__ import annotations

from typing import Any

from cmsensord.sinks.schema_parts import _int, _num, _obj, _str, _time

__all__ = ["EVENT_KINDS", "EVENT", "LOG", "LOG_LEVELS"]

#: foxglove.LogLevel: name -> value
LOG_LEVELS: dict[str, int] = {"UNKNOWN": 0, "DEBUG": 1, "INFO": 2, "WARNING": 3, "ERROR": 4, "FATAL": 5}

#: Every value of Event.kind.
EVENT_KINDS: tuple[str, ...] = (
    "anomaly_onset",
    "anomaly_clear",
    "anomaly_held",
    "decision_rule",
    "order_alarm",
    "order_alarm_clear",
    "tacho_lost",
    "tacho_restored",
    "tacho_missed_pulse",
    "tacho_extra_pulse",
    "severity_change",
    "failure",
    "failure_clear",
    "signal_lost",
    "signal_back",
    "flat_blocks",
    "frames_lost",
    "frames_repeated",
    "link_lost",
    "link_restored",
    "link_stalled",
    "reader_error",
    "reader_recovered",
    "reader_died",
    "queue_overflow",
    "decode_error",
    "channels",
    "config",
    "lines_unresolved",
    "line_harmonics",
    "band_above_nyquist",
    "band_too_narrow",
    "start",
    "stop",
    "disk_error",
    "retention",
    "salvage",
    "time_base",
    "capture",
    "capture_skipped",
    "mqtt_link",
    "mqtt_queue",
    "alarm_alert",
    "alarm_danger",
    "alarm_clear",
    "alarm_ack",
    "alarm_no_baseline",
    "alarm_restored",
    "alarm_not_restored",
    "alarm_state_error",
    "operating_state",
)

#: Event.details: further fields by kind (disk_error and salvage by ``action``, time_base)
_DETAILS: dict[str, Any] = {
    "type": "object",
    "description": "further fields, by kind; only those that apply are present",
    "properties": {
        "action": _str("disk_error, retention, salvage: what happened (abandoned, resumed, removed, "
                       "retention, retention_failed, low_space, salvage_failed, dir_fsync_failed, relocked, "
                       "relock_failed, relock_waiting; salvaged, "
                       "deleted, unreadable, ...)"),
        "op": _str("disk_error: the failed operation (open, write, fsync, close, read)"),
        "errno": _str("disk_error: the OS error's name (ENOSPC, EIO, ...)"),
        "file": _str("the file concerned"),
        "source": _str("salvage: the .part file read"),
        "kept": _str("salvage: where a damaged or unreadable file was kept"),
        "files": {"type": "array", "items": {"type": "string"},
                  "description": "retention: the files deleted"},
        "bytes": _int("retention: bytes freed; low_space: bytes free"),
        "unsynced": _int("disk_error: messages written since the last good fsync"),
        "errors": _int("disk_error (resumed): failed disk operations during the outage"),
        "chunks": _int("salvage: chunks recovered"),
        "dropped_bytes": _int("salvage: bytes that were not a complete chunk"),
        "lost_chunks": _int("salvage: damaged chunks skipped"),
        "lost_messages": _int("salvage: messages of the damaged chunks"),
        "segment": _int("time_base: the new time segment"),
        "reason": _str("time_base: reset (the board's clock restarted) or drift"),
        "offset_s": {"type": "number", "description": "time_base (drift): board clock minus wall clock [s]"},
        "rate_hz": _int("time_base (drift): the board clock's measured rate [Hz]"),
        "state": _str("operating_state: the machine's new operating state (stopped, starting, running, "
                      "coasting)"),
        "previous": _str("operating_state: the state before"),
        "bearing": _str("lines_unresolved, line_harmonics, band_too_narrow: the configured bearing"),
        "lines": {"type": "array", "items": {"type": "string"}, "description": "its lines: lines_unresolved: "
                  "not resolved; band_too_narrow: past the envelope; line_harmonics: window holds 3 x another"},
        "harmonic_of": {"type": "array", "items": {"type": "string"}, "description": "line_harmonics: per line, "
                        "the defect frequency whose third harmonic its window holds"},
        "bin_hz": {"type": "number", "description": "lines_unresolved: the envelope spectrum's bin width [Hz]; "
                   "band_too_narrow: the record's spectral bin width [Hz]"},
        "band": _str("band_too_narrow: the configured band that holds no bin"),
    },
}

EVENT = _obj(
    "cmsensord.Event",
    "Something that happened: an anomaly decision changing, a link fault, start and stop.",
    {
        "timestamp": _time(),
        "kind": {"type": "string", "enum": list(EVENT_KINDS), "description": "what happened"},
        "channel": {
            "type": "string",
            "description": "channel name; absent for an event of the link or the daemon",
        },
        "message": {"type": "string", "description": "human-readable, one line"},
        "filter": _int("1-based AKF index the event is about", minimum=1),
        "severity_index": _num("S_idx after the event (eq. 17)"),
        "level": _int("round(S_idx * n) after the event"),
        "alarm": _str("alarm_*: the alarm's name (rule/channel)"),
        "alarm_level": {"type": "string", "enum": ["normal", "alert", "danger"],
                        "description": "alarm_*: the alarm's level after the transition"},
        "previous_level": {"type": "string", "enum": ["normal", "alert", "danger"],
                           "description": "alarm_*: the alarm's level before it"},
        "filters": {"type": "array", "items": {"type": "integer"},
                    "description": "anomaly_held: the AKFs (1-based) whose flags the hysteresis holds"},
        "samples": _int("capture, capture_skipped: samples in the capture"),
        "n_channels": _int("channels: the channel count the board sends now", minimum=0),
        "state": _str("mqtt_link: the link's state (connected, disconnected, refused, failed)"),
        "queued": _int("mqtt_link: messages in the store-and-forward queue"),
        "action": _str("mqtt_queue: what happened (truncated, damaged, cursor_unreadable, skipped, resumed, "
                       "write_error, read_error, encode_error, handover_dropped, dropped, dropping)"),
        "bytes": _int("mqtt_queue (truncated, damaged): bytes cut from the queue's end or skipped as damaged"),
        "reason": _str("mqtt_queue (write_error, read_error): why the queue cannot be written or read"),
        "total": _int("mqtt_queue: messages dropped since start"),
        "count": _int("how many (frames lost, bytes discarded, queue drops, ...)"),
        "summarised": _int("a summary of this many events of the kind held back (at most 5 a "
                           "second are written one by one)"),
        "raw_total": _int("queue_overflow: RAW frames dropped from the queue since start"),
        "details": _DETAILS,
    },
    ["timestamp", "kind", "message"],
)


#: foxglove.Log, as published by Foxglove (foxglove-sdk ``schemas/jsonschema/Log.json``): the
#: events again, for Foxglove's Log panel
def _ref(title: str, description: str, what: str) -> dict[str, Any]:
    return {"title": title, "description": description, "type": "object", "properties": {
        "topic": {"type": "string", "description": f"Topic name of the {what} message"},
        "message_id": {"type": "string", "description": f"Unique identifier of the {what} message "
                                                        "(e.g., UUID7, ULID, or custom format)"}},
        "required": ["topic", "message_id"]}


LOG = {
    "title": "foxglove.Log",
    "description": "A log message",
    "$comment": "Generated by https://github.com/foxglove/foxglove-sdk",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object",
            "title": "time",
            "properties": {
                "sec": {"type": "integer", "minimum": 0},
                "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
            },
            "description": "Timestamp of log message",
        },
        "level": {
            "title": "foxglove.LogLevel",
            "description": "Log level",
            "oneOf": [{"title": name, "const": value,
                       "description": f"{name.capitalize()} log level"} for name, value in LOG_LEVELS.items()],
        },
        "message": {"type": "string", "description": "Log message"},
        "name": {"type": "string", "description": "Process or node name"},
        "file": {"type": "string", "description": "Filename"},
        "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
        "message_id": {"type": "string",
                       "description": "Unique identifier for this message (e.g., UUID7, ULID, or custom format)"},
        "lineage": {
            "title": "foxglove.LineageInfo",
            "description": "Lineage information for tracking data provenance",
            "type": "object",
            "properties": {
                "inputs": {"type": "array", "items": _ref(
                    "foxglove.InputReference", "Reference to an input message used in lineage tracking",
                    "input"), "description": "References to input messages that contributed to this message"},
                "processing_node": {"type": "string",
                                    "description": "Name of the processing node that produced this message"},
                "state": _ref("foxglove.StateReference",
                              "Optional reference to the state of the processing node", "state"),
            },
            "required": ["inputs", "processing_node"],
        },
    },
    "required": ["timestamp", "level", "message", "name", "file", "line"],
}

