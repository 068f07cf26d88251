"""An imported capture's sidecar (``CAPTURE.json``, written by ``cmsensord import``), read back:
what replay, calibrate, vkf and the acoustic calibration take from it (the channels' names and
units, the snapshots, the speed). Its fields are checked where it is read (:mod:`.sidecar_fields`):
one that is not usable is left out with a one-line warning, and the run goes on."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .sidecar_fields import checked, status_fs

__all__ = ["channel_units", "sidecar"]


_said: set[tuple[str, str]] = set()


def sidecar(path: str | Path) -> dict:
    """The capture's metadata written by ``cmsensord import`` (CAPTURE.json beside it), or {}
    when there is none, or when it cannot be read (truncated, not JSON, not an object): then a
    one-line warning on stderr, once a process for that file. A field it cannot use is left
    out, and an ``fs`` its STATUS frames contradict is theirs, with a one-line warning each
    (:func:`~.sidecar_fields.checked`)."""
    p = Path(str(path) + ".json")
    if not p.is_file():
        return {}
    try:
        meta = json.loads(p.read_text(encoding="utf-8"))
        why = "" if isinstance(meta, dict) else "not a JSON object"
    except (OSError, ValueError) as exc:
        why = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    if why:
        _warn(p, f"the capture's sidecar cannot be read ({why}): its channel names, units, speed and time line "
                 "are not used")
        return {}
    meta, lines = checked(meta, status_fs(path))
    for line in lines:
        _warn(p, f"the capture's sidecar's {line}")
    return meta


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
