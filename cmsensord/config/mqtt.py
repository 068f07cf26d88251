"""The optional ``mqtt`` section: the broker, its credentials, the topics published and the
disk-backed store-and-forward queue (:mod:`cmsensord.publish`)."""

from __future__ import annotations

import dataclasses
import errno
import os
import socket
from dataclasses import dataclass
from typing import Any, ClassVar

from .validation import Rule, at_most, setting, validate

__all__ = ["CREDENTIALS", "MqttConfig", "PUBLISHABLE", "RETAINED", "unreadable"]

#: what can be published: the last part of an MCAP topic (/cm/<channel>/<kind> or /cm/<kind>)
PUBLISHABLE = ("severity", "indicators", "alarms", "events", "diagnostics", "orders",
               "vibration_estimate")
#: kinds published retained: a dashboard that subscribes later shows their last value at once
RETAINED = frozenset({"severity", "indicators", "alarms"})

_A_PATH: dict[str, Any] = {"pattern": r"[^\x00]*", "pattern_reason": "must not contain a NUL byte"}
#: MQTT topic levels: no wildcards, no NUL, no leading or trailing /
_TOPIC = {"pattern": r"[^#+\x00/]+(/[^#+\x00/]+)*",
          "pattern_reason": "must be MQTT topic levels separated by / (no #, + or empty level)"}


def _publish_known(obj: Any) -> tuple[str, str, Any] | None:
    for item in obj.publish:
        if item not in PUBLISHABLE:
            return "publish", f"unknown kind {item!r}; choose from {', '.join(PUBLISHABLE)}", item
    return None


#: where systemd puts the shipped unit's credentials (LoadCredential=, systemd/cmsensord-mqtt.conf)
CREDENTIALS = "/run/credentials/cmsensord.service"


def unreadable(key: str, path: str, err: OSError) -> str:
    """Why the file of setting ``key`` cannot be used, one line: ``cannot read: <strerror>``.
    Under systemd (``INVOCATION_ID`` set) it adds how to pass the file: one the service's
    transient user may not read (EACCES) through ``LoadCredential=`` and its path under
    :data:`CREDENTIALS`; a missing one under ``/run/credentials/`` through the unit's
    ``LoadCredential=``."""
    reason = f"cannot read: {err.strerror or err}"
    if "INVOCATION_ID" not in os.environ:
        return reason
    name = os.path.basename(path)
    if err.errno == errno.EACCES:
        return (f"{reason}; the service's user cannot read it: give it to the service with "
                f"LoadCredential={name}:{path} (systemd/cmsensord-mqtt.conf) and set mqtt.{key}: "
                f"{CREDENTIALS}/{name}")
    if err.errno == errno.ENOENT and path.startswith("/run/credentials/"):
        return (f"{reason}; the unit loads no credential {name}: add LoadCredential={name}:<the file> "
                "to its drop-in (systemd/cmsensord-mqtt.conf)")
    return reason


#: schemes of a broker URL that mean TLS
_TLS_SCHEMES = ("mqtts", "ssl", "tls", "wss")


def _host_alone(obj: Any) -> tuple[str, str, Any] | None:
    """A host written as a URL or ``host:port`` (``mqtt://broker:1883``, ``broker:1883``,
    ``broker/x``): the name alone, and where its port and scheme go instead. A bare IPv6
    address (``::1``, more than one colon) is a host."""
    host = obj.host
    scheme, sep, rest = host.partition("://")
    if not sep:
        scheme, rest = "", host
        if "/" not in host and "[" not in host and host.count(":") != 1:
            return None
    netloc = rest.partition("/")[0].rpartition("@")[2]
    if netloc.startswith("["):
        name, _, tail = netloc[1:].partition("]")
        port = tail[1:] if tail.startswith(":") else ""
    elif netloc.count(":") == 1:
        name, _, port = netloc.partition(":")
    else:
        name, port = netloc, ""
    advice = f"give the host name alone ({name})" if name else "give the host name alone"
    if port:
        advice += f", the port as mqtt.port: {port}"
    if scheme.lower() in _TLS_SCHEMES and obj.ca_file is None:
        advice += (f"; {scheme}:// means TLS: set mqtt.ca_file to the broker's CA certificate"
                   + ("" if port else " and mqtt.port (8883 is the usual TLS port)"))
    return "host", advice, host


