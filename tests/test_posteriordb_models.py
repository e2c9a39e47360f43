"""The posteriordb models of ``benchmarks/posteriordb_models.py`` are the Stan programs.

For every posterior, at reference draws (Stan's, shipped in ``benchmarks/data/posteriordb``):
the model's sites give exactly the reference keys; mapping a draw to NumPyro's unconstrained
space and back (``postprocess_fn``, deterministic sites included) reproduces it; NumPyro's
potential energy there is finite; and the NumPyro log joint differs from the Stan program's
``target`` (written again below with SciPy, line by line from the ``.stan`` code shipped with
the data) by one constant across draws. The reference draws carry no ``lp__``, so this second,
independent transcription stands in for Stan's own log density.
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

pytest.importorskip("numpyro")

from numpyro.infer.util import initialize_model, log_density, unconstrain_fn

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root

from benchmarks import posteriordb_models as pdb


def _normal(x, loc, scale):
    return np.sum(stats.norm.logpdf(x, loc, scale))


def stan_eight_schools(d, p):
    theta = p["theta_trans"] * p["tau"] + p["mu"]
    return (
        _normal(p["theta_trans"], 0, 1)
        + _normal(d["y"], theta, d["sigma"])
        + _normal(p["mu"], 0, 5)
        + stats.cauchy.logpdf(p["tau"], 0, 5)
    )


def stan_ark(d, p):
    y, lags = d["y_now"], d["lags"]  # y[t], and y[t - k] in column k - 1
    mu = p["alpha"] + sum(p["beta"][k] * lags[:, k] for k in range(lags.shape[1]))
    return (
        _normal(p["alpha"], 0, 10)
        + _normal(p["beta"], 0, 10)
        + stats.cauchy.logpdf(p["sigma"], 0, 2.5)
        + _normal(y, mu, p["sigma"])
    )


def stan_gp_pois_regr(d, p):
    x = d["x"]
    cov = p["alpha"] ** 2 * np.exp(-0.5 * np.subtract.outer(x, x) ** 2 / p["rho"] ** 2)
    f = np.linalg.cholesky(cov + 1e-10 * np.eye(len(x))) @ p["f_tilde"]
    return (
        stats.gamma.logpdf(p["rho"], 25, scale=1 / 4)
        + _normal(p["alpha"], 0, 2)
        + _normal(p["f_tilde"], 0, 1)
        + np.sum(stats.poisson.logpmf(d["k"], np.exp(f)))
    )


def stan_kidscore_momiq(d, p):
    mean = p["beta"][0] + p["beta"][1] * d["mom_iq"]
    return stats.cauchy.logpdf(p["sigma"], 0, 2.5) + _normal(d["kid_score"], mean, p["sigma"])


def stan_logmesquite(d, p):
    # predictors: log diam1, log diam2, log canopy height, log total height, log density, group
    b, x = p["beta"], d["predictors"]
    mean = b[0] + sum(b[j + 1] * x[:, j] for j in range(6))
    return _normal(d["log_weight"], mean, p["sigma"])


def stan_garch11(d, p):
    y = d["y"]
    sigma = [float(d["sigma1"])]
    for t in range(1, len(y)):
        sigma.append(
            np.sqrt(
                p["alpha0"] + p["alpha1"] * (y[t - 1] - p["mu"]) ** 2 + p["beta1"] * sigma[-1] ** 2
            )
        )
    return _normal(y, p["mu"], np.array(sigma))


def stan_blr(d, p):
    return (
        _normal(p["beta"], 0, 10)
        + _normal(p["sigma"], 0, 10)
        + _normal(d["y"], d["X"] @ p["beta"], p["sigma"])
    )


def stan_diamonds(d, p):
    # transformed data from the raw design (its first column is the intercept's)
    raw = pdb.read_record("diamonds-diamonds")["data"]
    x = np.asarray(raw["X"])[:, 1:]
    xc = x - x.mean(axis=0)
    return (
        _normal(p["b"], 0, 1)
        + stats.t.logpdf(p["Intercept"], 3, 8, 10)
        + stats.t.logpdf(p["sigma"], 3, 0, 10)
        - stats.t.logsf(0, 3, 0, 10)
        + _normal(np.asarray(raw["Y"]), p["Intercept"] + xc @ p["b"], p["sigma"])
    )


def stan_eight_schools_centered(d, p):
    return (
        stats.cauchy.logpdf(p["tau"], 0, 5)
        + _normal(p["theta"], p["mu"], p["tau"])
        + _normal(d["y"], p["theta"], d["sigma"])
        + _normal(p["mu"], 0, 5)
    )


def stan_kilpisjarvi(d, p):
    return (
        _normal(p["alpha"], d["pmualpha"], d["psalpha"])
        + _normal(p["beta"], d["pmubeta"], d["psbeta"])
        + _normal(d["y"], p["alpha"] + p["beta"] * d["x"], p["sigma"])
    )


def stan_low_dim_gauss_mix(d, p):
    mu, sigma, theta = p["mu"], p["sigma"], p["theta"]
    mix = np.logaddexp(
        np.log(theta) + stats.norm.logpdf(d["y"], mu[0], sigma[0]),
        np.log1p(-theta) + stats.norm.logpdf(d["y"], mu[1], sigma[1]),
    )
    return _normal(sigma, 0, 2) + _normal(mu, 0, 2) + stats.beta.logpdf(theta, 5, 5) + mix.sum()


def stan_hmm_example(d, p):
    y, mu = d["y"], p["mu"]
    theta = [p["theta1"], p["theta2"]]
    gamma = [stats.norm.logpdf(y[0], mu[k], 1) for k in range(2)]
    for t in range(1, len(y)):
        gamma = [
            np.logaddexp(
                *[
                    gamma[j] + np.log(theta[j][k]) + stats.norm.logpdf(y[t], mu[k], 1)
                    for j in range(2)
                ]
            )
            for k in range(2)
        ]
    return stats.norm.logpdf(mu[0], 3, 1) + stats.norm.logpdf(mu[1], 10, 1) + np.logaddexp(*gamma)


def stan_arma11(d, p):
    y = d["y"]
    err = [y[0] - (p["mu"] + p["phi"] * p["mu"])]
    for t in range(1, len(y)):
        err.append(y[t] - (p["mu"] + p["phi"] * y[t - 1] + p["theta"] * err[-1]))
    return (
        _normal(p["mu"], 0, 10)
        + _normal(p["phi"], 0, 2)
        + _normal(p["theta"], 0, 2)
        + stats.cauchy.logpdf(p["sigma"], 0, 2.5)
        + _normal(np.array(err), 0, p["sigma"])
    )


def stan_earn_height(d, p):
    b = p["beta"]
    return _normal(d["earn"], b[0] + b[1] * d["height"], p["sigma"])


def stan_gp_regr(d, p):
    x = d["x"]
    cov = p["alpha"] ** 2 * np.exp(-0.5 * np.subtract.outer(x, x) ** 2 / p["rho"] ** 2)
    cov = cov + np.diag(np.full(len(x), p["sigma"]))
    return (
        stats.gamma.logpdf(p["rho"], 25, scale=1 / 4)
        + _normal(p["alpha"], 0, 2)
        + _normal(p["sigma"], 0, 1)
        + stats.multivariate_normal.logpdf(d["y"], np.zeros(len(x)), cov)
    )


def stan_kidscore_interaction(d, p):
    b, hs, iq = p["beta"], d["mom_hs"], d["mom_iq"]
    inter = hs * iq
    mean = b[0] + b[1] * hs + b[2] * iq + b[3] * inter
    return stats.cauchy.logpdf(p["sigma"], 0, 2.5) + _normal(d["kid_score"], mean, p["sigma"])


def _raw(name):
    return {k: np.asarray(v) for k, v in pdb.read_record(name)["data"].items()}


def stan_logearn_interaction_z(d, p):
    raw = _raw("earnings-logearn_interaction_z")  # transformed data from the raw data
    log_earn = np.log(raw["earn"])
    z = (raw["height"] - raw["height"].mean()) / np.std(raw["height"], ddof=1)
    inter = z * raw["male"]
    b = p["beta"]
    return _normal(log_earn, b[0] + b[1] * z + b[2] * raw["male"] + b[3] * inter, p["sigma"])


def stan_nes(d, p):
    raw = _raw("nes1972-nes")
    age = raw["age_discrete"]
    b = p["beta"]
    mean = (
        b[0]
        + b[1] * raw["real_ideo"]
        + b[2] * raw["race_adj"]
        + b[3] * (age == 2)
        + b[4] * (age == 3)
        + b[5] * (age == 4)
        + b[6] * raw["educ1"]
        + b[7] * raw["gender"]
        + b[8] * raw["income"]
    )
    return _normal(raw["partyid7"], mean, p["sigma"])


def stan_hmm_drive_0(d, p):
    raw = _raw("bball_drive_event_0-hmm_drive_0")
    u, v, alpha = raw["u"], raw["v"], raw["alpha"]
    theta = [p["theta1"], p["theta2"]]
    phi, lam = p["phi"], p["lambda"]
    target = sum(stats.dirichlet.logpdf(theta[k], alpha[k]) for k in range(2))
    target += stats.norm.logpdf(phi[0], 0, 1) + stats.norm.logpdf(phi[1], 3, 1)
    target += stats.norm.logpdf(lam[0], 0, 1) + stats.norm.logpdf(lam[1], 3, 1)

    def emit(t, k):  # exponential_lpdf(y | rate) = log(rate) - rate * y
        return np.log(phi[k]) - phi[k] * u[t] + np.log(lam[k]) - lam[k] * v[t]

    gamma = [emit(0, k) for k in range(2)]
    for t in range(1, len(u)):
        gamma = [
            np.logaddexp(*[gamma[j] + np.log(theta[j][k]) + emit(t, k) for j in range(2)])
            for k in range(2)
        ]
    return target + np.logaddexp(*gamma)


def stan_logmesquite_logvash(d, p):
    raw = _raw("mesquite-logmesquite_logvash")
    d1, d2 = raw["diam1"], raw["diam2"]
    b = p["beta"]
    mean = (
        b[0]
        + b[1] * np.log(d1 * d2 * raw["canopy_height"])
        + b[2] * np.log(d1 * d2)
        + b[3] * np.log(d1 / d2)
        + b[4] * np.log(raw["total_height"])
        + b[5] * raw["group"]
    )
    return _normal(np.log(raw["weight"]), mean, p["sigma"])


def stan_resonance(d, p):
    return (
        _normal(p["x"], 0, 0.003)
        + _normal(p["y"], 0, 1)
        + stats.gamma.logpdf(p["s"], 4, scale=1 / 4)
    )


STAN = {
    "eight_schools-eight_schools_noncentered": stan_eight_schools,
    "arK-arK": stan_ark,
    "gp_pois_regr-gp_pois_regr": stan_gp_pois_regr,
    "kidiq-kidscore_momiq": stan_kidscore_momiq,
    "mesquite-logmesquite": stan_logmesquite,
    "garch-garch11": stan_garch11,
    "sblrc-blr": stan_blr,
    "diamonds-diamonds": stan_diamonds,
    "eight_schools-eight_schools_centered": stan_eight_schools_centered,
    "kilpisjarvi_mod-kilpisjarvi": stan_kilpisjarvi,
    "low_dim_gauss_mix-low_dim_gauss_mix": stan_low_dim_gauss_mix,
    "hmm_example-hmm_example": stan_hmm_example,
    "arma-arma11": stan_arma11,
    "earnings-earn_height": stan_earn_height,
    "gp_pois_regr-gp_regr": stan_gp_regr,
    "kidiq-kidscore_interaction": stan_kidscore_interaction,
    "earnings-logearn_interaction_z": stan_logearn_interaction_z,
    "nes1972-nes": stan_nes,
    "bball_drive_event_0-hmm_drive_0": stan_hmm_drive_0,
    "mesquite-logmesquite_logvash": stan_logmesquite_logvash,
    "sblri-blr": stan_blr,
    pdb.RESONANCE: stan_resonance,
}


def test_every_posterior_has_a_transcription():
    assert set(STAN) == set(pdb.NAMES) == set(pdb.SPECS) | set(pdb.EXACT)
    assert set(pdb.SPECS) == set(pdb.POSTERIORS)


# By default: one with a bound that depends on another parameter and the resonance toy, and
# diamonds (the silent wrong sd) against its Stan program only (NumPyro's
# initialize_model on its 5000 x 24 design costs ~10 s); every one in make test-slow.
DEFAULT_POSTERIORS = ("eight_schools-eight_schools_noncentered", "garch-garch11", pdb.RESONANCE)
DEFAULT_LOG_JOINT = (*DEFAULT_POSTERIORS, "diamonds-diamonds")


def _params(default):
    return [
        name if name in default else pytest.param(name, marks=pytest.mark.slow)
        for name in pdb.NAMES
    ]


@pytest.fixture(scope="module", params=_params(DEFAULT_POSTERIORS))
def posterior(request):
    return pdb.load(request.param)


@pytest.fixture(scope="module")
def initialized(posterior):
    """NumPyro's ``(init, potential_fn, postprocess_fn)`` for the posterior's model."""
    init, potential_fn, postprocess_fn, _ = initialize_model(
        jax.random.key(0), posterior.model, model_kwargs=posterior.model_kwargs()
    )
    return init, potential_fn, postprocess_fn


def test_sites_name_the_reference_keys(posterior, initialized):
    """The reported sites' coordinates are the reference keys; the latent sample sites are
    what :meth:`Posterior.latent` rebuilds from them."""
    init, _, postprocess_fn = initialized
    values = postprocess_fn(init.z)
    reported = {name: values[name] for name in posterior.reported}
    assert sorted(pdb.reference_keys(reported)) == sorted(posterior.keys)
    rebuilt = posterior.latent(posterior.draws_sample[:1])
    assert set(rebuilt) == set(init.z)
    for name in init.z:
        assert np.shape(rebuilt[name])[1:] == np.shape(values[name])


def test_log_density_finite_and_transformed_parameters_reproduced(posterior, initialized):
    """At every reference draw kept: unconstrained and constrained again (deterministic sites
    recomputed) it is unchanged, and the potential energy there is finite."""
    draws = posterior.draws_sample
    latent = posterior.latent(draws)
    kwargs = posterior.model_kwargs()
    _, potential_fn, postprocess_fn = initialized

    def one(params):
        z = unconstrain_fn(posterior.model, (), kwargs, params)
        return potential_fn(z), postprocess_fn(z)

    energy, constrained = jax.jit(jax.vmap(one))(jax.tree.map(jnp.asarray, latent))
    assert np.all(np.isfinite(np.asarray(energy)))
    recomputed = pdb.flatten(constrained, posterior.keys, batch_ndim=1)
    np.testing.assert_allclose(recomputed, draws, rtol=1e-7, atol=1e-9 * np.abs(draws).max())


@pytest.mark.parametrize("name", _params(DEFAULT_LOG_JOINT))
def test_log_joint_equals_stan_target_up_to_a_constant(name):
    """NumPyro's log joint minus the SciPy transcription of the Stan program is one constant
    (the normalisers Stan's ``~`` drops and NumPyro's half laws add) across reference draws."""
    posterior = pdb.load(name)
    latent = posterior.latent(posterior.draws_sample)
    kwargs = posterior.model_kwargs()

    def numpyro_log_joint(params):
        return log_density(posterior.model, (), kwargs, params)[0]

    ours = np.asarray(jax.jit(jax.vmap(numpyro_log_joint))(jax.tree.map(jnp.asarray, latent)))
    data = {k: np.asarray(v) for k, v in posterior.data.items()}
    n = len(posterior.draws_sample)
    stan = np.array(
        [
            STAN[posterior.name](data, {k: np.asarray(v)[i] for k, v in latent.items()})
            for i in range(n)
        ]
    )
    assert np.all(np.isfinite(ours)) and np.all(np.isfinite(stan))
    difference = ours - stan
    spread = np.ptp(stan)  # the log density varies by this much across the draws
    assert spread > 1.0
    np.testing.assert_allclose(difference, difference[0], atol=1e-8 * max(1.0, np.abs(stan).max()))
