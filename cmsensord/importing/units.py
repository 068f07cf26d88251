"""Input units to m/s² (the capture's physical unit)."""

from __future__ import annotations

from .errors import ImportFailure

__all__ = ["G", "UNITS", "to_ms2_factor"]

#: standard gravity, m/s^2 per g
G = 9.80665
#: m/s^2 per input unit; "V" needs a sensitivity in mV/g
UNITS: dict[str, float | None] = {"g": G, "mg": G * 1e-3, "m/s2": 1.0, "mm/s2": 1e-3, "V": None}


def to_ms2_factor(unit: str, sensitivity_mv_per_g: float | None = None,
                  scale_factor: float = 1.0) -> float:
    """m/s² per raw value: ``scale_factor`` x (m/s² per ``unit``).

    For ``V`` the sensor's sensitivity in mV/g is needed: 1 V = 1000 / sensitivity g.
    """
    if unit not in UNITS:
        raise ImportFailure(f"--unit {unit!r}: unknown unit; choose from {', '.join(UNITS)}")
    listed = UNITS[unit]
    if listed is None:                  # "V": m/s² per volt from the sensitivity
        if sensitivity_mv_per_g is None:
            raise ImportFailure("--unit V needs the sensor's sensitivity; add --sensitivity MV_PER_G "
                                "(e.g. 100 for a 100 mV/g accelerometer)")
        per_unit = 1000.0 / sensitivity_mv_per_g * G
    else:
        if sensitivity_mv_per_g is not None:
            raise ImportFailure(f"--sensitivity applies to --unit V only (got --unit {unit}); "
                                "drop --sensitivity or use --unit V")
        per_unit = listed
    return scale_factor * per_unit
