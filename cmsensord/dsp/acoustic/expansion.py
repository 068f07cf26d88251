"""The expansion coefficients A_lmn of one update step (eqs. 24-31; docs/acoustic.md §4.1-§4.2).

The prior moments of the observation z (z*, Gamma_z) and the coefficients
A_lmn = <phi_l(x) phi_m(a) phi_n(z) | Z_{k-1}> for l, m, n <= 2, written with the centred
conditional moments of z, and the limit Bessel's inequality puts on them (docs §7).
"""

from __future__ import annotations

import math

from cmsensord.dsp.acoustic.model import AcousticModel
from cmsensord.dsp.acoustic.polynomials import phi2_coefficients
from cmsensord.dsp.acoustic.step import Prior

__all__ = ["expansion_coefficients", "z_moments", "bessel_limit", "BESSEL", "SQRT2"]

SQRT2 = math.sqrt(2.0)


def z_moments(model: AcousticModel, prior: Prior, y_floor: float | None):
    """z* = <z|Z_{k-1}>, Gamma_z, the prior means T1, T2 of theta_1(x), theta_2(x) and <a^2> (docs §4.1).

    ``y_floor`` None: the plain moments; else the predicted machine sound is kept >= y_floor e10
    and Gamma_z >= var <z|x, a> + var v (docs §7).
    """
    (l10, l11, _), (l20, l21, l22) = model.lam1[1], model.lam1[2]
    T1 = l10 + l11 * prior.x                                     # <theta1(x)|Z_{k-1}>
    T2 = l20 + l21 * prior.x + l22 * (prior.gx + prior.x * prior.x)   # <theta2(x)|Z_{k-1}>
    A2 = prior.ga + prior.a * prior.a                            # <a^2|Z_{k-1}>
    y_mean = model.e10 + prior.a * model.e11 * T1
    y2 = model.p20 + prior.a * model.p21 * T1 + A2 * model.p22 * T2
    if y_floor is not None:
        y_min = y_floor * model.e10 if model.e10 > 0 else y_floor
        y_mean = max(y_mean, y_min)
    z_pred = y_mean + model.v1
    # <z^2> = <y^2> + 2 <y><v> + <v^2> (v independent of x and a)
    z2 = y2 + 2.0 * y_mean * model.v1 + model.v2
    gz = z2 - z_pred * z_pred
    if y_floor is not None:
        # Gamma_z >= var <z|x, a> + var v: the truncated model's E[var(z|x, a)] can be < 0 (docs §7)
        explained = model.e11 ** 2 * (A2 * model.lam1[1][1] ** 2 * prior.gx + prior.ga * T1 * T1)
        gz = max(gz, explained + model.var_v, 1e-12 * z_pred * z_pred)
    return z_pred, gz, T1, T2, A2


def expansion_coefficients(model: AcousticModel, prior: Prior, *, y_floor: float | None = None) -> dict:
    """A_lmn for l, m, n <= 2 (eqs. 24-31), and the prior moments they use.

    Written with the centred conditional moments of z (docs §4.2), which are
    the paper's expressions rearranged so that no O(m_z) terms cancel.
    """
    z_pred, gz, T1, T2, A2 = z_moments(model, prior, y_floor)
    (_, l11, _), (_, l21, l22) = model.lam1[1], model.lam1[2]
    sx = math.sqrt(prior.gx)                      # sqrt(Gamma_x) = s_x sqrt(m_x)
    s_x = prior.gx / prior.x                      # s*_x of eq. 11
    kx = prior.gx / (prior.x * prior.x)           # 1 / m*_x
    sz = math.sqrt(gz)
    kz = gz / (z_pred * z_pred)                   # 1 / m*_z
    sa = math.sqrt(prior.ga)
    alpha1 = model.e11
    # E[(z - z*)^2 | x, a] = delta0 + a delta1 theta1(x) + a^2 delta2 theta2(x)
    delta1 = model.beta1 - 2.0 * z_pred * alpha1
    delta2 = model.p22
    # phi2(z) = ca (zeta^2 - 1) - cb zeta, zeta = (z - z*) / sqrt(Gamma_z)
    ca, cb = phi2_coefficients(kz)
    q = ca / gz
    r = cb / sz
    A = {}
    A["101"] = alpha1 * prior.a * l11 * sx / sz                                           # (24)
    A["102"] = sx * (-q * (prior.a * delta1 * l11 + A2 * delta2 * (l21 + 2.0 * l22 * (prior.x + s_x)))
                     + r * alpha1 * prior.a * l11)                                        # (25)
    A["201"] = 0.0                                                                         # (26)
    A["202"] = q * A2 * delta2 * l22 * SQRT2 * prior.gx * math.sqrt(1.0 + kx)              # (27)
    A["011"] = -alpha1 * sa * T1 / sz                                                      # (28)
    A["012"] = q * (sa * delta1 * T1 + 2.0 * prior.a * sa * delta2 * T2) - r * alpha1 * sa * T1   # (29)
    A["021"] = 0.0                                                                         # (30)
    A["022"] = q * SQRT2 * prior.ga * delta2 * T2                                          # (31)
    return {"A": A, "z_pred": z_pred, "gz": gz, "ca": ca, "cb": cb, "T1": T1, "T2": T2}


#: the bound Bessel's inequality puts on a sum of squared correlations of orthonormal functions
#: (1), with a margin
BESSEL = 1.0 - 1e-6


def bessel_limit(A: dict) -> dict:
    """Bessel's inequality for the A's of one function: sum_n A_l0n^2 <= <phi_l(x)^2> = 1 (and
    for a).  A model whose moments break it is outside its range (docs §7); the second-order
    coefficient gives way first."""
    A = dict(A)
    for k1, k2 in (("101", "102"), ("011", "012")):
        a1, a2 = A[k1], A[k2]
        if a1 * a1 + a2 * a2 > BESSEL:
            if a1 * a1 >= BESSEL:
                A[k1], A[k2] = math.copysign(math.sqrt(BESSEL), a1), 0.0
            else:
                A[k2] = math.copysign(math.sqrt(BESSEL - a1 * a1), a2)
    for k in ("202", "022"):
        if abs(A[k]) > BESSEL:
            A[k] = math.copysign(BESSEL, A[k])
    return A
