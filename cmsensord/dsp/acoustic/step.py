"""One step of the acoustic estimator: its prior, its posterior, and the safeguards' parameters.

The safeguards keep the truncated expansions of Orimoto, Ikuta & Wang inside their range
(docs/acoustic.md §7); ``guards=None`` wherever a :class:`Guards` is taken runs the
paper's equations without them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["Prior", "Posterior", "Guards", "DEFAULT_GUARDS"]


@dataclass
class Prior:
    """P0(x|Z_{k-1}) and P0(a|Z_{k-1}) (eqs. 7, 11-14)."""

    x: float        # x*_k
    gx: float       # Gamma_x,k
    a: float        # a*_k
    ga: float       # Gamma_a,k


@dataclass
class Posterior:
    """The estimates of one step (eqs. 16-19, 21-22) and the predicted observation."""

    x: float        # x^_k (16)
    px: float       # P_x,k (18)
    a: float        # a^_k (17)
    pa: float       # P_a,k (19)
    y: float        # y^_k (21)
    py: float       # P_y,k (22)
    z_pred: float = math.nan   # z*_k
    gz: float = math.nan       # Gamma_z,k
    zeta: float = math.nan     # (z - z*) / sqrt(Gamma_z), after the limiter
    A: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Guards:
    """The safeguards of the update and the prediction (docs/acoustic.md §7).

    zeta_max: the standardised observation zeta = (z - z*)/sqrt(Gamma_z) is limited to
    +-zeta_max before it enters phi_1(z), phi_2(z); x_floor: x^ >= x_floor x*, and the
    predicted x* >= x_floor <x>; y_floor: the predicted machine sound <y|Z_{k-1}> >=
    y_floor e10, and y^ >= y_floor |e10|; var_floor: the smallest fraction of the prior
    variance P_x keeps (and P_a, should the A's explain all of it).

    With them, and not configurable: P_x <= Gamma_x; P_a in [Gamma_a (1 - A_011^2 - A_012^2),
    Gamma_a]; Gamma_z >= var <z|x, a> + var v; Bessel's inequality on the expansion
    coefficients of x, a and y (the second-order one gives way first); |a^| <= ``A_MAX``;
    P_y >= 0.
    """

    zeta_max: float = 5.0
    x_floor: float = 1e-3
    y_floor: float = 1e-3
    var_floor: float = 1e-6

    def __post_init__(self) -> None:
        if not self.zeta_max > 0:
            raise ValueError(f"zeta_max must be > 0, got {self.zeta_max!r}")
        if not (0 < self.x_floor < 1 and 0 < self.var_floor < 1 and 0 < self.y_floor < 1):
            raise ValueError("guards: need 0 < x_floor, var_floor, y_floor < 1")


#: the default safeguards (the defaults of :class:`Guards`), shared: a Guards is immutable
DEFAULT_GUARDS = Guards()
