"""A JSON-schema checker restricted to what Foxglove's JSON-schema reader supports.

Foxglove (and Lichtblick, its open-source fork) turn a ``jsonschema`` schema into
message definitions with ``parseJsonSchema`` (``packages/mcap-support``), which accepts:

* an object: ``"type": "object"`` with a ``properties`` map (it iterates over it);
* per property either a ``oneOf`` whose alternatives all have a numeric ``const``
  (an enum, as ``foxglove.Log``'s level), or one ``type`` out of ``boolean``,
  ``string`` (no ``contentEncoding`` but ``base64``), ``number``, ``integer``,
  ``object`` (recursively) and ``array`` whose ``items`` have one ``type`` out of
  boolean, string, number, integer and object; anything else (``null``, a list of
  types, an array of arrays, a property without a type) is "Unsupported type" and
  the whole topic fails to load.

:func:`schema_problems` says what such a reader would refuse; :func:`message_problems`
checks a message against the schema in that subset (types, ``required``, ``enum``,
``minimum``/``maximum``, the ``oneOf`` constants) and also reports every field the
schema does not declare (Foxglove would not offer it in a message path) and every
``null``.
"""

from __future__ import annotations

from typing import Any

SCALARS = ("boolean", "string", "number", "integer")


def schema_problems(schema: dict, path: str = "") -> list[str]:
    """What Foxglove's parseJsonSchema would refuse in the object schema ``schema``."""
    where = path or "<root>"
    if schema.get("type") != "object":
        return [f"{where}: expected \"type\": \"object\", got {schema.get('type')!r}"]
    props = schema.get("properties")
    if not isinstance(props, dict):
        return [f"{where}: an object without \"properties\""]
    out: list[str] = []
    for name, field in props.items():
        out += _field_problems(field, f"{path}.{name}" if path else name)
    return out


def _field_problems(field: dict, path: str) -> list[str]:
    if isinstance(field.get("oneOf"), list):
        if all(isinstance(alt.get("const"), (int, float)) and not isinstance(alt.get("const"), bool)
               for alt in field["oneOf"]):
            return []
        return [f"{path}: oneOf alternatives must have number values"]
    t = field.get("type")
    if t in ("boolean", "number", "integer"):
        return []
    if t == "string":
        enc = field.get("contentEncoding")
        return [] if enc in (None, "base64") else [f"{path}: unsupported contentEncoding {enc!r}"]
    if t == "object":
        return schema_problems(field, path)
    if t == "array":
        items = field.get("items")
        if not isinstance(items, dict):
            return [f"{path}: an array without items"]
        it = items.get("type")
        if it == "object":
            return schema_problems(items, path + "[]")
        if it == "string" and items.get("contentEncoding") is not None:
            return [f"{path}[]: unsupported contentEncoding for array item"]
        return [] if it in SCALARS else [f"{path}[]: unsupported type {it!r} for array item"]
    return [f"{path}: unsupported type {t!r}"]


def message_problems(msg: Any, schema: dict, path: str = "") -> list[str]:
    """Where ``msg`` does not fit ``schema`` (assumed to pass :func:`schema_problems`)."""
    where = path or "<root>"
    if not isinstance(msg, dict):
        return [f"{where}: expected an object, got {type(msg).__name__}"]
    props = schema["properties"]
    out = [f"{where}: required field {r!r} absent" for r in schema.get("required", []) if r not in msg]
    for name, value in msg.items():
        sub = f"{path}.{name}" if path else name
        if name not in props:
            out.append(f"{sub}: not declared in the schema")
        else:
            out += _value_problems(value, props[name], sub)
    return out


def _value_problems(value: Any, field: dict, path: str) -> list[str]:
    if value is None:
        return [f"{path}: null (a missing value must be an absent field)"]
    if "oneOf" in field:
        allowed = [alt["const"] for alt in field["oneOf"]]
        return [] if value in allowed and not isinstance(value, bool) else [f"{path}: {value!r} not in {allowed}"]
    t = field["type"]
    if t == "object":
        return message_problems(value, field, path)
    if t == "array":
        if not isinstance(value, list):
            return [f"{path}: expected an array"]
        out: list[str] = []
        for i, item in enumerate(value):
            out += _value_problems(item, field["items"], f"{path}[{i}]")
        return out
    ok = {"boolean": lambda v: isinstance(v, bool),
          "string": lambda v: isinstance(v, str),
          "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
          "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool)}[t](value)
    if not ok:
        return [f"{path}: {value!r} is not a {t}"]
    out = []
    if "enum" in field and value not in field["enum"]:
        out.append(f"{path}: {value!r} not in the enum")
    if "minimum" in field and value < field["minimum"]:
        out.append(f"{path}: {value!r} < minimum {field['minimum']}")
    if "maximum" in field and value > field["maximum"]:
        out.append(f"{path}: {value!r} > maximum {field['maximum']}")
    return out
