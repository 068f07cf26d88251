"""The building blocks of the JSON schemas of the MCAP output (:mod:`.schemas`): the time,
numbers, strings, the channel name and an object of the JSON-schema subset Foxglove reads."""

from __future__ import annotations

from typing import Any

_DIALECT = "https://json-schema.org/draft/2020-12/schema"

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
