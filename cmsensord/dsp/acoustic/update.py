"""One step of the acoustic estimator from the closed forms: update (eqs. 16-31) and prediction (eqs. 32-38).

docs/acoustic.md §4.3 (the estimates), §5 (the prediction) and §7 (the safeguards).
"""

from __future__ import annotations

import math

from cmsensord.dsp.acoustic.expansion import SQRT2, bessel_limit, expansion_coefficients
from cmsensord.dsp.acoustic.model import AcousticModel
from cmsensord.dsp.acoustic.polynomials import phi_z
from cmsensord.dsp.acoustic.sound import bessel_limit_sound, sound_coefficients, sound_posterior
from cmsensord.dsp.acoustic.step import DEFAULT_GUARDS, Guards, Posterior, Prior

__all__ = ["update_closed_form", "predict", "A_MAX"]

#: |a^| is kept below this: a = B_11 = <theta1(x) theta1(y)> is a correlation of orthonormal functions
A_MAX = 0.99


def update_closed_form(model: AcousticModel, prior: Prior, z: float | None,
                       guards: Guards | None = DEFAULT_GUARDS) -> Posterior:
    """One update (eqs. 16-19, 21-22) from the closed forms of eqs. (24)-(31).

    ``z=None`` (no observation) returns the prior.  ``guards=None`` runs the
    paper's equations without the safeguards of docs §7.
    """
    yf = guards.y_floor if guards is not None else None
    co = expansion_coefficients(model, prior, y_floor=yf)
    A, z_pred, gz = co["A"], co["z_pred"], co["gz"]
    if guards is not None:
        A = bessel_limit(A)
    sx = math.sqrt(prior.gx)
    sa = math.sqrt(prior.ga)
    if z is None:
        f1 = f2 = 0.0
        zeta = math.nan
    else:
        zeta = (z - z_pred) / math.sqrt(gz)
        if guards is not None:
            zeta = min(max(zeta, -guards.zeta_max), guards.zeta_max)
        f1, f2 = phi_z(zeta, gz / (z_pred * z_pred))
    # x = c10 + c11 phi1(x): c10 = x*, c11 = -sqrt(Gamma_x) (eq. 23)
    Sx1 = A["101"] * f1 + A["102"] * f2              # sum_n A_10n phi_n(z), A_100 = 0
    Sx2 = A["201"] * f1 + A["202"] * f2              # sum_n A_20n phi_n(z), A_200 = 0
    x_hat = prior.x - sx * Sx1                                                             # (16)
    s_x = prior.gx / prior.x
    c20 = prior.gx + (prior.x - x_hat) ** 2
    c21 = 2.0 * sx * (x_hat - prior.x - s_x)
    c22 = SQRT2 * prior.gx * math.sqrt(1.0 + prior.gx / (prior.x * prior.x))
    px = c20 + c21 * Sx1 + c22 * Sx2                                                       # (18)
    Sa1 = A["011"] * f1 + A["012"] * f2
    Sa2 = A["021"] * f1 + A["022"] * f2
    a_hat = prior.a + sa * Sa1                                                             # (17)
    d20 = prior.ga + (prior.a - a_hat) ** 2
    d21 = 2.0 * sa * (prior.a - a_hat)
    d22 = SQRT2 * prior.ga
    pa = d20 + d21 * Sa1 + d22 * Sa2                                                       # (19)
    if guards is not None:
        x_hat = max(x_hat, guards.x_floor * prior.x)
        a_hat = min(max(a_hat, -A_MAX), A_MAX)          # a = B_11, |B_11| <= 1 (docs §7)
        px = min(max(px, guards.var_floor * prior.gx), prior.gx)
        # P_a between the mean of eq. (19) over P0(z) and the prior variance (docs §7)
        keep_a = max(1.0 - A["011"] ** 2 - A["012"] ** 2, guards.var_floor)
        pa = min(max(pa, keep_a * prior.ga), prior.ga)
    D = sound_coefficients(model, z_pred, gz)
    if guards is not None:
        D = bessel_limit_sound(D)
    y_hat, py = sound_posterior(D, f1, f2)                                                  # (21), (22)
    if guards is not None:
        y_hat = max(y_hat, guards.y_floor * abs(model.e10))   # a sound energy is > 0 (docs §7)
        py = max(py, 0.0)                  # eq. (22) is a truncated expansion too (docs §7)
    return Posterior(x=x_hat, px=px, a=a_hat, pa=pa, y=y_hat, py=py, z_pred=z_pred, gz=gz,
                     zeta=zeta, A=A)


def predict(model: AcousticModel, post: Posterior, guards: Guards | None = DEFAULT_GUARDS) -> Prior:
    """The prior of the next step, eqs. (34)-(35) and (37)-(38)."""
    x = model.F * post.x + model.G * model.u_mean                                          # (34)
    gx = model.F * model.F * post.px + model.G * model.G                                   # (35)
    if guards is not None:
        x = max(x, guards.x_floor * model.x_mean)
    return Prior(x=x, gx=gx, a=post.a, ga=post.pa)                                         # (37, 38)
