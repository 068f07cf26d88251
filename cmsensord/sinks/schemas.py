"""JSON schemas of the MCAP output, one per topic kind (the output contract).

Every message is JSON (message_encoding ``json``) described by a JSON Schema
(schema encoding ``jsonschema``). Timestamps are ``{"sec": int, "nsec": int}``
(nanoseconds since the Unix epoch, split), the form Foxglove recognises as a
time.

The schemas keep to what every Foxglove JSON-schema reader accepts (Foxglove
and Lichtblick's ``parseJsonSchema``): every object has ``"type": "object"``
and ``properties``; every field one ``type`` (boolean, string, number,
integer, object, or an array of one of these), or a ``oneOf`` of numeric
constants (``foxglove.Log``'s level); no union types, no ``null``. **A missing
value is an absent field**: JSON never carries NaN, infinity or ``null``; a
value that is missing (a lost observation) or not finite is left out of the
message (the encoder drops every ``None``), so such fields are not in
``required``, and a flag says why where it matters (``missing`` of AkfTrace and
VibrationEstimate, ``valid`` of Orders). An event of the link or the daemon has
no ``channel``; a fixed-frequency component of Orders has no ``order``.

Topics (``<channel>`` is the configured channel name, default ``ch0``, ``ch1``...):

=========================  ======================  =================================
topic                      schema name             rate
=========================  ======================  =================================
/cm/<channel>/severity     cmsensord.Severity      once per decision period (1 Hz)
/cm/<channel>/akf          cmsensord.AkfTrace      per observation (100 Hz)
/cm/<channel>/orders       cmsensord.Orders        per order-tracker output
/cm/events                 cmsensord.Event         on every event
/cm/log                    foxglove.Log            on every event (Foxglove's Log panel)
/cm/diagnostics            cmsensord.Diagnostics   1 Hz
=========================  ======================  =================================

``/cm/<channel>/indicators`` (cmsensord.Indicators, :mod:`.indicator_schema`) once per
``indicators.interval_s``, and, for a microphone channel (Orimoto, Ikuta & Wang), ``/cm/<channel>/vibration_estimate``
(cmsensord.VibrationEstimate) once per block (100 Hz).

The quantities of Kim et al. 2023 keep the paper's names: S_idx (eq. 17), F_a and cnt
(Fig. 3), R_i (eq. 16), x^-(k), x^(k), Y(k), z(k) (eqs. 3-15), Q^(k) (eq. 10).
"""

from __future__ import annotations

import json
from typing import Any

from cmsensord.sinks.alarm_schema import TOPIC_ALARMS, alarms_schema
from cmsensord.sinks.capture_schema import capture_spectrum_schema, capture_waveform_schema
from cmsensord.sinks.indicator_schema import indicators_schema

__all__ = [
    "SCHEMA_ENCODING",
    "MESSAGE_ENCODING",
    "SCHEMAS",
    "SCHEMA_NAMES",
    "EVENT_KINDS",
    "LINK_COUNTERS",
    "TOPIC_EVENTS",
    "TOPIC_DIAGNOSTICS",
    "TOPIC_LOG",
    "LOG_LEVELS",
    "TOPIC_ALARMS",
    "severity_topic",
    "akf_topic",
    "orders_topic",
    "indicators_topic",
    "vibration_estimate_topic",
    "schema_name",
    "schema_bytes",
]

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
_DIALECT = "https://json-schema.org/draft/2020-12/schema"

TOPIC_EVENTS = "/cm/events"
TOPIC_DIAGNOSTICS = "/cm/diagnostics"
TOPIC_LOG = "/cm/log"

#: foxglove.LogLevel: name -> value
LOG_LEVELS: dict[str, int] = {"UNKNOWN": 0, "DEBUG": 1, "INFO": 2, "WARNING": 3, "ERROR": 4, "FATAL": 5}


def severity_topic(channel: str) -> str:
    return f"/cm/{channel}/severity"


def akf_topic(channel: str) -> str:
    return f"/cm/{channel}/akf"


def orders_topic(channel: str) -> str:
    return f"/cm/{channel}/orders"


def indicators_topic(channel: str) -> str:
    return f"/cm/{channel}/indicators"


def vibration_estimate_topic(channel: str) -> str:
    return f"/cm/{channel}/vibration_estimate"


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

