"""The orthonormal polynomial families of the priors (eqs. 9, 10, 15; docs/acoustic.md §3).

:func:`laguerre_phi` and :func:`hermite_phi` evaluate any order with scipy.special (the
quadrature reference and the tests); :func:`phi_z` and :func:`phi2_coefficients` are the
closed forms of orders 1 and 2 of the observation's family that the estimator uses (math
module only).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["laguerre_phi", "hermite_phi", "phi_z", "phi2_coefficients"]


def laguerre_phi(order: int, x, mean: float, var: float) -> np.ndarray:
    """phi_l of eqs. (9)-(10): orthonormal under the gamma density with this mean and variance.

    phi_l(x) = sqrt(Gamma(m) l! / Gamma(m + l)) L_l^(m-1)(x / s),
    m = mean^2 / var, s = var / mean (eq. 11).  Uses scipy.special.
    """
    from scipy.special import eval_genlaguerre, gammaln

    m = mean * mean / var
    s = var / mean
    norm = math.exp(0.5 * (gammaln(m) + gammaln(order + 1.0) - gammaln(m + order)))
    return norm * eval_genlaguerre(order, m - 1.0, np.asarray(x, dtype=np.float64) / s)


def hermite_phi(order: int, a, mean: float, var: float) -> np.ndarray:
    """phi_m of eq. (15): He_m((a - a*) / sqrt(Gamma_a)) / sqrt(m!), orthonormal under N(a*, Gamma_a).

    He_m are the probabilists' Hermite polynomials (docs §3: the paper's H_m
    with the 1/sqrt(m!) normalisation is orthonormal only for these).
    """
    from scipy.special import eval_hermitenorm

    u = (np.asarray(a, dtype=np.float64) - mean) / math.sqrt(var)
    return eval_hermitenorm(order, u) / math.sqrt(math.factorial(order))


def phi2_coefficients(kz: float) -> tuple[float, float]:
    """ca, cb of phi_2(z) = ca (zeta^2 - 1) - cb zeta, zeta = (z - z*)/sqrt(Gamma_z), 1/m_z = kz
    (docs §3)."""
    ca = 1.0 / math.sqrt(2.0 * (1.0 + kz))
    cb = math.sqrt(2.0 * kz / (1.0 + kz))
    return ca, cb


def phi_z(zeta: float, kz: float) -> tuple[float, float]:
    """phi_1(z), phi_2(z) of eq. (10) in terms of zeta = (z - z*)/sqrt(Gamma_z), 1/m_z = kz."""
    ca, cb = phi2_coefficients(kz)
    return -zeta, ca * (zeta * zeta - 1.0) - cb * zeta
