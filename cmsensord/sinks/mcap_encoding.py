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
* A field whose value repeats from message to message (:data:`REPEATED`: a severity
  message's ``r``, the bank's noise variances, ten floats whose text is most of the
  message's encoding time) may be encoded once and its JSON reused
  (:func:`encode_message`'s ``repeat``): the bytes are those of the plain encoding.
* :class:`ChannelRegistry` registers a schema on the first message of its
  kind and a channel on the first message of its topic; a topic's kind is
  fixed by its first message.
"""

from __future__ import annotations

import json
import math
from json.encoder import c_make_encoder, encode_basestring_ascii  # type: ignore[attr-defined]
from typing import Any

from cmsensord.errors import SinkError
from cmsensord.sinks.encoded import EncodedMessage
from cmsensord.sinks.schemas import (
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    SCHEMAS,
    schema_bytes,
    schema_name,
)

__all__ = ["NS", "REPEATED", "ns_to_stamp", "encode_message", "ChannelRegistry"]

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
_encoder = json.JSONEncoder(
    allow_nan=False, separators=(",", ":"), default=_default, check_circular=False
)


def _c_encode(obj: Any) -> str:
    """What ``_encoder.encode`` gives, by the C encoder it builds on every call built once
    (``JSONEncoder.iterencode`` with ``_one_shot``: no markers, ASCII strings, no indent):
    ~2-3 µs a message less. The C encoder returns the text in pieces (one for a short
    message, several for a long one, e.g. a capture's waveform): joined as ``encode`` does."""
    return "".join(_c_encoder(obj, 0))


try:    # the C encoder's arguments as json.encoder passes them (CPython 3.8-3.13)
    _c_encoder = c_make_encoder(None, _default, encode_basestring_ascii, None, ":", ",",
                                False, False, False)
    _encode = _c_encode if _c_encode({"a": [1.5, None]}) == _encoder.encode({"a": [1.5, None]}) \
        else _encoder.encode
except TypeError:       # no C encoder (None), or another signature
    _encode = _encoder.encode

#: schema -> the field whose value is the same list from message to message: its JSON is
#: cached (:func:`encode_message`'s ``repeat``)
REPEATED = {"severity": "r"}
#: a placeholder for the repeated field: its JSON text, quotes included, cannot occur in an
#: encoding but as a string value made of exactly these characters (then the field is not cached)
_MARK = "\x00repeated\x00"
_MARK_JSON = json.dumps(_MARK)
#: most repeated values whose JSON is kept
_REPEAT_CACHE = 256
_repeat_json: dict[tuple, str] = {}


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


def _with_repeat(msg: dict, field: str) -> str | None:
    """The compact JSON of ``msg`` with its list ``field`` encoded from the cache of
    :data:`REPEATED` values; None when that does not apply (no such list, an item that is not
    a float with a fraction part); ValueError for a non-finite number: the plain path then
    encodes it.

    Only lists of non-integral floats are cached: a list equal to one of them (the cache's
    key) then has the same JSON text (not so 1 and 1.0, or 0.0 and -0.0)."""
    value = msg.get(field)
    if type(value) is not list:
        return None
    key = tuple(value)
    frag = _repeat_json.get(key)
    if frag is None:
        if not all(type(v) is float and not v.is_integer() for v in key):
            return None
        frag = _encode(value)           # ValueError for NaN or infinity
        if len(_repeat_json) >= _REPEAT_CACHE:
            _repeat_json.clear()
        _repeat_json[key] = frag
    body = _encode({**msg, field: _MARK})
    if body.count(_MARK_JSON) != 1:
        return None
    return body.replace(_MARK_JSON, frag, 1)


def encode_message(topic: str, stamp_ns: int, msg: dict, repeat: str | None = None) -> bytes:
    """The JSON body (UTF-8) of one message on ``topic`` stamped ``stamp_ns`` (ns, >= 0).

    ``{"timestamp": {"sec", "nsec"}, ...msg}`` unless ``msg`` has a
    ``timestamp``; ``msg`` itself is not modified. Raises SinkError (naming
    the topic) for a message JSON cannot represent even after sanitising.
    ``repeat``: a field whose value (a list of numbers) repeats from message to message
    (:data:`REPEATED`): its JSON is taken from a cache; the bytes are the same.  An
    :class:`~cmsensord.sinks.encoded.EncodedMessage` with its text: the text is the body.
    """
    try:
        body = msg.text if type(msg) is EncodedMessage else None     # its text, made with it
        if body is None and repeat is not None:
            body = _with_repeat(msg, repeat)
        if body is None:
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
