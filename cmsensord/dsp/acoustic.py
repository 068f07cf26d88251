"""Vibration from microphone sound under background noise: a recursive Bayesian estimator.

Implements seed 002 (H. Orimoto, A. Ikuta, X. Wang, "Bayesian estimation of
machine vibration from sound observed under background noise"), eqs. (1)-(38),
and the extended Kalman filter (EKF) of the same model the paper compares with.
The derivation of every closed form used here, and of what the converted text
of the paper garbles, is written down in ``docs/acoustic.md`` (sections given
as "docs §n" below).

Variables, per block k (10 ms: the board's block of 250 samples at 25 kHz):

* x_k  vibration energy: the accelerometer's block mean square [(m/s^2)^2]
  (docs §1: the paper's gamma prior is "suitable for energy variable", and
  radiated sound energy goes with vibration energy); the daemon feeds
  sqrt(x^_k), a block RMS in m/s^2, to the AKF bank of seed 000;
* y_k  sound energy of the machine (mean square sound pressure in the block);
* v_k  background-noise energy, independent of x_k and y_k;
* z_k = y_k + v_k  the observed sound energy (eq. 1, additivity of energy);
* a_k  the unknown sound-vibration correlation parameter.

Sound-vibration model (eqs. 2-5, 21-23; docs §2).  With theta^(1), theta^(2) the
orthonormal polynomials of x and y (Schmidt orthogonalisation, eqs. 4-5,
coefficients lambda), the expansion of P(y|x) truncated as the paper does
(B_r1 = a delta_r1, B_r2 = a^2 delta_r2) gives the conditional moments::

    <y   | x, a> = e10 + a e11 theta1(x)
    <y^2 | x, a> = p20 + a p21 theta1(x) + a^2 p22 theta2(x)

(e: y = sum_s e1s theta_s(y); p: y^2 = sum_s p2s theta_s(y), eq. 23), hence
with the background moments <v>, <v^2>::

    <z   | x, a> = alpha0 + a alpha1 theta1(x)                 alpha0 = e10 + <v>, alpha1 = e11
    <z^2 | x, a> = beta0 + a beta1 theta1(x) + a^2 beta2 theta2(x)
                   beta0 = p20 + 2 e10 <v> + <v^2>, beta1 = p21 + 2 e11 <v>, beta2 = p22

Update, one step (eqs. 6-31).  The prior P0(x|Z_{k-1}) is a gamma density with
mean x* and variance Gamma_x (eqs. 7, 11), P0(a|Z_{k-1}) Gaussian (a*, Gamma_a)
(eqs. 12-14), P0(z|Z_{k-1}) gamma with the model's predicted mean z* and
variance Gamma_z (eqs. 8, 11).  Their orthonormal polynomials are the
normalised generalised Laguerre polynomials (eqs. 9-10) and the normalised
(probabilists') Hermite polynomials (eq. 15).  The expansion coefficients
A_lmn = <phi_l(x) phi_m(a) phi_n(z) | Z_{k-1}> (eq. 6) are needed for
l, m, n <= 2, the orders the paper uses: A_101, A_102, A_201 = 0, A_202,
A_011, A_012, A_021 = 0, A_022 (eqs. 24-31), and A_00n = delta_n0 because
P0(z) matches the model's first two moments.  Then::

    x^  = sum_l sum_n A_l0n c1l phi_n(z)        (16)    P_x = sum_l sum_n A_l0n c2l phi_n(z)   (18)
    a^  = sum_m sum_n A_0mn d1m phi_n(z)        (17)    P_a = sum_m sum_n A_0mn d2m phi_n(z)   (19)
    y^  = <y|Z_k> = y* + D11 phi_1(z) + D12 phi_2(z)                                           (21)
    P_y = <(y - y^)^2|Z_k>, the same expansion of (y - y^)^2                                    (22)

with c, d the coefficients of eq. (23) and D_jn = <y^j phi_n(z)|Z_{k-1}> (docs §4.4): the
paper defines y^ as <y|Z_k> but prints <<y|x>|Z_k> = e10 + a^ e11 theta1(x^), which ignores
what z = y + v says about y directly (kept as :func:`sound_estimate`).

Prediction (eqs. 32-38)::

    x_{k+1} = F x_k + G u_k,  F, G from the time correlation of x (33)
    x*_{k+1} = F x^_k + G <u>,   Gamma_x,{k+1} = F^2 P_x,k + G^2 (<u^2> - <u>^2)   (34, 35)
    a*_{k+1} = a^_k,             Gamma_a,{k+1} = P_a,k                               (36-38)

Eq. (33) is read with the fluctuation of x about its mean (docs §5): F is the
lag-1 autocorrelation coefficient of x, G^2 = (1 - F^2) var(x), and u has unit
variance and mean <u> = (1 - F) <x> / G, so the prediction relaxes towards the
mean vibration instead of towards zero (x is an energy-like, positive variable).

Deviations from the paper (docs §7), all engineering safeguards of a truncated
expansion that leave the equations untouched inside their range:

* the standardised observation zeta = (z - z*)/sqrt(Gamma_z) is limited to
  +-``zeta_max`` before it enters phi_1(z), phi_2(z) (a noise burst or a dead
  microphone would otherwise drive the second-order term without bound);
* the truncated expansions of eqs. (18)-(19) are not positive definite: for
  an unusual z they give a negative posterior variance, and the next gamma
  prior (eq. 11) would not exist; a single noise burst would also drive P_a
  to zero and freeze a for good.  P_x is kept in
  [``var_floor`` Gamma_x, Gamma_x] (the upper bound keeps the recursion of
  eq. 35 stable), P_a in [Gamma_a (1 - A_011^2 - A_012^2), Gamma_a]: the
  lower bound is exactly the mean of eq. (19) over P0(z) (docs §7), so a's
  variance never shrinks faster than the second-order estimator's average;
  x^ is kept >= ``x_floor`` * x* (the gamma prior needs x* > 0);
* the predicted machine sound energy <y|Z_{k-1}> is kept >= ``y_floor`` * e10
  and Gamma_z >= var <z|x, a> + var(v) (the truncated model's conditional
  variance can be negative far from the calibration data);
* the A's of one function are correlations of orthonormal functions, so
  sum_n A_l0n^2 <= 1 (Bessel); a model outside its range can break it, and
  the second-order coefficient is then reduced first; |a^| <= ``A_MAX``
  (a = B_11 is itself such a correlation); P_y of eq. (22) is kept >= 0, y^ >= ``y_floor`` e10,
  and D11^2 + D12^2 <= Gamma_y.

A missing observation (lost frame) is a prediction without an update.

Implementations:

* :class:`AcousticEstimator` — the estimator, state in arrays with a leading
  channel axis carried between calls (a stream can be split anywhere); the
  per-step arithmetic is plain Python floats (one or two microphone channels:
  faster than numpy per step).
* :func:`update_closed_form` — one update from the closed forms (eqs. 16-31).
* :func:`update_reference` — the same update computed by numerical quadrature
  of the definitions (eq. 6 truncated at l, m, n <= 2, the families of
  eqs. 9, 10, 15 from scipy.special): the plain reference the closed forms are
  tested against.
* :class:`AcousticEKF` — the EKF of the same model (state (x, a), observation
  <z|x, a>, noise variance var(z|x, a) at the prior mean), the paper's baseline.

Only numpy and the math module are used on the daemon's path; scipy.special
(orthonormal families, quadrature) is loaded by the reference and the tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

__all__ = [
    "AcousticModel",
    "AcousticBlock",
    "AcousticEstimator",
    "AcousticEKF",
    "Prior",
    "Posterior",
    "block_energy",
    "laguerre_phi",
    "hermite_phi",
    "expansion_coefficients",
    "update_closed_form",
    "update_reference",
    "predict",
    "Guards",
    "sound_estimate",
    "sound_coefficients",
    "sound_posterior",
]

SQRT2 = math.sqrt(2.0)


# ---------------------------------------------------------------------------
# the model (what calibration learns)
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class AcousticModel:
    """What seed 002 assumes known, learnt by :mod:`cmsensord.acoustic_calib`.

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

    # derived constants of the conditional moments of z (module docstring)
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


