"""The acoustic calibration file: what the daemon reads for a microphone channel.

A calibration is the :class:`~cmsensord.dsp.acoustic.model.AcousticModel` of the
Orimoto, Ikuta & Wang estimator fitted for one microphone (by
:mod:`cmsensord.acoustic_calib`) and what the fit saw.  It is stored as JSON::

    {"format": "cmsensord.acoustic_calibration", "version": 1,
     "model": {<the AcousticModel's fields; lam1, lam2 as 3x3 lists>},
     "info": {<diagnostics and warnings of the fit>}}

:func:`load_calibration` reads and checks a file and raises
:class:`~cmsensord.errors.ConfigError` with a one-line message naming the file and the
key (docs/acoustic.md §9); :func:`save_calibration` writes one.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from cmsensord.dsp.acoustic import AcousticModel
from cmsensord.errors import ConfigError

__all__ = ["FORMAT", "VERSION", "AcousticModel", "Calibration", "save_calibration", "load_calibration"]

FORMAT = "cmsensord.acoustic_calibration"
VERSION = 1

_MODEL_KEYS = tuple(f.name for f in fields(AcousticModel))


@dataclass
class Calibration:
    """A fitted model and what the fit saw (diagnostics, warnings)."""

    model: AcousticModel
    info: dict[str, Any] = field(default_factory=dict)


def save_calibration(cal: Calibration, path) -> None:
    """Write the calibration as JSON (``format``, ``version``, ``model``, ``info``)."""
    model = asdict(cal.model)
    model["lam1"] = [list(r) for r in model["lam1"]]
    model["lam2"] = [list(r) for r in model["lam2"]]
    doc = {"format": FORMAT, "version": VERSION, "model": model, "info": cal.info}
    Path(path).write_text(json.dumps(doc, indent=2, default=float) + "\n", encoding="utf-8")


def load_calibration(path) -> AcousticModel:
    """Read a calibration file; a bad file raises ConfigError naming the file and the key."""
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(source, None, "calibration file not found") from None
    except IsADirectoryError:
        raise ConfigError(source, None, "is a directory, not a calibration file") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:     # ValueError: a NUL in the path
        reason = getattr(exc, "strerror", None) or exc
        raise ConfigError(source, None, f"cannot read the calibration file: {reason}") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(source, None, f"not JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ConfigError(source, "format", f"not an acoustic calibration (expected format {FORMAT!r})",
                          doc.get("format") if isinstance(doc, dict) else doc)
    if doc.get("version") != VERSION:
        raise ConfigError(source, "version", f"unsupported version (this daemon reads {VERSION})",
                          doc.get("version"))
    return _model(source, doc.get("model"))


def _model(source: str, model: Any) -> AcousticModel:
    """The ``model`` mapping of a calibration file as an AcousticModel, or ConfigError naming the key."""
    if not isinstance(model, dict):
        raise ConfigError(source, "model", "expected a mapping of the model's coefficients", model)
    unknown = [k for k in model if k not in _MODEL_KEYS]
    if unknown:
        raise ConfigError(source, f"model.{unknown[0]}", "unknown key")
    required = [k for k in _MODEL_KEYS if k != "block_s"]
    missing = [k for k in required if k not in model]
    if missing:
        raise ConfigError(source, f"model.{missing[0]}", "missing")
    try:
        return AcousticModel(**model)
    except (ValueError, TypeError) as exc:
        key, _, reason = str(exc).partition(": ")
        if key in _MODEL_KEYS:
            raise ConfigError(source, f"model.{key}", reason) from None
        raise ConfigError(source, "model", str(exc)) from None