#: The integer counters of Diagnostics.link (docs/PROTOCOL.md, receiver rule 5).
LINK_COUNTERS: tuple[str, ...] = (
    "bytes_received",
    "bytes_discarded",
    "crc_failures",
    "header_rejects",
    "frames_status",
    "frames_rms",
    "frames_raw",
    "frames_tacho",
    "frames_lost",
    "overruns",
    "frames_repeated",
)

# ---------------------------------------------------------------------------
# building blocks
# ---------------------------------------------------------------------------


def _time() -> dict[str, Any]:
    return {
        "type": "object",
        "title": "time",
        "description": "Time of the message: seconds and nanoseconds since the Unix epoch.",
        "properties": {
            "sec": {"type": "integer", "minimum": 0, "description": "whole seconds"},
            "nsec": {
                "type": "integer",
                "minimum": 0,
                "maximum": 999_999_999,
                "description": "nanoseconds within the second",
            },
        },
        "required": ["sec", "nsec"],
    }


def _num(description: str, nullable: bool = True) -> dict[str, Any]:
    """A number; ``nullable``: absent from a message when missing or not finite (so not required)."""
    if nullable:
        return {"type": "number", "description": description + " (absent when missing or not finite)"}
    return {"type": "number", "description": description}


def _int(description: str, minimum: int | None = 0) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "integer", "description": description}
    if minimum is not None:
        out["minimum"] = minimum
    return out


def _obj(title: str, description: str, properties: dict[str, Any], required: list[str]) -> dict:
    missing = set(required) - set(properties)
    assert not missing, missing  # a schema must describe what it requires
    return {
        "$schema": _DIALECT,
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": required,
    }


_CHANNEL = {"type": "string", "description": "configured channel name (ch0, ch1, ... by default)"}

def _str(description: str) -> dict[str, Any]:
    return {"type": "string", "description": description}


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

# ---------------------------------------------------------------------------
# the schemas
# ---------------------------------------------------------------------------

SEVERITY = _obj(
    "cmsensord.Severity",
    "Severity assessment (Kim et al. 2023) of one channel, published at every anomaly decision "
    "(once per decision period, 1 s by default).",
    {
        "timestamp": _time(),
        "channel": _CHANNEL,
        "severity_index": {
            "type": "number",
            "minimum": 0,
            "maximum": 1,
            "description": "S_idx = max_i I_i with I_i = i/n if F_a of AKF_i is 1 else 0 (eqs. 17-18)",
        },
        "level": {
            "type": "integer",
            "minimum": 0,
            "description": "round(S_idx * n): index of the highest-R AKF in anomaly, 0 = none",
        },
        "anomaly": {
            "type": "array",
            "items": {"type": "integer", "enum": [0, 1]},
            "description": "F_a of AKF_i for i = 1..n after this decision (Fig. 3)",
        },
        "outliers": {
            "type": "array",
            "items": {"type": "integer", "minimum": 0},
            "description": "cnt of AKF_i for i = 1..n at the decision: outliers |z| > z_c "
            "counted in this period",
        },
        "f_r": _num("rotation frequency [Hz] compared with cnt in this decision", nullable=False),
        "r": {
            "type": "array",
            "items": {"type": "number"},
            "description": "R_i = R_min + i (R_max - R_min) / n of AKF_i, i = 1..n (eq. 16)",
        },
        "failure": {
            "type": "boolean",
            "description": "true while AKF_n (the largest R) is in anomaly, or the combined severity is 1",
        },
        "missing": _int("observations missing (lost frames) in this decision period"),
        "no_data": {
            "type": "boolean",
            "description": "true when more than half the period's observations are missing: the "
                           "period is not judged, severity_index and anomaly are the ones held",
        },
        "transient": {
            "type": "boolean",
            "description": "true for the first decision period, while the filters converge",
        },
        "severity_akf": _num("combined: S_idx of the AKF bank", nullable=False),
        "severity_level": _num("combined: S_level of level_ratio", nullable=False),
        "level_ratio": _num("combined: the decision period's RMS / baseline", nullable=False),
        "level_alert": _num("combined: the level_ratio graded 0.5 (monitor.level_alert)", nullable=False),
        "level_danger": _num("combined: the level_ratio graded 1 (monitor.level_danger)", nullable=False),
        "signal_lost": {
            "type": "boolean",
            "description": "true when the decision has no signal (a sensor, cable or ADC fault, or the "
                           "machine stopped): combined, level_ratio below monitor.signal_floor; RAW, blocks "
                           "whose samples are all one ADC count (monitor.flat_signal); severity_index is "
                           "then the one held",
        },
    },
    [
        "timestamp",
        "channel",
        "severity_index",
        "level",
        "anomaly",
        "outliers",
        "f_r",
        "r",
        "failure",
        "missing",
        "transient",
    ],
)

