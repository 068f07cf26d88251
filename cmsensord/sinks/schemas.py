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

The schemas of /cm/events and /cm/log, with every kind of event and the log levels, are
:mod:`.event_schema`'s; the building blocks of every schema, :mod:`.schema_parts`'.
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
from cmsensord.sinks.event_schema import EVENT, LOG
from cmsensord.sinks.indicator_schema import indicators_schema
from cmsensord.sinks.schema_parts import _CHANNEL, _int, _num, _obj, _time

__all__ = [
    "SCHEMA_ENCODING",
    "MESSAGE_ENCODING",
    "SCHEMAS",
    "SCHEMA_NAMES",
    "LINK_COUNTERS",
    "TOPIC_EVENTS",
    "TOPIC_DIAGNOSTICS",
    "TOPIC_LOG",
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

TOPIC_EVENTS = "/cm/events"
TOPIC_DIAGNOSTICS = "/cm/diagnostics"
TOPIC_LOG = "/cm/log"


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