# ---------------------------------------------------------------------------
# the orthonormal families (eqs. 9, 10, 15), general order, for tests and docs
# ---------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------
# one update step: closed forms (eqs. 16-31)
# ---------------------------------------------------------------------------


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
    """The safeguards of the module docstring (docs §7).

    zeta_max: limit of |z - z*| / sqrt(Gamma_z); x_floor: x^ >= x_floor x*;
    y_floor: predicted machine sound >= y_floor e10; var_floor: the smallest
    fraction of the prior variance P_x keeps (and P_a, should the A's explain
    all of it).
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


NO_GUARDS = None  # pass guards=None to run the paper's equations without the safeguards


def _z_moments(model: AcousticModel, prior: Prior, y_floor: float | None):
    """z* = <z|Z_{k-1}>, Gamma_z and the prior means of theta_1(x), theta_2(x) (docs §4.1)."""
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
    z_pred, gz, T1, T2, A2 = _z_moments(model, prior, y_floor)
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
    ca = 1.0 / math.sqrt(2.0 * (1.0 + kz))
    cb = math.sqrt(2.0 * kz / (1.0 + kz))
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


#: |a^| is kept below this: a = B_11 = <theta1(x) theta1(y)> is a correlation of orthonormal functions
A_MAX = 0.99
_BESSEL = 1.0 - 1e-6


def _bessel(A: dict) -> dict:
    """Bessel's inequality for the A's of one function: sum_n A_l0n^2 <= <phi_l(x)^2> = 1 (and
    for a).  A model whose moments break it is outside its range (docs §7); the second-order
    coefficient gives way first."""
    A = dict(A)
    for k1, k2 in (("101", "102"), ("011", "012")):
        a1, a2 = A[k1], A[k2]
        if a1 * a1 + a2 * a2 > _BESSEL:
            if a1 * a1 >= _BESSEL:
                A[k1], A[k2] = math.copysign(math.sqrt(_BESSEL), a1), 0.0
            else:
                A[k2] = math.copysign(math.sqrt(_BESSEL - a1 * a1), a2)
    for k in ("202", "022"):
        if abs(A[k]) > _BESSEL:
            A[k] = math.copysign(_BESSEL, A[k])
    return A


def phi_z(zeta: float, kz: float) -> tuple[float, float]:
    """phi_1(z), phi_2(z) of eq. (10) in terms of zeta = (z - z*)/sqrt(Gamma_z), 1/m_z = kz."""
    ca = 1.0 / math.sqrt(2.0 * (1.0 + kz))
    cb = math.sqrt(2.0 * kz / (1.0 + kz))
    return -zeta, ca * (zeta * zeta - 1.0) - cb * zeta


def update_closed_form(model: AcousticModel, prior: Prior, z: float | None,
                       guards: Guards | None = Guards()) -> Posterior:
    """One update (eqs. 16-19, 21-22) from the closed forms of eqs. (24)-(31).

    ``z=None`` (no observation) returns the prior.  ``guards=None`` runs the
    paper's equations without the safeguards of docs §7.
    """
    yf = guards.y_floor if guards is not None else None
    co = expansion_coefficients(model, prior, y_floor=yf)
    A, z_pred, gz = co["A"], co["z_pred"], co["gz"]
    if guards is not None:
        A = _bessel(A)
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
        D = _bessel_y(D)
    y_hat, py = sound_posterior(D, f1, f2)                                                  # (21), (22)
    if guards is not None:
        y_hat = max(y_hat, guards.y_floor * abs(model.e10))   # a sound energy is > 0 (docs §7)
        py = max(py, 0.0)                  # eq. (22) is a truncated expansion too (docs §7)
    return Posterior(x=x_hat, px=px, a=a_hat, pa=pa, y=y_hat, py=py, z_pred=z_pred, gz=gz,
                     zeta=zeta, A=A)


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
    ca = 1.0 / math.sqrt(2.0 * (1.0 + kz))
    cb = math.sqrt(2.0 * kz / (1.0 + kz))
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


def _bessel_y(D: dict) -> dict:
    """Bessel's inequality for y: (D11^2 + D12^2)/Gamma_y <= 1 (the correlations of the
    standardised y with phi_1(z), phi_2(z)); the second-order coefficient gives way first."""
    D = dict(D)
    lim = _BESSEL * D["gy"]
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


def predict(model: AcousticModel, post: Posterior, guards: Guards | None = Guards()) -> Prior:
    """The prior of the next step, eqs. (34)-(35) and (37)-(38)."""
    x = model.F * post.x + model.G * model.u_mean                                          # (34)
    gx = model.F * model.F * post.px + model.G * model.G                                   # (35)
    if guards is not None:
        x = max(x, guards.x_floor * model.x_mean)
    return Prior(x=x, gx=gx, a=post.a, ga=post.pa)                                         # (37, 38)


# ---------------------------------------------------------------------------
# the plain reference: quadrature of the definitions (eq. 6)
# ---------------------------------------------------------------------------


def _z_poly_coeffs(order: int, z_pred: float, gz: float) -> np.ndarray:
    """Power-series coefficients (ascending) of phi_n(z), eq. (10), from scipy's genlaguerre."""
    from scipy.special import gammaln, genlaguerre

    m = z_pred * z_pred / gz
    s = gz / z_pred
    norm = math.exp(0.5 * (gammaln(m) + gammaln(order + 1.0) - gammaln(m + order)))
    c = genlaguerre(order, m - 1.0).coeffs[::-1]      # in powers of z / s
    return norm * c / s ** np.arange(order + 1)


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
    from scipy.special import roots_genlaguerre, roots_hermitenorm

    z_pred, gz, _, _, _ = _z_moments(model, prior, None)
    mx = prior.x * prior.x / prior.gx
    s_x = prior.gx / prior.x
    tx, wx = roots_genlaguerre(nodes, mx - 1.0)
    wx = wx / wx.sum()
    xs = s_x * tx                                        # nodes of the gamma prior of x
    ua, wa = roots_hermitenorm(nodes)
    wa = wa / wa.sum()
    as_ = prior.a + math.sqrt(prior.ga) * ua             # nodes of the Gaussian prior of a
    lam = np.asarray(model.lam1)
    th1 = lam[1, 0] + lam[1, 1] * xs
    th2 = lam[2, 0] + lam[2, 1] * xs + lam[2, 2] * xs * xs
    # conditional moments of z on the (a, x) grid
    zm1 = model.alpha0 + as_[:, None] * model.e11 * th1[None, :]
    zm2 = model.beta0 + as_[:, None] * model.beta1 * th1[None, :] \
        + (as_ * as_)[:, None] * model.p22 * th2[None, :]
    W = wa[:, None] * wx[None, :]
    phx = [laguerre_phi(l, xs, prior.x, prior.gx) for l in range(3)]
    pha = [hermite_phi(m, as_, prior.a, prior.ga) for m in range(3)] if prior.ga > 0 else \
        [np.ones_like(as_), np.zeros_like(as_), np.zeros_like(as_)]
    cond = []                                              # <phi_n(z) | x, a>
    for n in range(3):
        c = _z_poly_coeffs(n, z_pred, gz)
        mom = [np.ones_like(zm1), zm1, zm2]
        cond.append(sum(c[j] * mom[j] for j in range(n + 1)))
    A = np.zeros((3, 3, 3))
    for l in range(3):
        for m in range(3):
            for n in range(3):
                A[l, m, n] = np.sum(W * pha[m][:, None] * phx[l][None, :] * cond[n])
    if z is None:
        fz = np.array([1.0, 0.0, 0.0])
    else:
        fz = np.array([np.polyval(_z_poly_coeffs(n, z_pred, gz)[::-1], z) for n in range(3)])
    den = np.sum(A[0, 0, :] * fz)
    # c1l, c2l, d1m, d2m by projection: coefficient of phi_l = E[f phi_l]
    def proj_x(f):
        return np.array([np.sum(wx * f * phx[l]) for l in range(3)])

    def proj_a(f):
        return np.array([np.sum(wa * f * pha[m]) for m in range(3)])

    Sx = np.array([np.sum(A[l, 0, :] * fz) for l in range(3)]) / den
    Sa = np.array([np.sum(A[0, m, :] * fz) for m in range(3)]) / den
    c1 = proj_x(xs)
    x_hat = float(np.sum(c1[:2] * Sx[:2]))                                                 # (16)
    c2 = proj_x((xs - x_hat) ** 2)
    px = float(np.sum(c2 * Sx))                                                            # (18)
    d1 = proj_a(as_)
    a_hat = float(np.sum(d1[:2] * Sa[:2]))                                                 # (17)
    d2 = proj_a((as_ - a_hat) ** 2)
    pa = float(np.sum(d2 * Sa))                                                            # (19)
    # y (docs §4.4): D_jn = <y^j phi_n(z)>, from the prior moments of y on the same grid (third and
    # fourth central moments: the gamma density's), z = y + v with v independent
    my1 = float(np.sum(W * (zm1 - model.v1)))
    # (E[y^2] = E[<z^2|x,a>] - 2 <v> E[<z|x,a>] + 2 <v>^2 - <v^2>)
    ey2 = float(np.sum(W * zm2)) - 2.0 * model.v1 * float(np.sum(W * zm1)) + 2.0 * model.v1 ** 2 - model.v2
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
    Ad = {f"{l}{m}{n}": float(A[l, m, n]) for l in range(3) for m in range(3) for n in range(3)}
    return Posterior(x=x_hat, px=px, a=a_hat, pa=pa, y=y_hat, py=py, z_pred=z_pred, gz=gz,
                     zeta=math.nan if z is None else (z - z_pred) / math.sqrt(gz), A=Ad)