AKF_TRACE = _obj(
    "cmsensord.AkfTrace",
    "One observation through one AKF of the bank (Kim et al. 2023, eqs. 3-15).",
    {
        "timestamp": _time(),
        "channel": _CHANNEL,
        "filter": _int("1-based index i of AKF_i in the bank", minimum=1),
        "y": _num("observation y(k) (block RMS)"),
        "x_hat": _num("a posteriori estimate x^(k) (eq. 8)"),
        "x_prior": _num("a priori estimate x^-(k) = x^(k-1) (eq. 3)"),
        "lower": _num("lower adaptive bound x^-(k) - z_c sqrt(Y(k)) (eqs. 6, 15)"),
        "upper": _num("upper adaptive bound x^-(k) + z_c sqrt(Y(k)) (eqs. 6, 15)"),
        "z": _num("normalised correction z(k) = innovation / sqrt(Y(k)) (eq. 15)"),
        "outlier": {"type": "boolean", "description": "|z(k)| > z_c"},
        "q_hat": _num("process noise estimate Q^(k) = S(k) M(k) (eq. 10)"),
        "missing": {
            "type": "boolean",
            "description": "the observation was lost: time update only, y and z are absent",
        },
    },
    ["timestamp", "channel", "filter", "outlier", "missing"],
)

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

DIAGNOSTICS = _obj(
    "cmsensord.Diagnostics",
    "Health of the link and the processing loop, once per second.",
    {
        "timestamp": _time(),
        "link": {
            "type": "object",
            "description": "link counters since start (docs/PROTOCOL.md, receiver rule 5)",
            "properties": {
                "bytes_received": _int("bytes read from the link"),
                "bytes_discarded": _int("bytes dropped while hunting for a frame"),
                "crc_failures": _int("frames with a bad CRC"),
                "header_rejects": _int("sync found but header invalid (version, type, len)"),
                "frames_status": _int("STATUS frames decoded"),
                "frames_rms": _int("RMS frames decoded"),
                "frames_raw": _int("RAW frames decoded"),
                "frames_tacho": _int("TACHO frames decoded"),
                "frames_lost": _int("frames lost, from seq gaps"),
                "overruns": _int("frames with the ADC overrun flag"),
                "frames_repeated": _int("frames received again (the same frame twice), dropped"),
            },
            "required": list(LINK_COUNTERS),
        },
        "queue_depth": _int("frames waiting in the pipeline queue"),
        "queue_drops": _int("frames dropped because the queue was full, since start"),
        "lag_s": _num("processing lag: wall clock minus the time of the last processed frame [s]"),
        "observations": _int("observations processed since start"),
        "uptime_s": _num("seconds since the daemon started", nullable=False),
        "mqtt": {"type": "object", "description": "the link to the MQTT broker (only with an mqtt "
                 "section)", "properties": {
                     "state": {"type": "string", "description": "connecting, connected, disconnected, refused"},
                     "queued": {"type": "integer", "description": "messages queued, not yet acknowledged"},
                     "queue_bytes": {"type": "integer", "description": "the disk queue's size [bytes]"},
                     "dropped": {"type": "integer", "description": "messages dropped since start (queue bound)"},
                     "sent": {"type": "integer", "description": "messages sent since start"},
                     "acked": {"type": "integer", "description": "messages the broker acknowledged since start"}}},
    },
    ["timestamp", "link", "queue_depth", "queue_drops", "observations", "uptime_s"],
)

