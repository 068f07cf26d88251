"""The checking of every configuration setting: per-field rules, types, cross-field rules.

Every setting is a dataclass field whose type annotation gives the accepted
type (``bool`` is not an ``int``; an ``int`` is accepted where a ``float`` is
expected) and whose ``metadata`` gives the declarative rules
(``gt``/``ge``/``lt``/``le``, ``choices``, ``pattern``, ...), declared with
:func:`setting`. Rules that relate two fields are listed per class in
``_RULES`` (:data:`Rule` callables such as :func:`greater`, :func:`at_most`).
:func:`validate` runs in each class's ``__post_init__``, so an object built in
code is validated exactly like one read from a file. Every failure raises
:class:`~cmsensord.errors.ConfigError` whose ``str()`` is one line naming the
file, the key path and the reason.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from dataclasses import field
from typing import Any

from cmsensord.errors import ConfigError

__all__ = ["ConfigError", "Rule", "setting", "validate", "greater", "at_most", "fmt_num", "did_you_mean"]

_CODE = "<code>"  # source name for objects built in code rather than read from a file

_RULE_KEYS = frozenset(
    {"gt", "ge", "lt", "le", "choices", "pattern", "pattern_reason", "nonzero", "nonempty"}
)


def setting(default: Any, help: str, **rules: Any) -> Any:
    """A dataclass field carrying its help text and validation rules."""
    bad = set(rules) - _RULE_KEYS
    if bad:  # a misspelt rule must not silently disable a check
        raise TypeError(f"unknown validation rule(s) {sorted(bad)}")
    return field(default=default, metadata={"help": help, **rules})


class _Invalid(Exception):
    """Internal: a value failed a check (reason, value)."""

    def __init__(self, reason: str, value: Any) -> None:
        super().__init__(reason)
        self.reason = reason
        self.value = value


def fmt_num(x: Any) -> str:
    """A bound or value as the messages show it (floats by repr, so 1.0 stays 1.0)."""
    return repr(x) if isinstance(x, float) else str(x)


def did_you_mean(word: str, known: Iterable[str]) -> str | None:
    """``did you mean 'x'?`` naming the entry x of ``known`` closest to ``word`` (difflib's
    similarity ratio 0.6 or more, the highest), or None when none is that close."""
    near = difflib.get_close_matches(word, list(known), n=1, cutoff=0.6)
    return f"did you mean {near[0]!r}?" if near else None


def _as_bool(value: Any) -> bool:
    if isinstance(value, bool):
        return value
    raise _Invalid("expected true or false", value)


def _as_int(value: Any) -> int:
    if isinstance(value, int) and not isinstance(value, bool):
        return int(value)
    raise _Invalid("expected an integer", value)


def _as_float(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _Invalid("expected a number", value)
    try:
        number = float(value)
    except OverflowError:
        raise _Invalid("number too large", value) from None
    if not math.isfinite(number):
        raise _Invalid("expected a finite number", value)
    return number


def _as_str(value: Any) -> str:
    if isinstance(value, str):
        return value
    raise _Invalid("expected a string", value)


#: the scalar annotations and their checks (int -> float for float)
_SCALARS: dict[Any, Callable[[Any], Any]] = {bool: _as_bool, int: _as_int, float: _as_float, str: _as_str}


def _coerce(tp: Any, value: Any) -> Any:
    """Check ``value`` against the annotation ``tp``; return it (int -> float)."""
    origin = typing.get_origin(tp)
    if origin is typing.Union or origin is types.UnionType:
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _coerce(inner, value)
    if origin is tuple:
        (item_tp, _ellipsis) = typing.get_args(tp)
        if not isinstance(value, (tuple, list)):
            raise _Invalid("expected a list", value)
        return tuple(_coerce(item_tp, v) for v in value)
    if tp in _SCALARS:
        return _SCALARS[tp](value)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        raise _Invalid(f"expected a {tp.__name__}", value)
    raise TypeError(f"config: unsupported annotation {tp!r}")  # programming error


def _check_rules(meta: Mapping[str, Any], value: Any) -> None:
    """Apply a field's declarative rules to its (already coerced) value."""
    if value is None:
        return
    if "choices" in meta and value not in meta["choices"]:
        reason = "must be one of " + ", ".join(str(c) for c in meta["choices"])
        hint = did_you_mean(str(value), (str(c) for c in meta["choices"]))
        if hint:
            reason += f" ({hint})"
        raise _Invalid(reason, value)
    if meta.get("nonempty") and len(value) == 0:
        raise _Invalid("must not be empty", value)
    if "pattern" in meta and not re.fullmatch(meta["pattern"], value):
        raise _Invalid(meta.get("pattern_reason") or f"must match {meta['pattern']}", value)
    if meta.get("nonzero") and value == 0:
        raise _Invalid("must not be 0", value)
    bounds = []
    ok = True
    for key, sym, test in (
        ("gt", ">", lambda v, b: v > b),
        ("ge", ">=", lambda v, b: v >= b),
        ("lt", "<", lambda v, b: v < b),
        ("le", "<=", lambda v, b: v <= b),
    ):
        if key in meta:
            bounds.append(f"{sym} {fmt_num(meta[key])}")
            ok = ok and test(value, meta[key])
    if not ok:
        raise _Invalid("must be " + " and ".join(bounds), value)


# Cross-field rules: callables obj -> None or (key path, reason, value).
Rule = Callable[[Any], "tuple[str, str, Any] | None"]


def greater(key: str, other: str) -> Rule:
    """Rule: field ``key`` must be greater than field ``other``."""

    def rule(obj: Any) -> tuple[str, str, Any] | None:
        a, b = getattr(obj, key), getattr(obj, other)
        if not a > b:
            return key, f"must be greater than {other} = {fmt_num(b)}", a
        return None

    return rule


def at_most(key: str, other: str) -> Rule:
    """Rule: field ``key`` must be <= field ``other``."""

    def rule(obj: Any) -> tuple[str, str, Any] | None:
        a, b = getattr(obj, key), getattr(obj, other)
        if not a <= b:
            return key, f"must be <= {other} = {fmt_num(b)}", a
        return None

    return rule


_HINTS: dict[type, dict[str, Any]] = {}


def validate(obj: Any) -> None:
    """Validate and normalise a config dataclass instance in place.

    Raises ConfigError(source="<code>", path=<field name>); loaders relocate it
    to the file and the full key path.
    """
    cls = type(obj)
    hints = _HINTS.get(cls)
    if hints is None:
        hints = _HINTS[cls] = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        value = getattr(obj, f.name)
        try:
            coerced = _coerce(hints[f.name], value)
        except _Invalid as bad:
            raise ConfigError(_CODE, f.name, bad.reason, bad.value) from None
        try:
            _check_rules(f.metadata, coerced)
        except _Invalid as bad:  # report the value as written (1, not 1.0)
            raise ConfigError(_CODE, f.name, bad.reason, value) from None
        if coerced is not value:
            object.__setattr__(obj, f.name, coerced)
    for rule in getattr(cls, "_RULES", ()):
        found = rule(obj)
        if found is not None:
            path, reason, value = found
            raise ConfigError(_CODE, path, reason, value)

