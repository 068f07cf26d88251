"""The JSON schema of ``/cm/alarms`` (cmsensord.Alarms): the alarm table whenever it changes.

Written by :mod:`cmsensord.monitor.alarms` when an alarm's shown or live level,
its latch or acknowledgement, the levels in force (a speed band, the first value)
or the machine's operating state changes.  No
union types: a value not known (no value seen yet, a level not given, a baseline
not learned, a voting alarm's channel) is absent.  :mod:`.schemas` registers it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["alarms_schema", "TOPIC_ALARMS"]

TOPIC_ALARMS = "/cm/alarms"
_LEVEL = {"type": "string", "enum": ["normal", "alert", "danger"]}


def _n(description: str) -> dict[str, Any]:
    return {"type": "number", "description": description}


def _row(time: dict[str, Any]) -> dict[str, Any]:
    return {"type": "object", "description": "one alarm", "properties": {
        "id": {"type": "string", "description": "<rule>/<channel>, or <rule> for a voting alarm"},
        "rule": {"type": "string", "description": "configured rule name"},
        "indicator": {"type": "string", "description": "the indicator watched"},
        "channel": {"type": "string", "description": "the channel (absent for a voting alarm)"},
        "channels": {"type": "array", "items": {"type": "string"}, "description": "channels watched"},
        "level": {**_LEVEL, "description": "level shown: the live level, or the latched one until acknowledged"},
        "live": {**_LEVEL, "description": "level after the delays, without the latch"},
        "latched": {"type": "boolean", "description": "a latched level is held until acknowledged"},
        "acknowledged": {"type": "boolean", "description": "acknowledged while still showing a level"},
        "value": _n("newest value of the indicator (voting: the highest of the channels) [its unit]"),
        "alert_level": _n("alert level in force [the indicator's unit]"),
        "danger_level": _n("danger level in force [the indicator's unit]"),
        "since": {**time, "description": "when the shown level last changed"},
        "restored": {"type": "boolean", "description": "present (true) while the level shown is the one "
                     "active when the daemon stopped, put back at its restart and not yet confirmed by "
                     "the rule"},
    }, "required": ["id", "rule", "indicator", "channels", "level", "live", "latched", "acknowledged"]}


def alarms_schema(time: dict[str, Any], obj: Callable[..., dict]) -> dict[str, Any]:
    """The schema, built with the shared ``time`` object and ``obj`` builder of :mod:`.schemas`."""
    return obj(
        "cmsensord.Alarms",
        "The alarm table, written whenever an alarm's level, latch or acknowledgement or the "
        "machine's operating state changes.",
        {
            "timestamp": time,
            "operating_state": {"type": "string", "enum": ["stopped", "starting", "running", "coasting"],
                                "description": "alarms are evaluated only while running"},
            "worst": {**_LEVEL, "description": "highest level shown by any alarm"},
            "worst_alarm": {"type": "string", "description": "the first alarm showing that level"},
            "speed_rpm": _n("newest shaft speed [rpm]"),
            "alarms": {"type": "array", "items": _row(time), "description": "every alarm, in config order"},
        },
        ["timestamp", "operating_state", "worst", "alarms"],
    )