ORDERS = _obj(
    "cmsensord.Orders",
    "Order tracking of one channel (Yeh, Pan & Le): shaft speed and, per tracked component (an "
    "order of the shaft speed or a fixed frequency), RMS and amplitude over the output block.",
    {
        "timestamp": _time(),
        "channel": _CHANNEL,
        "speed_rpm": _num("shaft speed [rpm], mean over the block"),
        "valid": {"type": "boolean",
                  "description": "false below orders.min_rpm or without a tacho speed (the "
                                 "orders cannot be told apart), or when every sample of the block "
                                 "was lost (a prediction): rms/amplitude are absent"},
        "method": {"type": "string", "enum": ["recursive", "smoothed", "batch"],
                   "description": "recursive (Yeh, Pan & Le, causal), smoothed (fixed-lag RTS) or "
                                  "batch (Tůma's second-generation VKF, zero-phase)"},
        "orders": {
            "type": "array",
            "description": "one entry per tracked component",
            "items": {
                "type": "object",
                "properties": {
                    "name": {"type": "string", "description": "component name (configured)"},
                    "order": {"type": "number",
                              "description": "order (multiple of shaft speed); absent for a fixed frequency"},
                    "freq_hz": _num("frequency of the component over the block [Hz]"),
                    "rms": _num("RMS of the tracked waveform over the block [m/s^2]"),
                    "amplitude": _num("0-peak amplitude, the mean envelope of the tracked waveform over "
                                      "the block [m/s^2] (a steady sine of amplitude a reads a, its rms a / sqrt 2)"),
                },
                "required": ["name"],
            },
        },
        "missing_fraction": {"type": "number", "minimum": 0, "maximum": 1,
                             "description": "recursive and smoothed: fraction of the block's samples "
                                            "without a measurement (lost RAW frames, gaps); rms and "
                                            "amplitude there are the tracker's predictions. 0 when none"},
    },
    ["timestamp", "channel", "valid", "orders"],
)

VIBRATION_ESTIMATE = _obj(
    "cmsensord.VibrationEstimate",
    "Orimoto, Ikuta & Wang estimate of the machine's vibration from the sound of a microphone channel "
    "(kind: microphone), one per block (10 ms): the recursive Bayesian estimator of eqs. 6-38. "
    "x_hat = sqrt(x_ms) is what the channel's AKF bank watches in place of an accelerometer's block RMS.",
    {
        "timestamp": _time(),
        "channel": _CHANNEL,
        "x_hat": _num("estimated vibration as a block RMS acceleration [m/s^2]: sqrt(x_ms), what "
                      "the channel's AKF bank watches"),
        "x_ms": _num("estimated vibration energy x^_k, the block mean square acceleration "
                     "[(m/s^2)^2] (eq. 16)"),
        "x_ms_var": _num("its variance P_x,k [(m/s^2)^4] (eq. 18)"),
        "a_hat": _num("estimated sound-vibration correlation parameter a^_k (eq. 17)"),
        "a_var": _num("its variance P_a,k (eq. 19)"),
        "y_hat": _num("estimated machine sound energy y^_k without the background [Pa^2] (eq. 21)"),
        "y_var": _num("its variance P_y,k [Pa^4] (eq. 22)"),
        "z": _num("observed sound energy z_k = y_k + v_k, the block mean square [Pa^2] (eq. 1)"),
        "z_pred": _num("predicted sound energy z*_k = <z_k | Z_k-1> [Pa^2]"),
        "missing": {"type": "boolean",
                    "description": "the block was lost: prediction only (eqs. 34-38), z is absent"},
    },
    ["timestamp", "channel", "missing"],
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

#: kind key -> JSON schema.
SCHEMAS: dict[str, dict[str, Any]] = {
    "severity": SEVERITY,
    "akf": AKF_TRACE,
    "event": EVENT,
    "diagnostics": DIAGNOSTICS,
    "orders": ORDERS,
    "vibration_estimate": VIBRATION_ESTIMATE,
    "log": LOG,
    "indicators": indicators_schema(_time(), _obj),
    "capture_waveform": capture_waveform_schema(_time, _obj),
    "capture_spectrum": capture_spectrum_schema(_time, _obj),
    "alarms": alarms_schema(_time(), _obj),
}

#: kind key -> MCAP schema name.
SCHEMA_NAMES: dict[str, str] = {kind: s["title"] for kind, s in SCHEMAS.items()}


def schema_name(kind: str) -> str:
    """MCAP schema name of a kind key ("severity" -> "cmsensord.Severity")."""
    return SCHEMA_NAMES[kind]


def schema_bytes(kind: str) -> bytes:
    """The schema of a kind key as UTF-8 JSON, as stored in the MCAP Schema record."""
    return json.dumps(SCHEMAS[kind], separators=(",", ":")).encode("utf-8")
