"""Message encoding of the MCAP sink: JSON bodies, and schemas and channels registered lazily.

Messages are JSON (``MESSAGE_ENCODING``) described by jsonschema schemas
(:mod:`cmsensord.sinks.schemas`):

* :func:`encode_message` turns a message dict into the bytes of a message
  record: compact JSON, with ``"timestamp": {"sec", "nsec"}`` put first
  unless the message has a ``timestamp`` field. numpy scalars and arrays
  become Python numbers and lists.
* JSON never carries NaN, infinity or ``null``: a field whose value is
  ``None`` or not finite is left out (a missing value is an absent field,
  :mod:`cmsensord.sinks.schemas`); in an array, where nothing can be left
  out, such a value is ``null``. The fast path encodes with
  ``allow_nan=False``; only a message that fails it, or whose JSON holds
  ``null``, is sanitised and encoded again, so clean messages cost one
  substring search extra.
* :class:`ChannelRegistry` registers a schema on the first message of its
  kind and a channel on the first message of its topic; a topic's kind is
  fixed by its first message.
"""

from __future__ import annotations

import json
import math
from typing import Any

from cmsensord.errors import SinkError
from cmsensord.sinks.schemas import (
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    SCHEMAS,
    schema_bytes,
    schema_name,
)

__all__ = ["NS", "ns_to_stamp", "encode_message", "ChannelRegistry"]

NS = 1_000_000_000  # nanoseconds per second


def ns_to_stamp(ns: int) -> dict[str, int]:
    """Nanoseconds -> ``{"sec": ns // 10**9, "nsec": ns % 10**9}``."""
    return {"sec": ns // NS, "nsec": ns % NS}


def _default(obj: Any) -> Any:
    """json ``default=`` hook: numpy scalars and arrays -> Python objects."""
    tolist = getattr(obj, "tolist", None)  # np.ndarray and np.generic both have it
    if tolist is not None:
        return tolist()
    raise TypeError(f"object of type {type(obj).__name__} is not JSON serializable")


# One encoder, built once: json.dumps(**kwargs) would build a new one per call.
# check_circular=False: no id() bookkeeping per container (~20 % faster); a
# circular message then fails with RecursionError, handled like any bad message.
_encode = json.JSONEncoder(
    allow_nan=False, separators=(",", ":"), default=_default, check_circular=False
).encode


def _sanitize(obj: Any) -> Any:
    """A copy of ``obj`` with every non-finite float replaced by None, and every dict key
    whose value is then None left out.

    The slow path: only called for a message the strict encoder rejected or whose
    JSON holds ``null``.
    """
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            v = _sanitize(v)
            if v is not None:
                out[k] = v
        return out
    if isinstance(obj, (list, tuple)):
        return [_sanitize(v) for v in obj]
    if isinstance(obj, (str, int)) or obj is None:
        return obj
    tolist = getattr(obj, "tolist", None)
    if tolist is not None:
        return _sanitize(tolist())
    return obj


def _encode_sanitized(topic: str, msg: dict) -> str:
    try:
        return _encode(_sanitize(msg))
    except (ValueError, TypeError, RecursionError) as err:
        raise SinkError(f"{topic}: message cannot be encoded as JSON: {err}") from None


def encode_message(topic: str, stamp_ns: int, msg: dict) -> bytes:
    """The JSON body (UTF-8) of one message on ``topic`` stamped ``stamp_ns`` (ns, >= 0).

    ``{"timestamp": {"sec", "nsec"}, ...msg}`` unless ``msg`` has a
    ``timestamp``; ``msg`` itself is not modified. Raises SinkError (naming
    the topic) for a message JSON cannot represent even after sanitising.
    """
    try:
        body = _encode(msg)
    except (ValueError, TypeError, RecursionError):  # NaN/inf (allow_nan=False), bad type
        body = _encode_sanitized(topic, msg)
    else:
        if "null" in body:                           # a None (or the word in a string)
            body = _encode_sanitized(topic, msg)
    if "timestamp" not in msg:
        sec, nsec = divmod(stamp_ns, NS)
        if len(body) > 2:
            body = f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},{body[1:]}'
        else:
            body = f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}}}}'
    return body.encode()


class ChannelRegistry:
    """The schemas and channels of one file, each registered with ``writer`` on first use.

    ``writer`` has ``register_schema(name, encoding, data) -> id`` and
    ``register_channel(topic, message_encoding, schema_id) -> id`` (a
    :class:`~cmsensord.sinks.mcap_chunks.ChunkWriter`). :attr:`channels` maps
    topic -> (channel id, kind) for every registered topic.
    """

    def __init__(self, writer: Any) -> None:
        self._writer = writer
        self.channels: dict[str, tuple[int, str]] = {}  # topic -> (channel id, kind)
        self._schemas: dict[str, int] = {}  # kind -> schema id

    def register(self, topic: str, kind: str) -> tuple[int, str]:
        """Register ``topic`` with schema ``kind`` (and the schema, on its first use).

        Returns (channel id, kind). Raises SinkError when ``topic`` is
        registered already (its kind is fixed) or ``kind`` is not a schema key.
        """
        if topic in self.channels:
            raise SinkError(
                f"{topic}: written with schema {kind!r}, but the topic has schema "
                f"{self.channels[topic][1]!r}"
            )
        if kind not in SCHEMAS:
            raise SinkError(f"{topic}: unknown schema {kind!r} (one of {', '.join(SCHEMAS)})")
        schema_id = self._schemas.get(kind)
        if schema_id is None:
            schema_id = self._writer.register_schema(
                name=schema_name(kind), encoding=SCHEMA_ENCODING, data=schema_bytes(kind)
            )
            self._schemas[kind] = schema_id
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding=MESSAGE_ENCODING, schema_id=schema_id
        )
        entry = self.channels[topic] = (channel_id, kind)
        return entry
