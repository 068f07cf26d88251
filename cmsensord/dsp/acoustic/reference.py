"""The plain reference of one update step: numerical quadrature of the definitions (eq. 6).

The closed forms (:func:`~cmsensord.dsp.acoustic.update.update_closed_form`) are tested
against it (docs/acoustic.md §4).  No closed forms and no safeguards: the orthonormal
families come from scipy.special (eqs. 9, 10, 15), the expectations from Gauss quadrature
over the priors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cmsensord.dsp.acoustic.expansion import z_moments
from cmsensord.dsp.acoustic.model import AcousticModel
from cmsensord.dsp.acoustic.polynomials import hermite_phi, laguerre_phi
from cmsensord.dsp.acoustic.step import Posterior, Prior

__all__ = ["update_reference"]


def _z_poly_coeffs(order: int, z_pred: float, gz: float) -> np.ndarray:
    """Power-series coefficients (ascending) of phi_n(z), eq. (10), from scipy's genlaguerre."""
    from scipy.special import gammaln, genlaguerre

    m = z_pred * z_pred / gz
    s = gz / z_pred
    norm = math.exp(0.5 * (gammaln(m) + gammaln(order + 1.0) - gammaln(m + order)))
    c = genlaguerre(order, m - 1.0).coeffs[::-1]      # in powers of z / s
    return norm * c / s ** np.arange(order + 1)


@dataclass
class _Grid:
    """The quadrature of the prior P0(x) P0(a): nodes and normalised weights, the orthonormal
    polynomials at the nodes, and the conditional moments of z on the (a, x) grid."""

    xs: np.ndarray      # nodes of the gamma prior of x (generalised Gauss-Laguerre)
    wx: np.ndarray
    as_: np.ndarray     # nodes of the Gaussian prior of a (Gauss-Hermite)
    wa: np.ndarray
    W: np.ndarray       # weights of the (a, x) grid
    phx: list           # phi_l(x) at the nodes, l = 0..2
    pha: list           # phi_m(a) at the nodes, m = 0..2
    zm1: np.ndarray     # <z | x, a>
    zm2: np.ndarray     # <z^2 | x, a>


def _grid(model: AcousticModel, prior: Prior, nodes: int) -> _Grid:
    from scipy.special import roots_genlaguerre, roots_hermitenorm

    mx = prior.x * prior.x / prior.gx
    s_x = prior.gx / prior.x
    tx, wx = roots_genlaguerre(nodes, mx - 1.0)
    wx = wx / wx.sum()
    xs = s_x * tx
    ua, wa = roots_hermitenorm(nodes)
    wa = wa / wa.sum()
    as_ = prior.a + math.sqrt(prior.ga) * ua
    lam = np.asarray(model.lam1)
    th1 = lam[1, 0] + lam[1, 1] * xs
    th2 = lam[2, 0] + lam[2, 1] * xs + lam[2, 2] * xs * xs
    zm1 = model.alpha0 + as_[:, None] * model.e11 * th1[None, :]
    zm2 = model.beta0 + as_[:, None] * model.beta1 * th1[None, :] \
        + (as_ * as_)[:, None] * model.p22 * th2[None, :]
    W = wa[:, None] * wx[None, :]
    phx = [laguerre_phi(l, xs, prior.x, prior.gx) for l in range(3)]
    pha = [hermite_phi(m, as_, prior.a, prior.ga) for m in range(3)] if prior.ga > 0 else \
        [np.ones_like(as_), np.zeros_like(as_), np.zeros_like(as_)]
    return _Grid(xs=xs, wx=wx, as_=as_, wa=wa, W=W, phx=phx, pha=pha, zm1=zm1, zm2=zm2)


def _coefficients(g: _Grid, z_pred: float, gz: float) -> np.ndarray:
    """A_lmn = <phi_l(x) phi_m(a) <phi_n(z) | x, a>> over the grid, l, m, n <= 2 (eq. 6)."""
    cond = []                                              # <phi_n(z) | x, a>
    for n in range(3):
        c = _z_poly_coeffs(n, z_pred, gz)
        mom = [np.ones_like(g.zm1), g.zm1, g.zm2]
        cond.append(sum(c[j] * mom[j] for j in range(n + 1)))
    A = np.zeros((3, 3, 3))
    for l in range(3):
        for m in range(3):
            for n in range(3):
                A[l, m, n] = np.sum(g.W * g.pha[m][:, None] * g.phx[l][None, :] * cond[n])
    return A