# ---------------------------------------------------------------------------
# streams: the estimator and the EKF over (T, C) blocks
# ---------------------------------------------------------------------------


def block_energy(samples: np.ndarray, block_len: int) -> np.ndarray:
    """z_k: the mean square of each whole block of ``block_len`` samples (last axis).

    ``samples`` (..., n) in physical units (Pa); returns (..., n // block_len).
    """
    samples = np.asarray(samples, dtype=np.float64)
    n = samples.shape[-1]
    if block_len < 1 or n % block_len:
        raise ValueError(f"samples must hold whole blocks of {block_len} samples, got {n}")
    b = samples.reshape(samples.shape[:-1] + (n // block_len, block_len))
    return np.mean(b * b, axis=-1)


@dataclass
class AcousticBlock:
    """Per-block outputs, shape (T, C); NaN where a channel has no estimate yet."""

    x_hat: np.ndarray
    P_x: np.ndarray
    a_hat: np.ndarray
    P_a: np.ndarray
    y_hat: np.ndarray
    P_y: np.ndarray
    z_pred: np.ndarray     # z*_k, the predicted observation
    valid: np.ndarray      # bool: an observation was used (else prediction only)


def _as_tc(z: np.ndarray, C: int, valid) -> tuple[np.ndarray, np.ndarray]:
    z = np.asarray(z, dtype=np.float64)
    if z.ndim == 1 and C == 1:
        z = z[:, None]
    if z.ndim != 2 or z.shape[1] != C:
        raise ValueError(f"z: expected shape (T, {C}), got {z.shape}")
    ok = np.isfinite(z)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != z.shape:
            raise ValueError(f"valid: expected shape {z.shape}, got {valid.shape}")
        ok &= valid
    return z, ok


def _empty_block(T: int, C: int, valid: np.ndarray) -> AcousticBlock:
    return AcousticBlock(*(np.full((T, C), np.nan) for _ in range(7)), valid=valid)


class AcousticEstimator:
    """The seed-002 estimator for C microphone channels, one model each.

    ``process(z, valid)`` runs T blocks of sound energy (T, C); the priors
    (x*, Gamma_x, a*, Gamma_a per channel) are carried between calls, so any
    split of the stream gives the same estimates as one pass.
    """

    def __init__(self, models, guards: Guards | None = Guards()):
        if isinstance(models, AcousticModel):
            models = [models]
        self.models = list(models)
        if not self.models:
            raise ValueError("need at least one AcousticModel")
        self.C = len(self.models)
        self.guards = guards
        self.reset()

    def reset(self) -> None:
        m = self.models
        self.x = np.array([mm.x0 for mm in m])      # x*_k
        self.gx = np.array([mm.gx0 for mm in m])    # Gamma_x,k
        self.a = np.array([mm.a0 for mm in m])      # a*_k
        self.ga = np.array([mm.ga0 for mm in m])    # Gamma_a,k

    def state(self) -> dict:
        return {k: getattr(self, k).copy() for k in ("x", "gx", "a", "ga")}

    def process(self, z, valid=None) -> AcousticBlock:
        z, ok = _as_tc(z, self.C, valid)
        T = z.shape[0]
        out = _empty_block(T, self.C, ok)
        g = self.guards
        for c, model in enumerate(self.models):
            prior = Prior(float(self.x[c]), float(self.gx[c]), float(self.a[c]), float(self.ga[c]))
            zc, okc = z[:, c].tolist(), ok[:, c].tolist()
            rows = []
            for k in range(T):
                post = update_closed_form(model, prior, zc[k] if okc[k] else None, g)
                rows.append((post.x, post.px, post.a, post.pa, post.y, post.py, post.z_pred))
                prior = predict(model, post, g)
            if rows:
                arr = np.array(rows)
                for j, name in enumerate(("x_hat", "P_x", "a_hat", "P_a", "y_hat", "P_y", "z_pred")):
                    getattr(out, name)[:, c] = arr[:, j]
            self.x[c], self.gx[c], self.a[c], self.ga[c] = prior.x, prior.gx, prior.a, prior.ga
        return out


class AcousticEKF:
    """The extended Kalman filter of the same model (the paper's baseline, ref. [11]).

    State s = (x, a); transition x_{k+1} = F x_k + G u_k, a_{k+1} = a_k (eqs.
    32-36); observation z = <z|x, a> + noise = alpha0 + a alpha1 theta1(x) + w
    with var(w) = var(z|x, a) = <z^2|x, a> - <z|x, a>^2 at the prior mean
    (floored at var(v)).  Linearised at the prior mean:
    H = (a* alpha1 lambda11, alpha1 theta1(x*)).  ``sound="posterior"``: y^, P_y the EKF's
    <y|Z_k> with y = <y|x, a> + w_y in the state (docs §8); ``sound="eq21"``: the printed
    eqs. (21)-(22) from the EKF's x^, a^.  No safeguards (a plain EKF).
    """

    def __init__(self, models, sound: str = "posterior"):
        if isinstance(models, AcousticModel):
            models = [models]
        if sound not in ("posterior", "eq21"):
            raise ValueError(f"sound must be 'posterior' or 'eq21', got {sound!r}")
        self.models = list(models)
        self.C = len(self.models)
        self.sound = sound
        self.reset()

    def reset(self) -> None:
        self.s = np.array([[m.x0, m.a0] for m in self.models])                   # (C, 2)
        self.P = np.array([[[m.gx0, 0.0], [0.0, m.ga0]] for m in self.models])   # (C, 2, 2)

    def process(self, z, valid=None) -> AcousticBlock:
        z, ok = _as_tc(z, self.C, valid)
        T = z.shape[0]
        out = _empty_block(T, self.C, ok)
        for c, m in enumerate(self.models):
            (l10, l11, _), (l20, l21, l22) = m.lam1[1], m.lam1[2]
            x, a = float(self.s[c, 0]), float(self.s[c, 1])
            pxx, pxa, paa = float(self.P[c, 0, 0]), float(self.P[c, 0, 1]), float(self.P[c, 1, 1])
            zc, okc = z[:, c].tolist(), ok[:, c].tolist()
            rows = []
            for k in range(T):
                t1 = l10 + l11 * x
                t2 = l20 + l21 * x + l22 * x * x
                h = m.alpha0 + a * m.e11 * t1
                var_z = m.beta0 + a * m.beta1 * t1 + a * a * m.p22 * t2 - h * h
                R = max(var_z, m.var_v, 1e-12 * h * h)
                Hx, Ha = a * m.e11 * l11, m.e11 * t1
                PHx = pxx * Hx + pxa * Ha
                PHa = pxa * Hx + paa * Ha
                HPH = Hx * PHx + Ha * PHa
                # y = <y|x, a> + w_y (var w_y = R - var v), z = y + v: y in the state (docs §8)
                cyz = HPH + R - m.var_v                     # prior var y = cov(y, z)
                y_hat, py = h - m.v1, cyz
                if okc[k]:
                    S = HPH + R
                    Kx, Ka = PHx / S, PHa / S
                    innov = zc[k] - h
                    x, a = x + Kx * innov, a + Ka * innov
                    y_hat, py = y_hat + cyz / S * innov, cyz - cyz * cyz / S
                    # Joseph form (I - K H) P (I - K H)' + K R K'
                    i00, i01 = 1.0 - Kx * Hx, -Kx * Ha
                    i10, i11 = -Ka * Hx, 1.0 - Ka * Ha
                    n00 = i00 * pxx + i01 * pxa
                    n01 = i00 * pxa + i01 * paa
                    n10 = i10 * pxx + i11 * pxa
                    n11 = i10 * pxa + i11 * paa
                    pxx = n00 * i00 + n01 * i01 + Kx * Kx * R
                    pxa = n00 * i10 + n01 * i11 + Kx * Ka * R
                    paa = n10 * i10 + n11 * i11 + Ka * Ka * R
                if self.sound == "eq21":
                    y_hat, py = sound_estimate(m, x, pxx, a, paa)
                rows.append((x, pxx, a, paa, y_hat, py, h))
                # prediction (32)-(38)
                x = m.F * x + m.G * m.u_mean
                pxx = m.F * m.F * pxx + m.G * m.G
                pxa = m.F * pxa
            if rows:
                arr = np.array(rows)
                for j, name in enumerate(("x_hat", "P_x", "a_hat", "P_a", "y_hat", "P_y", "z_pred")):
                    getattr(out, name)[:, c] = arr[:, j]
            self.s[c] = (x, a)
            self.P[c] = ((pxx, pxa), (pxa, paa))
        return out
