"""The model the acoustic estimator assumes known (Orimoto, Ikuta & Wang), as calibration learns it.

Symbols as in docs/acoustic.md §1-§2 and §5: x the vibration energy, y the machine sound
energy, v the background-noise energy, z = y + v the observed sound energy, a the
sound-vibration correlation parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

__all__ = ["AcousticModel"]


@dataclass(frozen=True)
class AcousticModel:
    """What Orimoto, Ikuta & Wang assume known, fitted by :mod:`cmsensord.acoustic_calib`.

    Stored in a calibration file (:mod:`cmsensord.acoustic_model`).  Raises ValueError
    naming the field for a value outside the model's range.

    lam1: lambda^(1)_ri, r, i = 0..2 (eq. 4): theta_r(x) = sum_i lam1[r][i] x^i,
        orthonormal under the distribution of x;
    lam2: lambda^(2)_si (eq. 5), the same for y (kept for the record; the
        estimator uses e and p, which follow from it);
    e10, e11: y = e10 + e11 theta1(y) (eq. 23);
    p20, p21, p22: y^2 = p20 + p21 theta1(y) + p22 theta2(y) (eq. 23, the
        paper's p_2s in eqs. 25-31);
    v1, v2: background-noise moments <v>, <v^2>;
    F, G, u_mean: the vibration's time transition (eqs. 32-33), <u> of eq. 34;
    x0, gx0, a0, ga0: the initial prior x*, Gamma_x, a*, Gamma_a;
    block_s: the block length the model was learnt with [s].
    """

    lam1: tuple[tuple[float, ...], ...]
    lam2: tuple[tuple[float, ...], ...]
    e10: float
    e11: float
    p20: float
    p21: float
    p22: float
    v1: float
    v2: float
    F: float
    G: float
    u_mean: float
    x0: float
    gx0: float
    a0: float
    ga0: float
    block_s: float = 0.01

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("lam1", "lam2"):
                arr = np.asarray(v, dtype=np.float64)
                if arr.shape != (3, 3) or not np.all(np.isfinite(arr)):
                    raise ValueError(f"{f.name}: expected a 3x3 table of finite numbers, got {v!r}")
                object.__setattr__(self, f.name, tuple(tuple(float(c) for c in row) for row in arr))
            else:
                if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                        or not math.isfinite(float(v)):
                    raise ValueError(f"{f.name}: expected a finite number, got {v!r}")
                object.__setattr__(self, f.name, float(v))
        for key in ("e11", "p22", "gx0", "x0", "block_s"):
            if not getattr(self, key) > 0:
                raise ValueError(f"{key}: must be > 0, got {getattr(self, key)!r}")
        if not self.ga0 >= 0:
            raise ValueError(f"ga0: must be >= 0, got {self.ga0!r}")
        if not self.v1 >= 0 or not self.v2 >= self.v1 ** 2:
            raise ValueError(f"background moments: need <v> >= 0 and <v^2> >= <v>^2, got "
                             f"{self.v1!r}, {self.v2!r}")
        if not -1.0 < self.F < 1.0:
            raise ValueError(f"F: must lie in (-1, 1), got {self.F!r}")
        if not self.G > 0:
            raise ValueError(f"G: must be > 0, got {self.G!r}")
        if not self.lam1[1][1] != 0 or not self.lam1[2][2] != 0:
            raise ValueError("lam1: theta_1 and theta_2 need a non-zero leading coefficient")

    # constants of the conditional moments of z (docs/acoustic.md §2)
    @property
    def alpha0(self) -> float:
        return self.e10 + self.v1

    @property
    def beta0(self) -> float:
        return self.p20 + 2.0 * self.e10 * self.v1 + self.v2

    @property
    def beta1(self) -> float:
        return self.p21 + 2.0 * self.e11 * self.v1

    @property
    def var_v(self) -> float:
        return self.v2 - self.v1 ** 2

    @property
    def x_mean(self) -> float:
        """The stationary mean of the transition model, <x> = G <u> / (1 - F)."""
        return self.G * self.u_mean / (1.0 - self.F)
