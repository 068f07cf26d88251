"""The machine sound of one update step: y^ = <y|Z_k> and P_y (eqs. 21-22; docs/acoustic.md §4.4).

:func:`sound_coefficients` and :func:`sound_posterior` compute the definition <y|Z_k> with
Bayes' theorem (eq. 6) for y; :func:`sound_estimate` is the paper's printed form
<<y|x>|Z_k>, which ignores what z = y + v says about y directly (the EKF's ``sound="eq21"``).
"""

from __future__ import annotations

import math

from cmsensord.dsp.acoustic.expansion import BESSEL
from cmsensord.dsp.acoustic.model import AcousticModel
from cmsensord.dsp.acoustic.polynomials import phi2_coefficients

__all__ = ["sound_coefficients", "sound_posterior", "sound_estimate", "bessel_limit_sound"]


def sound_coefficients(model: AcousticModel, z_pred: float, gz: float) -> dict:
    """The expansion coefficients of the machine sound, D_jn = <y^j phi_n(z) | Z_{k-1}> (docs §4.4).

    y* = <y|Z_{k-1}> = z* - <v>, Gamma_y = Gamma_z - var v (z = y + v, v independent of y); the
    third and fourth central moments of y given Z_{k-1} are those of the gamma density with
    this mean and variance (the paper's P0 for energy variables, eqs. 7-8).  Returns
    D10 = y*, D11, D12 (for y) and D20, D21, D22 (for y^2), and the moments.
    """
    ys = z_pred - model.v1
    gy = gz - model.var_v
    if not gy > 0:
        gy = 1e-12 * max(ys * ys, z_pred * z_pred)
    sz = math.sqrt(gz)
    kz = gz / (z_pred * z_pred)
    ca, cb = phi2_coefficients(kz)
    if ys > 0:
        mu3 = 2.0 * gy * gy / ys                      # gamma: skewness 2 sqrt(Gamma_y) / y*
        mu4 = 3.0 * gy * gy + 6.0 * gy ** 3 / (ys * ys)
    else:                                             # outside the model's range: Gaussian closure
        mu3, mu4 = 0.0, 3.0 * gy * gy
    # <y phi1(z)> = -cov(y, z)/sigma_z;  <y phi2(z)> = ca <y (zeta^2 - 1)> - cb <y zeta>
    D11 = -gy / sz
    D12 = ca * mu3 / gz - cb * gy / sz
    # the same for y^2: cov(y^2, z) = mu3 + 2 y* Gamma_y, <y^2 (zeta^2 - 1)> = (mu4 + 2 y* mu3 - Gamma_y^2)/Gamma_z
    c2 = mu3 + 2.0 * ys * gy
    D21 = -c2 / sz
    D22 = ca * (mu4 + 2.0 * ys * mu3 - gy * gy) / gz - cb * c2 / sz
    return {"y_prior": ys, "gy": gy, "mu3": mu3, "mu4": mu4, "D11": D11, "D12": D12,
            "D20": gy + ys * ys, "D21": D21, "D22": D22}


def bessel_limit_sound(D: dict) -> dict:
    """Bessel's inequality for y: (D11^2 + D12^2)/Gamma_y <= 1 (the correlations of the
    standardised y with phi_1(z), phi_2(z)); the second-order coefficient gives way first."""
    D = dict(D)
    lim = BESSEL * D["gy"]
    if D["D11"] ** 2 + D["D12"] ** 2 > lim:
        D["D12"] = math.copysign(math.sqrt(max(lim - D["D11"] ** 2, 0.0)), D["D12"])
    return D


def sound_posterior(D: dict, f1: float, f2: float) -> tuple[float, float]:
    """y^ = <y|Z_k> and P_y = <(y - y^)^2|Z_k> from the D's and phi_1(z), phi_2(z) (docs §4.4).

    Bayes' theorem (eq. 6) for y: <g(y)|Z_k> = sum_n <g(y) phi_n(z)|Z_{k-1}> phi_n(z) /
    sum_n A_00n phi_n(z), the denominator being 1 (docs §4.2).
    """
    ys = D["y_prior"]
    y_hat = ys + D["D11"] * f1 + D["D12"] * f2                                            # (21)
    # (y - y^)^2 = y^2 - 2 y^ y + y^^2
    py = (D["D20"] - 2.0 * y_hat * ys + y_hat * y_hat
          + (D["D21"] - 2.0 * y_hat * D["D11"]) * f1 + (D["D22"] - 2.0 * y_hat * D["D12"]) * f2)   # (22)
    return y_hat, py


def sound_estimate(model: AcousticModel, x_hat: float, px: float, a_hat: float,
                   pa: float) -> tuple[float, float]:
    """The printed eqs. (21)-(22), <<y|x>|Z_k>: y from the estimates of x and a only (docs §4.4;
    the estimator uses :func:`sound_posterior`, the definition <y|Z_k>)."""
    (l10, l11, _), (l20, l21, l22) = model.lam1[1], model.lam1[2]
    t1 = l10 + l11 * x_hat
    t2 = l20 + l21 * x_hat + l22 * (px + x_hat * x_hat)
    y_hat = model.e10 + a_hat * model.e11 * t1                                             # (21)
    # (y - y^)^2 = e20 + e21 theta1(y) + e22 theta2(y):  e2s from p2s and e1s (eq. 23)
    e20 = model.p20 - 2.0 * y_hat * model.e10 + y_hat * y_hat
    e21 = model.p21 - 2.0 * y_hat * model.e11
    py = e20 + a_hat * e21 * t1 + (pa + a_hat * a_hat) * model.p22 * t2                   # (22)
    return y_hat, py