def _estimates(g: _Grid, A: np.ndarray, fz: np.ndarray, den: float) -> tuple[float, float, float, float]:
    """x^, P_x, a^, P_a (eqs. 16-19), the coefficients c, d of eq. (23) by projection."""
    def proj_x(f):                     # coefficient of phi_l = E[f phi_l]
        return np.array([np.sum(g.wx * f * g.phx[l]) for l in range(3)])

    def proj_a(f):
        return np.array([np.sum(g.wa * f * g.pha[m]) for m in range(3)])

    Sx = np.array([np.sum(A[l, 0, :] * fz) for l in range(3)]) / den
    Sa = np.array([np.sum(A[0, m, :] * fz) for m in range(3)]) / den
    c1 = proj_x(g.xs)
    x_hat = float(np.sum(c1[:2] * Sx[:2]))                                                 # (16)
    c2 = proj_x((g.xs - x_hat) ** 2)
    px = float(np.sum(c2 * Sx))                                                            # (18)
    d1 = proj_a(g.as_)
    a_hat = float(np.sum(d1[:2] * Sa[:2]))                                                 # (17)
    d2 = proj_a((g.as_ - a_hat) ** 2)
    pa = float(np.sum(d2 * Sa))                                                            # (19)
    return x_hat, px, a_hat, pa


def _sound(model: AcousticModel, g: _Grid, z_pred: float, gz: float, fz: np.ndarray,
           den: float) -> tuple[float, float]:
    """y^, P_y (eqs. 21-22, docs/acoustic.md §4.4): D_jn = <y^j phi_n(z)> from the prior moments
    of y on the grid (third and fourth central moments: the gamma density's), z = y + v with v
    independent."""
    my1 = float(np.sum(g.W * (g.zm1 - model.v1)))
    # (E[y^2] = E[<z^2|x,a>] - 2 <v> E[<z|x,a>] + 2 <v>^2 - <v^2>)
    ey2 = float(np.sum(g.W * g.zm2)) - 2.0 * model.v1 * float(np.sum(g.W * g.zm1)) + 2.0 * model.v1 ** 2 \
        - model.v2
    gy = ey2 - my1 * my1
    mu3 = 2.0 * gy * gy / my1
    mu4 = 3.0 * gy * gy + 6.0 * gy ** 3 / (my1 * my1)
    ey = [1.0, my1, ey2, mu3 + 3.0 * my1 * gy + my1 ** 3,
          mu4 + 4.0 * my1 * mu3 + 6.0 * my1 ** 2 * gy + my1 ** 4]       # E0[y^j], j = 0..4
    ev = [1.0, model.v1, model.v2]

    def e_yz(j: int, i: int) -> float:                   # E0[y^j z^i], z = y + v, i <= 2
        return sum(math.comb(i, t) * ey[j + t] * ev[i - t] for t in range(i + 1))

    Dy = [[sum(_z_poly_coeffs(n, z_pred, gz)[i] * e_yz(j, i) for i in range(n + 1)) for n in range(3)]
          for j in range(3)]
    y_hat = float(np.dot(Dy[1], fz)) / den                                                 # (21)
    py = float(np.dot(np.asarray(Dy[2]) - 2.0 * y_hat * np.asarray(Dy[1]) + y_hat ** 2 * np.asarray(Dy[0]),
                      fz)) / den                                                           # (22)
    return y_hat, py


def update_reference(model: AcousticModel, prior: Prior, z: float | None, *, nodes: int = 40) -> Posterior:
    """One update by numerical quadrature of the definitions (no closed forms, no safeguards).

    A_lmn = <phi_l(x) phi_m(a) phi_n(z) | Z_{k-1}> (eq. 6) with phi from
    scipy.special (eqs. 9, 10, 15), integrated over the gamma prior of x
    (generalised Gauss-Laguerre nodes) and the Gaussian prior of a (Gauss-Hermite
    nodes), <phi_n(z)|x, a> from the conditional moments of z; the
    coefficients c, d of eq. (23) by projection (same quadrature); then eqs.
    (16)-(19), (21)-(22) as sums over l, m, n <= 2 and division by
    sum_n A_00n phi_n(z).
    """
    z_pred, gz, _, _, _ = z_moments(model, prior, None)
    g = _grid(model, prior, nodes)
    A = _coefficients(g, z_pred, gz)
    if z is None:
        fz = np.array([1.0, 0.0, 0.0])
    else:
        fz = np.array([np.polyval(_z_poly_coeffs(n, z_pred, gz)[::-1], z) for n in range(3)])
    den = np.sum(A[0, 0, :] * fz)
    x_hat, px, a_hat, pa = _estimates(g, A, fz, den)
    y_hat, py = _sound(model, g, z_pred, gz, fz, den)
    Ad = {f"{l}{m}{n}": float(A[l, m, n]) for l in range(3) for m in range(3) for n in range(3)}
    return Posterior(x=x_hat, px=px, a=a_hat, pa=pa, y=y_hat, py=py, z_pred=z_pred, gz=gz,
                     zeta=math.nan if z is None else (z - z_pred) / math.sqrt(gz), A=Ad)
