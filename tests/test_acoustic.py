"""Orimoto, Ikuta & Wang: the acoustic estimator (cmsensord.dsp.acoustic) and its calibration.

- the Laguerre (eqs. 9-10) and Hermite (eq. 15) families are orthonormal under
  their weights (Gauss quadrature);
- the closed forms of eqs. (16)-(31) equal a plain quadrature of the
  definitions (eq. 6 truncated at l, m, n <= 2), and the paper's readable
  closed forms (eqs. 24, 25, 27, 28);
- the update reduces to the prior when z carries no information;
- estimates stay finite and positive under silence, clipping and noise bursts;
- processing a stream in pieces equals one pass (estimator and EKF);
- on data drawn from the paper's own model the estimator beats the EKF;
- calibration recovers known parameters; calibration files round-trip, and a bad
  file is a one-line ConfigError naming the file and the key.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from cmsensord.acoustic_calib import (
    Calibration,
    cross_term_variance,
    fit_model,
    load_calibration,
    save_calibration,
    schmidt,
)
from cmsensord.dsp.acoustic import (
    AcousticEKF,
    AcousticEstimator,
    AcousticModel,
    Guards,
    Prior,
    block_energy,
    expansion_coefficients,
    hermite_phi,
    laguerre_phi,
    phi_z,
    update_closed_form,
    update_reference,
)
from cmsensord.errors import ConfigError

# --------------------------------------------------------------------------- helpers

def kibble(N, *, n=4, rho2=0.8, phi2=0.9, v_shape=2.0, v_mean=0.5, seed=0):
    """Data from the paper's own model: x, y energies of n correlated Gaussian components
    (Kibble's bivariate gamma: B_rr = a^r with a = rho^2), AR(1) components (F = phi^2),
    gamma background v."""
    rng = np.random.default_rng(seed)
    phi, rho = math.sqrt(phi2), math.sqrt(rho2)
    X = np.empty((N, n))
    X[0] = rng.standard_normal(n)
    e = rng.standard_normal((N, n)) * math.sqrt(1 - phi2)
    for k in range(1, N):
        X[k] = phi * X[k - 1] + e[k]
    Y = rho * X + math.sqrt(1 - rho2) * rng.standard_normal((N, n))
    x = np.sum(X ** 2, axis=1) / n
    y = np.sum(Y ** 2, axis=1) / n
    v = rng.gamma(v_shape, v_mean / v_shape, N)
    return x, y, v


@pytest.fixture(scope="module")
def model() -> AcousticModel:
    x, y, v = kibble(100_000, seed=1)
    _, _, vb = kibble(50_000, seed=2)
    return fit_model(x, y + v, vb).model


PRIORS = [Prior(1.0, 0.3, 0.8, 0.01), Prior(0.6, 0.05, 0.5, 0.04), Prior(1.8, 1.2, 0.9, 1e-4),
          Prior(1.1, 0.2, -0.3, 0.02)]


# --------------------------------------------------------------------------- families

@pytest.mark.parametrize("mean,var", [(1.0, 0.5), (0.7, 0.01), (3.0, 6.0), (0.2, 0.1)])
def test_laguerre_family_is_orthonormal_under_the_gamma_prior(mean, var):
    from scipy.special import roots_genlaguerre

    m, s = mean * mean / var, var / mean
    t, w = roots_genlaguerre(30, m - 1.0)
    w = w / w.sum()                                   # the gamma density (eq. 7) as weights
    x = s * t
    G = np.array([[np.sum(w * laguerre_phi(i, x, mean, var) * laguerre_phi(j, x, mean, var))
                   for j in range(5)] for i in range(5)])
    np.testing.assert_allclose(G, np.eye(5), atol=1e-9)
    # the weights are the gamma density with this mean and variance
    assert np.sum(w * x) == pytest.approx(mean) and np.sum(w * (x - mean) ** 2) == pytest.approx(var)


@pytest.mark.parametrize("mean,var", [(0.0, 1.0), (0.8, 0.01), (-2.0, 4.0)])
def test_hermite_family_is_orthonormal_under_the_gaussian_prior(mean, var):
    from scipy.special import roots_hermitenorm

    u, w = roots_hermitenorm(30)
    w = w / w.sum()
    a = mean + math.sqrt(var) * u
    G = np.array([[np.sum(w * hermite_phi(i, a, mean, var) * hermite_phi(j, a, mean, var))
                   for j in range(5)] for i in range(5)])
    np.testing.assert_allclose(G, np.eye(5), atol=1e-9)


@pytest.mark.parametrize("mean,var", [(1.0, 0.5), (0.02, 1e-5), (5.0, 0.01)])
def test_phi_z_in_standardised_form_equals_eq_10(mean, var):
    z = mean + math.sqrt(var) * np.linspace(-3, 3, 13)
    zeta = (z - mean) / math.sqrt(var)
    f1, f2 = phi_z(zeta, var / mean ** 2)
    np.testing.assert_allclose(f1, laguerre_phi(1, z, mean, var), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(f2, laguerre_phi(2, z, mean, var), rtol=1e-9, atol=1e-9)


# --------------------------------------------------------------------------- the update

@pytest.mark.parametrize("prior", PRIORS)
def test_closed_forms_equal_quadrature_of_the_definitions(model, prior):
    ref0 = update_reference(model, prior, None)
    co = expansion_coefficients(model, prior)
    for key, val in co["A"].items():                   # eqs. (24)-(31)
        assert val == pytest.approx(ref0.A[key], rel=1e-8, abs=1e-10), key
    # A_00n = delta_n0: P0(z) matches the model's first two moments of z
    assert ref0.A["000"] == pytest.approx(1.0)
    assert abs(ref0.A["001"]) < 1e-9 and abs(ref0.A["002"]) < 1e-9
    for q in (-2.0, -0.5, 0.0, 0.7, 2.5):
        z = co["z_pred"] + q * math.sqrt(co["gz"])
        got = update_closed_form(model, prior, z, guards=None)
        ref = update_reference(model, prior, z)
        for f in ("x", "px", "a", "pa", "y", "py"):
            assert getattr(got, f) == pytest.approx(getattr(ref, f), rel=1e-8, abs=1e-12), (f, q)


@pytest.mark.parametrize("prior", PRIORS[:3])
def test_the_papers_readable_closed_forms(model, prior):
    """Eqs. (24), (25), (27), (28) as printed, in the paper's m*, s* notation."""
    A = expansion_coefficients(model, prior)
    co = A["A"]
    zs, gz = A["z_pred"], A["gz"]
    mx, sx = prior.x ** 2 / prior.gx, prior.gx / prior.x
    mz, sz = zs ** 2 / gz, gz / zs
    (l10, l11, _), (_, l21, l22) = model.lam1[1], model.lam1[2]
    a, ga = prior.a, prior.ga
    A2 = ga + a * a
    e11, p21, p22, v1 = model.e11, model.p21, model.p22, model.v1
    assert co["101"] == pytest.approx(math.sqrt(mx / mz) / sz * a * e11 * l11 * sx)          # (24)
    a102 = -math.sqrt(2.0 / (mx * mz * (mz + 1))) * mx * (
        (mx + 1) / sz ** 2 * A2 * p22 * l22 * sx ** 2 - (mz + 1) / sz * a * e11 * l11 * sx
        + 1.0 / (2 * sz ** 2) * (a * p21 * l11 * sx + A2 * p22 * l21 * sx + 2 * a * e11 * l11 * sx * v1))
    assert co["102"] == pytest.approx(a102, rel=1e-7)                                         # (25)
    a202 = math.sqrt(mx * (mx + 1) / (mz * (mz + 1))) / sz ** 2 * A2 * p22 * l22 * sx ** 2
    assert co["202"] == pytest.approx(a202, rel=1e-9)                                         # (27)
    # (28): the printed last line lost the minus sign of the line before it (docs §4.3)
    assert co["011"] == pytest.approx(-math.sqrt(1 / mz) / sz * math.sqrt(ga) * e11 * (l10 + l11 * prior.x))
    assert co["201"] == 0.0 and co["021"] == 0.0                                               # (26), (30)


@pytest.mark.parametrize("prior", PRIORS)
def test_update_is_the_prior_when_z_carries_no_information(model, prior):
    # a = 0 exactly (no sound-vibration correlation, no doubt about it): z says nothing
    none = Prior(prior.x, prior.gx, 0.0, 0.0)
    for z in (0.1, 1.0, 3.0, 40.0):
        for guards in (None, Guards()):
            post = update_closed_form(model, none, z, guards)
            assert (post.x, post.px, post.a, post.pa) == pytest.approx((none.x, none.gx, 0.0, 0.0), abs=1e-15)
    # no observation (lost frame): the prior
    post = update_closed_form(model, prior, None)
    assert (post.x, post.px, post.a, post.pa) == (prior.x, prior.gx, prior.a, prior.ga)
    # background noise ever louder and more variable: the update fades to the prior
    moves = []
    for scale in (1.0, 1e2, 1e4, 1e6):
        noisy = dataclasses.replace(model, v1=model.v1 * scale, v2=model.v2 * scale ** 2 * 4)
        co = expansion_coefficients(noisy, prior)
        post = update_closed_form(noisy, prior, co["z_pred"] + 1.5 * math.sqrt(co["gz"]), None)
        moves.append(abs(post.x - prior.x) + abs(post.a - prior.a))
    assert moves[-1] < 1e-3 * moves[0] and all(b < a for a, b in zip(moves, moves[1:]))


def _all_finite_positive(out):
    for f in ("x_hat", "P_x", "a_hat", "P_a", "y_hat", "P_y"):
        assert np.all(np.isfinite(getattr(out, f))), f
    assert np.all(out.x_hat > 0) and np.all(out.P_x > 0) and np.all(out.P_a >= 0)


def test_estimates_stay_finite_and_positive_under_silence_clipping_and_bursts(model):
    _, y, v = kibble(3000, seed=5)
    z = y + v
    ref = AcousticEstimator(model).process(z)
    typical = float(np.median(ref.x_hat))
    cases = {
        "silence": np.r_[z[:500], np.zeros(1000), z[1500:]],          # a dead microphone
        "clipping": np.r_[z[:500], np.full(1000, 50 * z.max()), z[1500:]],   # saturated preamp
        "bursts": z * np.where(np.arange(3000) % 97 < 3, 1e4, 1.0),    # door slams
        "tiny": np.full(3000, 1e-300),
        "huge": np.full(3000, 1e300),
    }
    for name, zz in cases.items():
        out = AcousticEstimator(model).process(zz)
        _all_finite_positive(out)
        if name in ("silence", "clipping"):
            # back to normal once the microphone is: within 20 % of the reference estimate level
            assert np.median(out.x_hat[2500:, 0]) == pytest.approx(np.median(ref.x_hat[2500:, 0]), rel=0.2)
    assert typical > 0


@pytest.mark.parametrize("cls", [AcousticEstimator, AcousticEKF])
def test_processing_in_pieces_equals_one_pass(model, cls):
    _, y, v = kibble(1200, seed=7)
    z = np.stack([y + v, 1.3 * (y + v)], axis=1)
    z[100:103, 0] = np.nan                                # lost frames: prediction only
    valid = np.ones_like(z, dtype=bool)
    valid[500, 1] = False
    m2 = dataclasses.replace(model, e10=model.e10 * 1.3, e11=model.e11 * 1.3, p20=model.p20 * 1.69,
                             p21=model.p21 * 1.69, p22=model.p22 * 1.69)
    one = cls([model, m2]).process(z, valid)
    f = cls([model, m2])
    rng = np.random.default_rng(3)
    cuts = np.sort(rng.choice(np.arange(1, 1200), 7, replace=False))
    parts = [f.process(z[a:b], valid[a:b]) for a, b in zip(np.r_[0, cuts], np.r_[cuts, 1200])]
    parts.append(f.process(z[:0], valid[:0]))            # an empty call changes nothing
    for name in ("x_hat", "P_x", "a_hat", "P_a", "y_hat", "P_y"):
        assert np.array_equal(np.concatenate([getattr(p, name) for p in parts]), getattr(one, name)), name
    assert not one.valid[100, 0] and not one.valid[500, 1]
    # a lost observation is a prediction: x^ there is the predicted x*
    assert one.x_hat[101, 0] == pytest.approx(model.F * one.x_hat[100, 0] + model.G * model.u_mean)


def test_on_the_papers_own_model_the_estimator_beats_the_ekf(model):
    """Data with the structure the paper assumes (Kibble bivariate gamma: B_rr = a^r; gamma
    energies; AR(1)): 48 sets of 250 observations, each filter restarted per set.  Vibration
    and sound (dB error of y^, Table 2), against the EKF with either sound estimate."""
    x, y, v = kibble(12_000, seed=3)
    z = y + v
    makes = {"est": AcousticEstimator, "ekf": AcousticEKF, "ekf21": lambda m: AcousticEKF(m, sound="eq21")}
    ex = {k: [] for k in makes}
    ey = {k: [] for k in makes}
    for i in range(48):
        sl = slice(250 * i, 250 * i + 250)
        for key, make in makes.items():
            out = make(model).process(z[sl])
            ex[key].append(np.sqrt(np.mean((out.x_hat[:, 0] - x[sl]) ** 2)))
            yh = np.maximum(out.y_hat[:, 0], 1e-12)
            ey[key].append(np.sqrt(np.mean((10 * np.log10(yh / y[sl])) ** 2)))
    ex = {k: np.array(a) for k, a in ex.items()}
    ey = {k: np.array(a) for k, a in ey.items()}
    rms = lambda a: np.sqrt(np.mean(a ** 2))  # noqa: E731
    assert rms(ex["est"]) < rms(ex["ekf"])
    assert np.sum(ex["est"] < ex["ekf"]) >= 30
    for k in ("ekf", "ekf21"):                                      # sound: >= 10 of 12 sets
        assert rms(ey["est"]) < rms(ey[k]), k
        assert np.sum(ey["est"] < ey[k]) >= 40, k


def _brute_force_posterior(model, prior, zs):
    """E[x|z], E[a|z], E[y|z] by quadrature of Bayes' theorem on a grid, one step: x gamma
    (x*, Gamma_x), a Gaussian (a*, Gamma_a), y | x, a gamma with the model's conditional mean
    and variance (docs §2), v gamma with <v>, var v, z = y + v.  Grid nodes where the truncated
    model's conditional variance is not positive are left out (their prior weight is returned)."""
    from scipy.special import roots_genlaguerre, roots_hermitenorm
    from scipy.stats import gamma

    tx, wx = roots_genlaguerre(40, prior.x ** 2 / prior.gx - 1.0)
    xs, wx = prior.gx / prior.x * tx, wx / wx.sum()
    ua, wa = roots_hermitenorm(30)
    as_, wa = prior.a + math.sqrt(prior.ga) * ua, wa / wa.sum()
    lam = np.asarray(model.lam1)
    th1 = lam[1, 0] + lam[1, 1] * xs
    th2 = lam[2, 0] + lam[2, 1] * xs + lam[2, 2] * xs * xs
    mu = model.e10 + as_[:, None] * model.e11 * th1[None, :]
    m2 = model.p20 + as_[:, None] * model.p21 * th1[None, :] + (as_ ** 2)[:, None] * model.p22 * th2[None, :]
    s2 = m2 - mu * mu
    W = wa[:, None] * wx[None, :]
    ok = (mu > 0) & (s2 > 0.01 * mu * mu)
    left_out = float(W[~ok].sum())
    W, mu, s2 = np.where(ok, W, 0.0), np.where(ok, mu, 1.0), np.where(ok, s2, 1.0)
    vk, vs = model.v1 ** 2 / model.var_v, model.var_v / model.v1
    out = []
    for z in zs:
        yy = np.linspace(0.0, z, 3001)[1:-1]
        joint = W[:, :, None] * gamma.pdf(yy, (mu * mu / s2)[:, :, None], scale=(s2 / mu)[:, :, None]) \
            * gamma.pdf(z - yy, vk, scale=vs)[None, None, :]
        Z = joint.sum()
        out.append((float(joint.sum((0, 2)) @ xs / Z), float(joint.sum((1, 2)) @ as_ / Z),
                    float(joint.sum((0, 1)) @ yy / Z)))
    return out, left_out


@pytest.mark.parametrize("prior", [Prior(1.0, 0.3, 0.8, 0.002), Prior(0.6, 0.05, 0.5, 0.04)])
def test_update_matches_the_numerical_posterior_of_x_a_and_y(model, prior):
    """One step on the paper's own model: x^, a^ and y^ = <y|Z_k> equal the posterior means of a
    brute-force Bayes update to the truncation's accuracy; eq. (21) as printed, <<y|x>|Z_k>,
    misses the information z = y + v carries about y directly (docs §4.4)."""
    from cmsensord.dsp.acoustic import sound_estimate

    co = expansion_coefficients(model, prior)
    sz = math.sqrt(co["gz"])
    sy = math.sqrt(co["gz"] - model.var_v)
    qs = (-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5)
    ref, left_out = _brute_force_posterior(model, prior, [co["z_pred"] + q * sz for q in qs])
    assert left_out < 0.02
    for q, (bx, ba, by) in zip(qs, ref):
        got = update_closed_form(model, prior, co["z_pred"] + q * sz, guards=None)
        assert abs(got.x - bx) < 0.05 * math.sqrt(prior.gx), q
        assert abs(got.a - ba) < 0.15 * math.sqrt(prior.ga), q
        assert abs(got.y - by) < 0.05 * sy, q
        if abs(q) >= 1.0:                                             # the printed eq. (21)
            y21 = sound_estimate(model, got.x, got.px, got.a, got.pa)[0]
            assert abs(y21 - by) > 0.25 * sy, q


def test_block_energy_is_the_mean_square_per_block():
    s = np.arange(12.0).reshape(1, 12)
    np.testing.assert_allclose(block_energy(s, 4), [[np.mean(s[0, :4] ** 2), np.mean(s[0, 4:8] ** 2),
                                                      np.mean(s[0, 8:] ** 2)]])
    with pytest.raises(ValueError, match="whole blocks of 5"):
        block_energy(s, 5)


def test_model_rejects_impossible_values(model):
    with pytest.raises(ValueError, match="F: must lie in"):
        dataclasses.replace(model, F=1.0)
    with pytest.raises(ValueError, match="lam1: expected a 3x3"):
        dataclasses.replace(model, lam1=((1.0,),))
    with pytest.raises(ValueError, match="background moments"):
        dataclasses.replace(model, v2=model.v1 ** 2 / 2)


# --------------------------------------------------------------------------- calibration

def test_schmidt_gives_orthonormal_polynomials_under_the_sample():
    x = np.random.default_rng(0).gamma(3.0, 0.5, 5000)
    lam = schmidt([np.mean(x ** j) for j in range(5)])
    th = np.stack([lam[r, 0] + lam[r, 1] * x + lam[r, 2] * x * x for r in range(3)])
    np.testing.assert_allclose(th @ th.T / x.size, np.eye(3), atol=1e-9)


def test_calibration_recovers_the_parameters_of_known_data():
    n, rho2, phi2 = 8, 0.7, 0.85
    x, y, v = kibble(200_000, n=n, rho2=rho2, phi2=phi2, seed=11)
    _, _, vb = kibble(200_000, n=n, seed=12)
    cal = fit_model(x, y + v, vb)
    m = cal.model
    assert m.a0 == pytest.approx(rho2, abs=0.02)               # B_11 = rho^2 (Kibble)
    assert cal.info["B22"] == pytest.approx(rho2 ** 2, abs=0.05)
    assert m.F == pytest.approx(phi2, abs=0.01)
    assert m.e10 == pytest.approx(1.0, rel=0.01) and m.e11 == pytest.approx(math.sqrt(2 / n), rel=0.03)
    assert m.v1 == pytest.approx(0.5, rel=0.01) and m.v2 == pytest.approx(0.25 * 1.5, rel=0.03)
    assert m.x_mean == pytest.approx(np.mean(x))
    assert cal.info["method"] == "regression" and cal.info["cross_var"] == 0.0
    # y's polynomials are orthonormal under the true y
    lam2 = np.asarray(m.lam2)
    th = np.stack([lam2[r, 0] + lam2[r, 1] * y + lam2[r, 2] * y * y for r in range(3)])
    np.testing.assert_allclose(th @ th.T / y.size, np.eye(3), atol=0.05)


def test_calibration_rejects_unusable_data():
    x, y, v = kibble(2000, seed=1)
    with pytest.raises(ValueError, match="need at least 500 blocks"):
        fit_model(x[:100], (y + v)[:100], v)
    with pytest.raises(ValueError, match="machine sound is not identifiable"):
        fit_model(x, y + v, 10 * v)                             # background louder than the capture
    with pytest.raises(ValueError, match="same length"):
        fit_model(x, (y + v)[:-1], v)
    with pytest.raises(ValueError, match="x: blocks must be finite"):
        fit_model(np.r_[x[:-1], np.nan], y + v, v)
    with pytest.raises(ValueError, match="cross_var"):
        fit_model(x, y + v, v, cross_var=-1.0)


def test_calibrated_model_reproduces_the_conditional_mean_and_variance_of_z():
    """docs §6: <z|x, a0> and var(z|x, a0) of the model are the least-squares fits of z and of the
    squared residual on theta_0..2(x), and the cross-term variance enters as observation noise."""
    x, y, v = kibble(50_000, seed=3)
    _, _, vb = kibble(50_000, seed=4)
    z = y + v
    m0 = fit_model(x, z, vb).model
    m1 = fit_model(x, z, vb, cross_var=0.01).model
    lam = np.asarray(m0.lam1)
    th1 = lam[1, 0] + lam[1, 1] * x
    th2 = lam[2, 0] + lam[2, 1] * x + lam[2, 2] * x * x
    mean = m0.alpha0 + m0.a0 * m0.e11 * th1
    var = m0.beta0 + m0.a0 * m0.beta1 * th1 + m0.a0 ** 2 * m0.p22 * th2 - mean ** 2
    r2 = (z - mean) ** 2
    basis = np.stack([np.ones_like(x), th1, th2])
    np.testing.assert_allclose(basis @ r2 / x.size, basis @ var / x.size, rtol=1e-8, atol=1e-12)
    assert np.mean(z - mean) == pytest.approx(0.0, abs=1e-12)
    # the same fit, with 0.01 moved from the machine sound's variance to the noise
    assert m1.var_v == pytest.approx(m0.var_v + 0.01)
    assert m1.e11 ** 2 == pytest.approx(m0.e11 ** 2 - 0.01)
    assert m1.a0 * m1.e11 == pytest.approx(m0.a0 * m0.e11)


def test_cross_term_variance_of_independent_waveforms():
    rng = np.random.default_rng(5)
    L = 250
    m = rng.standard_normal((3000, L)) * 0.3             # machine sound, white

    def b(n):                                           # background, white
        return rng.standard_normal((n, L)) * 0.1

    # 2<m b> over L white samples: variance 4 var(m) var(b) / L
    est = cross_term_variance(m + b(3000), b(3000))
    assert est == pytest.approx(4 * 0.09 * 0.01 / L, rel=0.1)
    assert cross_term_variance(b(500), b(500)) < 0.2 * 4 * 0.09 * 0.01 / L


def test_calibration_file_round_trips(tmp_path, model):
    path = tmp_path / "cal.json"
    save_calibration(Calibration(model, {"note": "test"}), path)
    assert load_calibration(path) == model


@pytest.mark.parametrize("edit,key,reason", [
    (lambda d: d["model"].update(F=1.5), "model.F", "must lie in (-1, 1)"),
    (lambda d: d["model"].pop("e11"), "model.e11", "missing"),
    (lambda d: d["model"].update(colour=1), "model.colour", "unknown key"),
    (lambda d: d["model"].update(G="x"), "model.G", "expected a finite number"),
    (lambda d: d.update(format="other"), "format", "not an acoustic calibration"),
    (lambda d: d.update(version=9), "version", "unsupported version"),
])
def test_bad_calibration_file_is_one_line_config_error(tmp_path, model, edit, key, reason):
    path = tmp_path / "cal.json"
    save_calibration(Calibration(model, {}), path)
    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))
    with pytest.raises(ConfigError) as err:
        load_calibration(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: {key}: ") and reason in msg and "\n" not in msg


def test_unreadable_calibration_files(tmp_path):
    with pytest.raises(ConfigError, match="calibration file not found"):
        load_calibration(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json")
    with pytest.raises(ConfigError, match=r"not JSON: .* line 1"):
        load_calibration(bad)