def _key_needs_cert(obj: Any) -> tuple[str, str, Any] | None:
    if (obj.keyfile is None) != (obj.certfile is None):
        return "keyfile", "a client certificate needs both certfile and keyfile", obj.keyfile
    if obj.password_file is not None and obj.username is None:
        return "password_file", "a password needs a username", obj.password_file
    return None


@dataclass(frozen=True)
class MqttConfig:
    """Publishing to an MQTT broker (absent: nothing is published and paho is not imported)."""

    host: str = setting(dataclasses.MISSING, "broker host name or address", nonempty=True,
                        pattern=r"[^\x00\s]+", pattern_reason="must be a host name without spaces")
    port: int = setting(1883, "broker port (8883 is the usual TLS port)", ge=1, le=65535)
    client_id: str | None = setting(None, "MQTT client id (default: the host name)", nonempty=True,
                                    pattern=r"[^#+/\x00\s]+",
                                    pattern_reason="must not contain /, #, +, spaces or NUL")
    topic_prefix: str | None = setting(None, "topic prefix (default: cmsensord/<client_id>)",
                                       nonempty=True, **_TOPIC)
    qos: int = setting(1, "MQTT QoS of the messages: 1 (acknowledged, store-and-forward) or 0",
                       choices=(0, 1))
    username: str | None = setting(None, "user name for the broker", nonempty=True)
    password_file: str | None = setting(None, "file holding the password (never the password "
                                        "itself in the YAML)", nonempty=True, **_A_PATH)
    ca_file: str | None = setting(None, "CA certificate (PEM): TLS to the broker", nonempty=True,
                                  **_A_PATH)
    certfile: str | None = setting(None, "client certificate (PEM), with keyfile", nonempty=True,
                                   **_A_PATH)
    keyfile: str | None = setting(None, "client key (PEM), with certfile", nonempty=True, **_A_PATH)
    publish: tuple[str, ...] = setting(("severity", "indicators", "alarms", "events"),
                                       "what to publish: kinds of MCAP topics")
    heartbeat_s: float = setting(30.0, "seconds between <prefix>/heartbeat messages", gt=0)
    keepalive_s: int = setting(30, "MQTT keep-alive [s]", ge=5, le=65535)
    queue_dir: str | None = setting(None, "directory of the store-and-forward queue "
                                    "(default: <output.dir>/mqtt-queue)", nonempty=True, **_A_PATH)
    queue_mb: float = setting(64.0, "bound of the on-disk queue; the oldest messages are dropped "
                              "beyond it", gt=0)
    fsync_s: float = setting(1.0, "seconds between fsyncs of the queue and writes of its acknowledged "
                             "position (a kill -9 loses at most this much, and its restart repeats "
                             "what the broker acknowledged in this much + 0.2 s, and the 20 in "
                             "flight)", gt=0, le=60)
    resend_per_s: float = setting(200.0, "rate limit of the backlog sent after a reconnection "
                                  "[messages/s]", gt=0)
    reconnect_min_s: float = setting(1.0, "first reconnect back-off", gt=0)
    reconnect_max_s: float = setting(60.0, "longest reconnect back-off", gt=0)
    handover_messages: int = setting(10000, "bounded in-memory queue from the processing loop "
                                     "to the publisher thread", ge=16)
    discovery: bool = setting(False, "publish Home Assistant MQTT discovery messages")
    discovery_prefix: str = setting("homeassistant", "Home Assistant discovery prefix", **_TOPIC)

    _RULES: ClassVar[tuple[Rule, ...]] = (_host_alone, _publish_known, _key_needs_cert,
                                          at_most("reconnect_min_s", "reconnect_max_s"))

    def __post_init__(self) -> None:
        validate(self)

    @property
    def client(self) -> str:
        """The client id: ``client_id`` or the host name."""
        return self.client_id or socket.gethostname() or "cmsensord"

    @property
    def prefix(self) -> str:
        """The topic prefix: ``topic_prefix`` or ``cmsensord/<client id>``."""
        return self.topic_prefix or f"cmsensord/{self.client}"

    def queue_path(self, output_dir: str) -> str:
        """The queue's directory: ``queue_dir`` or ``<output_dir>/mqtt-queue``."""
        return self.queue_dir or os.path.join(output_dir, "mqtt-queue")
