"""The frequencies marked on a capture's spectra: the shaft's 1x and each bearing's defect lines.

:class:`CaptureMarks` gives, for a capture of a channel over board samples [a, b), the
shaft speed then (the mean of the tacho's causal speed at those of 16 points of the
window its edges already cover — the newest covered speed when none is —, as the
indicator records read it; without a tacho ``indicators.rpm``; none: no marks) and
the lines at that speed: ``1x`` (kind ``shaft``) and, for every bearing whose
``channel`` is this one, its FTF, BPFO, BPFI and BSF (Randall & Antoni 2011; see
:mod:`cmsensord.dsp.indicators.bearings`), labelled ``<bearing> BPFO`` and so on.
Lines at or above the Nyquist frequency are left out.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cmsensord.config import Config
from cmsensord.dsp.indicators.bearings import DEFECTS, Geometry, defect_frequencies

__all__ = ["CaptureMarks", "SPEED_POINTS"]

#: points of the capture window at which the tacho speed is read
SPEED_POINTS = 16


class CaptureMarks:
    """Shaft speed and defect lines of a capture window (see the module docstring).
    ``tacho``: the shaft's tacho tracker now (None: no tacho)."""

    def __init__(self, cfg: Config, tacho: Callable[[], Any]):
        self.rpm = cfg.indicators.rpm
        self.tacho = tacho
        self.bearings = [(b.channel, b.name, Geometry(b.elements, b.ball_diameter, b.pitch_diameter,
                                                      b.contact_angle_deg)) for b in cfg.bearings]

    def speed(self, a: int, b: int) -> tuple[float | None, str | None]:
        """(shaft speed [Hz], "tacho" or "config") over board samples [a, b); (None, None): unknown."""
        tacho = self.tacho()
        if tacho is not None:
            at = a + (np.arange(SPEED_POINTS) + 0.5) * (b - a) / SPEED_POINTS
            covered = float(tacho.covered_until)
            at = at[at < covered] if (at < covered).any() else np.array([covered - 1.0])
            hz, ok = tacho.evaluate_causal(at)
            if ok.any():
                return float(np.mean(hz[ok])), "tacho"
        return (self.rpm / 60.0, "config") if self.rpm else (None, None)

    def waits(self, b: int) -> bool:
        """Whether the tacho's edges do not yet cover the board samples up to ``b``."""
        tacho = self.tacho()
        return tacho is not None and tacho.covered_until < b

    def fields(self, channel: str, a: int, b: int, nyquist_hz: float) -> dict[str, Any]:
        """The capture spectrum's fields: ``shaft_speed_rpm``, ``speed_source`` and ``marks``
        (absent when the speed is unknown)."""
        f_r, source = self.speed(a, b)
        if f_r is None or not f_r > 0:
            return {}
        marks: list[dict[str, Any]] = [{"label": "1x", "kind": "shaft", "freq_hz": round(f_r, 6)}]
        for ch, name, g in self.bearings:
            if ch != channel:
                continue
            for kind, hz in zip(DEFECTS, defect_frequencies(g, f_r)):
                marks.append({"label": f"{name} {kind.upper()}", "kind": kind, "bearing": name,
                              "freq_hz": round(hz, 6)})
        return {"shaft_speed_rpm": round(60.0 * f_r, 6), "speed_source": source,
                "marks": [m for m in marks if m["freq_hz"] < nyquist_hz]}
