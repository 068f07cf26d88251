"""Rolling-element bearing defect frequencies from the geometry and the shaft speed.

With n rolling elements of diameter d on a pitch diameter D, contact angle phi,
the inner race turning at f_r with the outer race fixed (the kinematic relations
without slip, Randall & Antoni 2011, the bearing characteristic frequencies):

    FTF  = f_r / 2 (1 - d/D cos phi)                  cage (fundamental train)
    BPFO = n f_r / 2 (1 - d/D cos phi)                ball pass, outer race
    BPFI = n f_r / 2 (1 + d/D cos phi)                ball pass, inner race
    BSF  = D f_r / (2 d) (1 - (d/D cos phi)^2)        ball spin; a ball defect strikes
                                                      both races: its line is 2 x BSF

Real bearings slip 1-2 %: the envelope spectrum is searched in a window around
each frequency (:mod:`.envelope`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["Geometry", "DefectFrequencies", "defect_frequencies", "DEFECTS"]

#: the defect frequencies' names, in the order of the messages
DEFECTS = ("ftf", "bpfo", "bpfi", "bsf")


class Geometry(NamedTuple):
    """n rolling elements of diameter d on the pitch diameter D (same unit), contact angle [deg]."""

    n: int
    d: float
    D: float
    contact_angle_deg: float = 0.0


class DefectFrequencies(NamedTuple):
    """Hz at the shaft speed given, or orders (multiples of the shaft speed) at f_r = 1."""

    ftf: float
    bpfo: float
    bpfi: float
    bsf: float


def defect_frequencies(g: Geometry, f_r: float = 1.0) -> DefectFrequencies:
    """FTF, BPFO, BPFI and BSF [Hz] of bearing ``g`` at the shaft speed ``f_r`` [Hz]
    (f_r = 1: as orders)."""
    r = g.d / g.D * math.cos(math.radians(g.contact_angle_deg))
    return DefectFrequencies(ftf=f_r / 2 * (1 - r), bpfo=g.n * f_r / 2 * (1 - r),
                             bpfi=g.n * f_r / 2 * (1 + r), bsf=g.D * f_r / (2 * g.d) * (1 - r * r))
