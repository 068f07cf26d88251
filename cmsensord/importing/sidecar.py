"""An imported capture's sidecar (``CAPTURE.json``, written by ``cmsensord import``), read back:
what replay, calibrate, vkf and the acoustic calibration take from it (the channels' names and
units, the snapshots, the speed). Its fields are checked where it is read (:mod:`.sidecar_fields`):
one that is not usable is left out with a one-line warning, and the run goes on."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from .sidecar_fields import capture_status, checked

__all__ = ["MAX_SIDECAR_BYTES", "MAX_SIDECAR_DEPTH", "channel_units", "sidecar"]


#: the largest sidecar read: an import's holds ~320 bytes a snapshot (IMS's 6,324 snapshots of 4
#: channels: 2 MB), so 64 MiB is some 200,000 snapshots, 30 times IMS's, read in ~150 MB
MAX_SIDECAR_BYTES = 64 << 20
#: the deepest nesting of arrays and objects read: an import's sidecar nests 3 deep (its object,
#: the snapshots' array, a snapshot's object); a bound of its own, not the parser's, which hangs
#: on the depth of the stack it is called at, so that a value just within the parser's depth
#: could still overflow the stack where it is quoted in a warning
MAX_SIDECAR_DEPTH = 32

_said: set[tuple[str, str]] = set()


def sidecar(path: str | Path) -> dict:
    """The capture's metadata written by ``cmsensord import`` (CAPTURE.json beside it), or {}
    when there is none, or when it cannot be read (truncated, not JSON, not an object, nested
    deeper than ``MAX_SIDECAR_DEPTH``, larger than ``MAX_SIDECAR_BYTES``: refused before it is read):
    then a one-line warning on stderr, once a process for that file. A field it cannot use is
    left out, and an ``fs`` its STATUS frames contradict is theirs, with a one-line warning each
    (:func:`~.sidecar_fields.checked`)."""
    p = Path(str(path) + ".json")
    if not p.is_file():
        return {}
    try:
        meta = json.loads(_text(p), parse_int=_whole)
        why = ("not a JSON object" if not isinstance(meta, dict)
               else "nested too deeply" if _depth(meta) > MAX_SIDECAR_DEPTH else "")
    except (OSError, ValueError) as exc:
        why = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    except RecursionError:
        why = "nested too deeply"
    if why:
        _warn(p, f"the capture's sidecar cannot be read ({why}): its channel names, units, speed and time line "
                 "are not used")
        return {}
    meta, lines = checked(meta, capture_status(path))
    for line in lines:
        _warn(p, f"the capture's sidecar's {line}")
    return meta


def _text(p: Path) -> str:
    """The sidecar's text; ValueError (the reason) when it is larger than ``MAX_SIDECAR_BYTES``,
    said from its size before a byte is read."""
    with open(p, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if size > MAX_SIDECAR_BYTES:
            raise ValueError(f"{size:,} bytes, over the {MAX_SIDECAR_BYTES:,} read of a sidecar: not an import's")
        return f.read(MAX_SIDECAR_BYTES + 1).decode("utf-8")


def _depth(value: object) -> int:
    """How deep ``value``'s arrays and objects nest (1: an object of scalars), without recursion."""
    deepest, todo = 0, [(value, 1)]
    while todo:
        v, d = todo.pop()
        items = v.values() if isinstance(v, dict) else v if isinstance(v, list) else None
        if items is None:
            continue
        deepest = max(deepest, d)
        if d <= MAX_SIDECAR_DEPTH:          # deeper is too deep however deep
            todo.extend((x, d + 1) for x in items)
    return deepest


def _whole(digits: str) -> int | float:
    """A JSON whole number: an int, or past the digits Python converts to one, a float (then
    +-inf: no number a sidecar field can use)."""
    try:
        return int(digits)
    except ValueError:
        return float(digits)


def _warn(p: Path, line: str) -> None:
    """``warning: SIDECAR: LINE`` on stderr, once a process."""
    if (str(p), line) not in _said:
        _said.add((str(p), line))
        print(f"warning: {p}: {line}", file=sys.stderr)


def channel_units(meta: dict) -> list[str]:
    """Each channel's unit in the capture (m/s2, a microphone's Pa), as its sidecar ``meta``
    says it; [] when it says none (not an import)."""
    units = meta.get("unit")
    n = len(meta.get("channel_names") or [])
    return [str(u) for u in units] if isinstance(units, list) else [str(units)] * n if units else []
