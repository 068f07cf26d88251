"""Input units to each channel's physical unit (m/s² for an accelerometer, Pa for a
microphone: the capture's), and the unit a file says its columns are in.

A capture's channel is an accelerometer's (its values m/s²: g, mg, m/s2, mm/s2, or V through a
sensitivity in mV/g) or a microphone's (Pa). One import may hold both (a paired recording for
the acoustic calibration): ``--unit`` gives one unit, or one per channel."""

from __future__ import annotations

import re

from .errors import ImportFailure

__all__ = ["G", "UNITS", "InG", "per_channel", "physical_unit", "resolve_units", "to_ms2_factor", "unit_in_name",
           "unit_of", "unit_in_suffix"]

#: standard gravity, m/s^2 per g
G = 9.80665
#: the physical unit per input unit (m/s^2; a microphone's Pa: Pa); "V" needs a sensitivity in mV/g
UNITS: dict[str, float | None] = {"g": G, "mg": G * 1e-3, "m/s2": 1.0, "mm/s2": 1e-3, "V": None, "Pa": 1.0}


class InG(float):
    """A value given in g (``--range 5g``), in m/s²: an acceleration's, no microphone's."""


def physical_unit(unit: str) -> str:
    """The capture's unit of a channel imported in ``unit``: Pa for Pa, else m/s2."""
    return "Pa" if unit == "Pa" else "m/s2"


def per_channel(value, n: int, option: str) -> list:
    """``value`` (None, one, or a tuple of one or ``n``) as one per channel; a one-line error
    for another count."""
    if not isinstance(value, tuple):
        return [value] * n
    if len(value) not in (1, n):
        raise ImportFailure(f"{option} gives {len(value)} values for {n} channel(s); give one, or one per "
                            "imported channel")
    return list(value) * n if len(value) == 1 else list(value)


def to_ms2_factor(unit: str, sensitivity_mv_per_g: float | None = None,
                  scale_factor: float = 1.0) -> float:
    """The physical unit (:func:`physical_unit`) per raw value: ``scale_factor`` x (m/s² per ``unit``,
    or 1 for Pa).

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
              "mm/s2": "mm/s2", "mm/s^2": "mm/s2", "mm/s²": "mm/s2", "v": "V", "pa": "Pa"}
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


#: a unit at the end of an array's, a variable's or a column's name after ``_`` (``acc_mg``, and
#: ``acc_mg_0``, a column of the array ``acc_mg``): the units the import takes (a velocity's
#: ``_mm_s`` is none, nor is ``_v``, a vertical axis as often as volts)
_SUFFIX = re.compile(r"^(.*?_(g|mg|ms2|m_s2|mps2|mm_s2|mms2|pa))(?:_\d+)?$", re.IGNORECASE)
_SUFFIX_UNITS = {"g": "g", "mg": "mg", "ms2": "m/s2", "m_s2": "m/s2", "mps2": "m/s2", "mm_s2": "mm/s2",
                 "mms2": "mm/s2", "pa": "Pa"}


def unit_in_suffix(name: str) -> tuple[str, str] | None:
    """The unit a name ends with after ``_`` and the name up to it (``acc_mg_0`` -> ``mg``,
    ``acc_mg``), or None."""
    m = _SUFFIX.match(name)
    return (_SUFFIX_UNITS[m.group(2).lower()], m.group(1)) if m else None


def resolve_units(given: tuple[str, ...] | None, said: list[tuple[str, str | None]],
                  named: dict[str, str] | None = None, what: str = "column") -> tuple[list[str], list[str]]:
    """(each imported column's unit, notes) from ``--unit`` (``given``: one unit, or one per
    column; None: not given) and what the file says of each (``said``: (column, UNITS key or
    None); ``named``: the columns whose unit their ``what``'s name gives, :func:`unit_in_suffix`,
    to that name). Not given: each column's own unit where the file says it, else m/s², with a
    note; given, a note on each column the file says another unit of."""
    if given is not None and len(given) not in (1, len(said)):
        raise ImportFailure(f"--unit gives {len(given)} units for {len(said)} channel(s); give one unit, or one "
                            "per imported channel")
    if given is None:
        return _from_file(said, named or {}, what)
    units = list(given) * len(said) if len(given) == 1 else list(given)
    other = [(c, u, g) for (c, u), g in zip(said, units) if u is not None and u != g]
    if not other:
        return units, []
    gave = ", ".join(sorted({g for _, _, g in other}))
    says = ", ".join(sorted({u for _, u, _ in other if u}))
    who = f"the {what} name says" if all(c in (named or {}) for c, _, _ in other) else "the file says"
    return units, [f"--unit {gave} given, but {who} {says} ({', '.join(c for c, _, _ in other)}): the values "
                   f"are taken as {gave}; check --unit"]


def _from_file(said: list[tuple[str, str | None]], named: dict[str, str], what: str) -> tuple[list[str], list[str]]:
    """Each column's unit as the file says it (m/s² where it says none), and a note."""
    units = [u or "m/s2" for _, u in said]
    known = {u for _, u in said if u is not None}
    if not known:
        return units, [f"unit m/s2 assumed: the file does not say its unit; give --unit ({', '.join(UNITS)})"]
    if all(c in named for c, _ in said) and len(known) == 1:
        names = list(dict.fromkeys(named[c] for c, _ in said))
        return units, [f"unit {units[0]} taken from the {what} name{'s' if len(names) > 1 else ''} "
                       f"{', '.join(names)}; --unit sets another"]
    if all(u is not None for _, u in said) and len(known) == 1:
        return units, [f"unit {units[0]} from the file ({', '.join(c for c, _ in said)}); --unit sets another"]
    listed = ", ".join(f"{c}: {u or 'none, taken as m/s2'}" for c, u in said)
    return units, [f"units from the file ({listed}); --unit sets others (one, or one per channel)"]
