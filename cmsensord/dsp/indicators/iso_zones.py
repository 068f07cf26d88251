"""ISO 10816-3 / ISO 20816-3 evaluation zones of the broadband velocity RMS, and the
standard's baseline-relative alarm.

Zones (velocity RMS, mm/s, over the band of :mod:`.velocity`):

* A: newly commissioned machines;  B: acceptable for unrestricted long-term operation;
* C: unsatisfactory for long-term continuous operation;  D: severe enough to cause damage.

Boundaries A/B, B/C, C/D by machine group and foundation (ISO 10816-3, Table A.1 and A.2):

=========================  ==========  ==========
machine group              rigid       flexible
=========================  ==========  ==========
1: large, > 300 kW         2.3 / 4.5 / 7.1    3.5 / 7.1 / 11.0
2: medium, 15-300 kW       1.4 / 2.8 / 4.5    2.3 / 4.5 / 7.1
=========================  ==========  ==========

A value on a boundary is in the higher zone.  ISO 10816-3 (Annex A) sets the ALARM
level from the machine's own baseline: baseline + 0.25 x the B/C boundary, but not
above 1.25 x the B/C boundary.
"""

from __future__ import annotations

from bisect import bisect_right

__all__ = ["ZONES", "BOUNDARIES_MM_S", "boundaries", "zone", "zone_index", "baseline_alarm_mm_s"]

ZONES = ("A", "B", "C", "D")

#: (group, foundation) -> (A/B, B/C, C/D) in mm/s RMS
BOUNDARIES_MM_S: dict[tuple[int, str], tuple[float, float, float]] = {
    (1, "rigid"): (2.3, 4.5, 7.1),
    (1, "flexible"): (3.5, 7.1, 11.0),
    (2, "rigid"): (1.4, 2.8, 4.5),
    (2, "flexible"): (2.3, 4.5, 7.1),
}


def boundaries(group: int, foundation: str) -> tuple[float, float, float]:
    """The A/B, B/C and C/D boundaries [mm/s] of a machine group (1, 2) and foundation
    (rigid, flexible); KeyError for any other."""
    return BOUNDARIES_MM_S[(group, foundation)]


def zone_index(v_mm_s: float, group: int, foundation: str) -> int:
    """0..3 for zone A..D (a value on a boundary is in the higher zone)."""
    return bisect_right(boundaries(group, foundation), v_mm_s)   # NaN: 3, as np.searchsorted


def zone(v_mm_s: float, group: int, foundation: str) -> str:
    """The zone letter of a velocity RMS [mm/s]."""
    return ZONES[zone_index(v_mm_s, group, foundation)]


def baseline_alarm_mm_s(baseline_mm_s: float, group: int, foundation: str) -> float:
    """ISO 10816-3 Annex A ALARM: baseline + 0.25 x B/C, capped at 1.25 x B/C [mm/s]."""
    bc = boundaries(group, foundation)[1]
    return min(baseline_mm_s + 0.25 * bc, 1.25 * bc)
