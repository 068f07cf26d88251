"""Home Assistant MQTT discovery (``mqtt.discovery``): per monitored channel (the Processor's,
once the board says which), a sensor for its severity index when ``severity`` is published
and, when ``alarms`` is published and there are alarm rules, one for its worst alarm: each
sensor only when its state topic is published, else it would stay "unknown".

Each message is retained at ``<discovery_prefix>/sensor/<client>_<channel>_<what>/config``;
a sensor not announced gets an empty retained message there, which removes one an earlier
configuration announced (from the broker and from Home Assistant).
The severity sensor reads ``severity_index`` from ``<prefix>/<channel>/severity``; the worst
alarm sensor reads ``level`` (normal, alert, danger) from ``<prefix>/<channel>/worst_alarm``,
a retained state derived from each ``/cm/alarms`` table by :class:`WorstAlarms` (the table is
plant-wide). Both take ``<prefix>/status`` (``online`` / the last will ``offline``) as their
availability.
"""

from __future__ import annotations

import json
import re
from typing import Any

from cmsensord.alarms import LEVELS
from cmsensord.config.mqtt import MqttConfig
from cmsensord.publish.topics import TopicMap


def discovery_messages(cfg: MqttConfig, channels: tuple[str, ...], worst_alarm: bool = True) -> list[tuple[str, str]]:
    """(topic, JSON) of the discovery message of each channel's severity sensor when
    ``severity`` is in ``cfg.publish`` and of its worst alarm sensor when ``worst_alarm`` and
    ``alarms`` is; (topic, ``""``) for each sensor not announced (its removal)."""
    topics = TopicMap(cfg)
    node = re.sub(r"[^A-Za-z0-9_-]", "_", cfg.client)
    common: dict[str, Any] = {"availability_topic": topics.status, "payload_available": "online",
                              "payload_not_available": "offline",
                              "device": {"identifiers": [f"cmsensord_{node}"],
                                         "name": f"cmsensord {cfg.client}", "manufacturer": "cmsensord"}}
    out = []
    for ch in channels:
        sensors: dict[str, dict[str, Any] | None] = {"severity": None, "worst_alarm": None}
        if "severity" in cfg.publish:
            sensors["severity"] = {"name": f"{ch} severity", "state_topic": f"{topics.prefix}/{ch}/severity",
                                   "value_template": "{{ value_json.severity_index }}",
                                   "state_class": "measurement"}
        if worst_alarm and "alarms" in cfg.publish:
            state = topics.worst_alarm(ch)
            sensors["worst_alarm"] = {"name": f"{ch} worst alarm", "state_topic": state,
                                      "value_template": "{{ value_json.level }}",
                                      "json_attributes_topic": state, "device_class": "enum",
                                      "options": list(LEVELS)}
        for what, body in sensors.items():
            uid = f"{node}_{ch}_{what}"
            config = "" if body is None else json.dumps({**body, "unique_id": f"cmsensord_{uid}", **common})
            out.append((f"{cfg.discovery_prefix}/sensor/{uid}/config", config))
    return out


class WorstAlarms:
    """Each channel's worst alarm, from the plant-wide ``/cm/alarms`` tables, as it changes."""

    def __init__(self, channels: tuple[str, ...]) -> None:
        self.channels = channels
        self._last: dict[str, dict] = {}

    def changed(self, table: dict) -> list[tuple[str, dict]]:
        """(channel, state) of each channel whose state differs from the last table's (all at
        the first). The state is ``{"level": L}`` with L the highest level shown by an alarm
        watching the channel (its own, or a voting alarm over it; ``normal`` if none), and
        ``"alarm"``: the id of the first alarm (config order) showing L, when L is not normal."""
        out = []
        for ch in self.channels:
            rows = [r for r in table.get("alarms", ()) if ch in r.get("channels", ())]
            level = max((LEVELS.index(r["level"]) for r in rows), default=0)
            state = {"level": LEVELS[level]}
            if level:
                state["alarm"] = next(r["id"] for r in rows if r["level"] == LEVELS[level])
            if self._last.get(ch) != state:
                self._last[ch] = state
                out.append((ch, state))
        return out
