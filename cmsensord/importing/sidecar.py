"""An imported capture's sidecar (``CAPTURE.json``, written by ``cmsensord import``), read back:
what replay, calibrate, vkf and the acoustic calibration take from it (the channels' names and
units, the snapshots, the speed)."""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["channel_units", "sidecar"]


def sidecar(path: str | Path) -> dict:
    """The capture's metadata written by ``cmsensord import`` (CAPTURE.json beside it), or {}."""
    p = Path(str(path) + ".json")
    try:
        return json.loads(p.read_text()) if p.is_file() else {}
    except (OSError, ValueError):
        return {}


def channel_units(meta: dict) -> list[str]:
    """Each channel's unit in the capture (m/s2, a microphone's Pa), as its sidecar ``meta``
    says it; [] when it says none (not an import)."""
    units = meta.get("unit")
    n = len(meta.get("channel_names") or [])
    return [str(u) for u in units] if isinstance(units, list) else [str(units)] * n if units else []
