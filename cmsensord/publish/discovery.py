"""Home Assistant MQTT discovery (``mqtt.discovery``): one sensor per channel for its severity index.

Each message is retained at ``<discovery_prefix>/sensor/<client>_<channel>_severity/config`` and
tells Home Assistant to read ``severity_index`` from ``<prefix>/<channel>/severity``, with
``<prefix>/status`` (``online`` / the last will ``offline``) as its availability.
"""

from __future__ import annotations

import json
import re

from cmsensord.config.mqtt import MqttConfig
from cmsensord.publish.topics import TopicMap


def discovery_messages(cfg: MqttConfig, channels: tuple[str, ...]) -> list[tuple[str, str]]:
    """(topic, JSON) of the discovery message of each channel's severity sensor."""
    topics = TopicMap(cfg)
    node = re.sub(r"[^A-Za-z0-9_-]", "_", cfg.client)
    device = {"identifiers": [f"cmsensord_{node}"], "name": f"cmsensord {cfg.client}",
              "manufacturer": "cmsensord"}
    out = []
    for ch in channels:
        uid = f"{node}_{ch}_severity"
        body = {"name": f"{ch} severity", "unique_id": f"cmsensord_{uid}",
                "state_topic": f"{topics.prefix}/{ch}/severity",
                "value_template": "{{ value_json.severity_index }}", "state_class": "measurement",
                "availability_topic": topics.status, "payload_available": "online",
                "payload_not_available": "offline", "device": device}
        out.append((f"{cfg.discovery_prefix}/sensor/{uid}/config", json.dumps(body)))
    return out
