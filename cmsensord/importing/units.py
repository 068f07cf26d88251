"""Input units to m/s² (the capture's physical unit), and the unit a file says its columns are in."""

from __future__ import annotations

import re

from .errors import ImportFailure

__all__ = ["G", "UNITS", "resolve_unit", "to_ms2_factor", "unit_in_name", "unit_of"]

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


#: how files write the units of UNITS (lower case, spaces and brackets dropped)
_SPELLINGS = {"g": "g", "g0": "g", "gn": "g", "mg": "mg", "m/s2": "m/s2", "m/s^2": "m/s2", "m/s²": "m/s2",
              "m/s**2": "m/s2", "ms^-2": "m/s2", "ms-2": "m/s2", "m/sec^2": "m/s2", "m/sec2": "m/s2",
              "mm/s2": "mm/s2", "mm/s^2": "mm/s2", "mm/s²": "mm/s2", "v": "V"}
#: a unit at the end of a column's name: ``Acc X (g)``, ``a [m/s^2]``
_IN_NAME = re.compile(r"[\[(]\s*([^\[\]()]+?)\s*[\])]\s*$")


def unit_of(text: str | None) -> str | None:
    """The :data:`UNITS` key a file's unit string means (``m/s^2`` -> ``m/s2``, ``G`` -> ``g``), or None."""
    if not text:
        return None
    key = re.sub(r"[\s\[\]()]", "", text).lower()
    return _SPELLINGS.get(key)


def unit_in_name(name: str) -> str | None:
    """The unit a column's name ends with (``Acc X (g)`` -> ``g``), or None."""
    m = _IN_NAME.search(name)
    return unit_of(m.group(1)) if m else None


def resolve_unit(given: str | None, said: list[tuple[str, str | None]]) -> tuple[str, str | None]:
    """(the unit to import in, a note or None) from ``--unit`` (``given``, None: not given) and
    what the file says of each imported column (``said``: (column, UNITS key or None)). Not
    given: the file's unit when every column says the same one, else m/s², with a note (the
    file says no unit, or different ones); given, a note when the file says another."""
    units = {u for _, u in said if u is not None}
    known = all(u is not None for _, u in said) and len(units) == 1
    if given is None:
        if known:
            unit = units.pop()
            return unit, (f"unit {unit} from the file ({', '.join(c for c, _ in said)}); --unit sets another")
        if units:
            listed = ", ".join(f"{c}: {u}" for c, u in said if u is not None)
            return "m/s2", f"the file gives its columns different or no units ({listed}): taken as m/s2; give --unit"
        return "m/s2", f"unit m/s2 assumed: the file does not say its unit; give --unit ({', '.join(UNITS)})"
    other = [(c, u) for c, u in said if u is not None and u != given]
    if not other:
        return given, None
    says = ", ".join(sorted({u for _, u in other if u}))
    return given, (f"--unit {given} given, but the file says {says} ({', '.join(c for c, _ in other)}): the "
                   f"values are taken as {given}; check --unit")
