"""MCAP topic -> MQTT topic, retain flag and payload.

``/cm/<channel>/<kind>`` is published as ``<prefix>/<channel>/<kind>`` and ``/cm/<kind>`` as
``<prefix>/<kind>`` when ``<kind>`` is in the ``publish`` list; the payload is the message's
MCAP JSON (same schema, :func:`~cmsensord.sinks.mcap_encoding.encode_message`) with one more
field, ``seq``: the message's number in the daemon's queue to the broker, 1, 2, 3, ... over all
topics and across restarts, so a receiver of ``<prefix>/#`` sees a gap or a duplicate at once.
"""

from __future__ import annotations

from cmsensord.config.mqtt import RETAINED, MqttConfig
from cmsensord.sinks.mcap_encoding import encode_message


class TopicMap:
    """Which MCAP messages are published, where, and whether retained."""

    def __init__(self, cfg: MqttConfig) -> None:
        self.prefix = cfg.prefix
        self.kinds = frozenset(cfg.publish)
        self._cache: dict[str, tuple[str, bool] | None] = {}

    def route(self, topic: str) -> tuple[str, bool] | None:
        """(MQTT topic, retained) of an MCAP topic, or None when it is not published."""
        found = self._cache.get(topic, False)
        if found is not False:
            return found                # type: ignore[return-value]
        parts = topic.strip("/").split("/")
        route = None
        if len(parts) >= 2 and parts[0] == "cm" and parts[-1] in self.kinds:
            route = (f"{self.prefix}/{'/'.join(parts[1:])}", parts[-1] in RETAINED)
        self._cache[topic] = route
        return route

    @property
    def status(self) -> str:
        """The retained ``online`` / ``offline`` (last will) topic."""
        return f"{self.prefix}/status"

    def worst_alarm(self, channel: str) -> str:
        """The retained topic of a channel's worst alarm (Home Assistant discovery only)."""
        return f"{self.prefix}/{channel}/worst_alarm"

    @property
    def heartbeat(self) -> str:
        return f"{self.prefix}/heartbeat"


def payload(topic: str, stamp_ns: int, msg: dict, seq: int) -> bytes:
    """The MCAP JSON body of ``msg`` with ``"seq": seq`` added."""
    body = encode_message(topic, stamp_ns, msg)
    return body[:-1] + b',"seq":%d}' % seq if len(body) > 2 else b'{"seq":%d}' % seq
