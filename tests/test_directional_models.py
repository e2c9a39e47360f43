"""The directional posteriors of ``benchmarks/directional_models.py``: each model's log density
against its hand-written formula (both the manifold-site model and the normalised-Gaussian
model NUTS samples), and the references (``@pytest.mark.slow``: the circular regression's
quadrature on a coarser grid, and each reference against exact i.i.d. draws or a long NUTS run,
within 5 Monte-Carlo standard errors).
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

numpyro = pytest.importorskip("numpyro")

from numpyro.infer.util import log_density
from scipy import special, stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root

from benchmarks import directional_models as dm
from liesample.numpyro import MatrixFisher
from liesample.targets import VonMisesFisherPosterior, quaternion_to_rotation

jax.config.update("jax_enable_x64", True)


def logp(model, data, params):
    return float(log_density(model, (), {"data": data}, params)[0])


def log_sphere_area(d):
    """``log |S^(d−1)|``: the uniform law's log density is its negative."""
    return np.log(2.0) + d / 2 * np.log(np.pi) - special.gammaln(d / 2)


def normal_logpdf(z):
    return float(np.sum(stats.norm.logpdf(np.asarray(z))))


def random_unit(rng, d):
    z = rng.standard_normal(d)
    return z / np.linalg.norm(z), z


# --------------------------------------------------------------------------- log densities


def test_vmf_sphere_log_density_is_the_formula():
    data = {k: jnp.asarray(v) for k, v in dm.vmf_data().items()}
    x = np.asarray(data["x"])
    n, d = x.shape
    rng = np.random.default_rng(0)
    for kappa in (0.5, 30.0):
        mu, z = random_unit(rng, d)
        formula = (
            -log_sphere_area(d)
            + stats.lognorm.logpdf(kappa, s=dm.VMF_PRIOR[1], scale=np.exp(dm.VMF_PRIOR[0]))
            + n * dm.log_vmf_normaliser(kappa, d)
            + kappa * mu @ x.sum(0)
        )
        ours = logp(dm.vmf_model, data, {"mu": jnp.asarray(mu), "kappa": kappa})
        assert ours == pytest.approx(formula, rel=1e-10, abs=1e-8)
        # NUTS's model: a Gaussian z in place of the uniform direction z / |z|
        nuts = logp(dm.vmf_nuts_model, data, {"mu_z": jnp.asarray(z), "kappa": kappa})
        assert nuts == pytest.approx(formula + log_sphere_area(d) + normal_logpdf(z), rel=1e-10)


def test_watson_log_density_is_the_bingham_reference():
    data = {k: jnp.asarray(v) for k, v in dm.watson_data().items()}
    x = np.asarray(data["x"])
    bingham = dm.watson_bingham(x)
    rng = np.random.default_rng(1)
    offsets = []
    for _ in range(3):
        mu, z = random_unit(rng, 3)
        formula = -np.log(4 * np.pi) + dm.WATSON_CONCENTRATION * np.sum((x @ mu) ** 2)
        ours = logp(dm.watson_model, data, {"mu": jnp.asarray(mu)})
        assert ours == pytest.approx(formula, rel=1e-12)
        nuts = logp(dm.watson_nuts_model, data, {"mu_z": jnp.asarray(z)})
        assert nuts == pytest.approx(formula + np.log(4 * np.pi) + normal_logpdf(z), rel=1e-12)
        offsets.append(ours - float(bingham.log_prob(jnp.asarray(mu))))
    np.testing.assert_allclose(offsets, offsets[0], rtol=0, atol=1e-9)  # one law, normalised apart


def test_watson_reference_is_antipodal_with_unit_second_moment():
    mean, sd = dm.watson_reference(dm.watson_data()["x"])
    np.testing.assert_array_equal(mean, 0.0)
    assert float(np.sum(sd**2)) == pytest.approx(1.0, abs=1e-10)  # E|mu|² = 1


def test_circular_regression_log_density_is_the_quadratures_integrand():
    data = {k: jnp.asarray(v) for k, v in dm.circular_data().items()}
    x, y = np.asarray(data["x"]), np.asarray(data["y"])
    rng = np.random.default_rng(2)
    offsets = []
    for _ in range(2):
        u, z = random_unit(rng, 2)
        alpha, beta, kappa = np.arctan2(u[1], u[0]), rng.normal(), np.exp(rng.normal(1.0))
        formula = (
            stats.vonmises.logpdf(alpha, dm.CIRCULAR_PRIOR[0])
            + stats.norm.logpdf(beta)
            + stats.lognorm.logpdf(kappa, s=1.0, scale=np.e)
            + np.sum(stats.vonmises.logpdf(y, kappa, loc=alpha + 2 * np.arctan(beta * x)))
        )
        params = {"beta": beta, "kappa": kappa}
        ours = logp(dm.circular_model, data, {"alpha": alpha, **params})
        assert ours == pytest.approx(formula, rel=1e-10)
        nuts = logp(dm.circular_nuts_model, data, {"alpha_z": jnp.asarray(z), **params})
        assert nuts == pytest.approx(formula + normal_logpdf(z), rel=1e-10)
        # the quadrature's density is w.r.t. d(log kappa): the model's plus log kappa
        integrand = float(dm.circular_log_density(alpha, beta, np.log(kappa), data))
        offsets.append(ours + np.log(kappa) - integrand)
    np.testing.assert_allclose(offsets, offsets[0], rtol=0, atol=1e-9)


@pytest.mark.slow
def test_circular_regression_quadrature_is_converged():
    """A coarser grid (3/4 of the nodes in ``alpha``, half in ``beta`` and ``log kappa``) moves
    no moment by more than 1e-6 of the smallest sd: the trapezoid rule converges geometrically
    for a smooth periodic integrand and for one negligible at the bounds."""
    data = dm.circular_data()
    mean, sd = dm.circular_reference(data)
    coarse_mean, coarse_sd = dm.circular_reference(data, points=(96, 61, 61))
    np.testing.assert_allclose(coarse_mean, mean, rtol=0, atol=1e-6 * sd.min())
    np.testing.assert_allclose(coarse_sd, sd, rtol=1e-6)


def test_rotation_averaging_log_density_is_the_formula():
    data = {k: jnp.asarray(v) for k, v in dm.rotation_data().items()}
    rotations = np.asarray(data["R"])
    n = rotations.shape[0]
    rng = np.random.default_rng(3)
    for kappa in (0.7, 6.0):
        q, z = random_unit(rng, 4)
        rotation = np.asarray(quaternion_to_rotation(jnp.asarray(q)))
        log_c = float(MatrixFisher(jnp.asarray(kappa * np.eye(3))).log_normalizer())
        formula = (
            stats.lognorm.logpdf(kappa, s=dm.ROTATION_PRIOR[1], scale=np.exp(dm.ROTATION_PRIOR[0]))
            + kappa * np.sum(rotation * rotations.sum(0))
            - n * log_c
        )  # the Haar prior's density is 1
        ours = logp(dm.rotation_model, data, {"M": jnp.asarray(rotation), "kappa": kappa})
        assert ours == pytest.approx(formula, rel=1e-10)
        nuts = logp(dm.rotation_nuts_model, data, {"M_z": jnp.asarray(z), "kappa": kappa})
        assert nuts == pytest.approx(formula + normal_logpdf(z), rel=1e-10)


def test_vmf_reference_on_s2_is_liesamples_exact_posterior():
    """In three dimensions the quadrature is :class:`VonMisesFisherPosterior`'s (an independent
    implementation of the same integral, on S² only)."""
    x = stats.vonmises_fisher([0.0, 0.6, 0.8], 5.0).rvs(30, random_state=np.random.default_rng(4))
    mean, _ = dm.vmf_reference(x)
    exact = VonMisesFisherPosterior(x, prior_mean=dm.VMF_PRIOR[0], prior_sd=dm.VMF_PRIOR[1])
    np.testing.assert_allclose(mean[:3], exact.expectations()["direction"], rtol=1e-7, atol=1e-9)


# --------------------------------------------------------------------------- references (slow)


def assert_within_mcse(draws, mean, sd, names, limit=5.0):
    """Means and sds of i.i.d. ``draws`` against a reference, within ``limit`` MCSE (the sd's
    MCSE from the fourth central moment)."""
    n = draws.shape[0]
    m, s = draws.mean(0), draws.std(0, ddof=1)
    mcse_mean = s / np.sqrt(n)
    m4 = np.mean((draws - m) ** 4, axis=0)
    mcse_sd = np.sqrt(np.maximum(m4 - s**4, 0.0)) / (2 * s * np.sqrt(n))
    z_mean = (m - mean) / mcse_mean
    z_sd = (s - sd) / mcse_sd
    assert np.all(np.abs(z_mean) < limit), dict(zip(names, np.round(z_mean, 2)))
    assert np.all(np.abs(z_sd) < limit), dict(zip(names, np.round(z_sd, 2)))


@pytest.mark.slow
def test_vmf_reference_matches_exact_draws():
    posterior = dm.load(dm.VMF_SPHERE)
    draws = dm.vmf_exact_draws(posterior.data["x"], 20_000, seed=1)
    assert_within_mcse(draws, posterior.mean, posterior.sd, posterior.keys)


@pytest.mark.slow
def test_watson_reference_matches_exact_draws():
    posterior = dm.load(dm.AXIAL_BIMODAL)
    law = dm.watson_bingham(posterior.data["x"])
    draws = np.asarray(law.sample(jax.random.key(5), (100_000,)))
    assert_within_mcse(draws, posterior.mean, posterior.sd, posterior.keys)


@pytest.mark.slow
def test_rotation_reference_matches_independent_exact_draws():
    """The exact means against draws of another seed than the reference's sds."""
    posterior = dm.load(dm.ROTATION_AVERAGING)
    draws = dm.rotation_exact_draws(posterior.data["R"], 100_000, seed=9)
    assert_within_mcse(draws, posterior.mean, posterior.sd, posterior.keys)


@pytest.mark.slow
def test_circular_regression_reference_matches_a_long_nuts_run():
    import arviz_stats
    from numpyro.infer import MCMC, NUTS

    from benchmarks import posteriordb_models as pdb

    posterior = dm.load(dm.CIRCULAR_REGRESSION)
    mcmc = MCMC(NUTS(posterior.nuts_model), num_warmup=1000, num_samples=5000, num_chains=4,
                chain_method="vectorized", progress_bar=False)  # fmt: skip
    mcmc.run(jax.random.key(6), **posterior.model_kwargs())
    draws = pdb.flatten(mcmc.get_samples(group_by_chain=True), posterior.keys, batch_ndim=2)
    mcse = np.asarray(arviz_stats.mcse(draws, method="mean", chain_axis=0, draw_axis=1))
    mcse_sd = np.asarray(arviz_stats.mcse(draws, method="sd", chain_axis=0, draw_axis=1))
    flat = draws.reshape(-1, draws.shape[-1])
    z_mean = (flat.mean(0) - posterior.mean) / mcse
    z_sd = (flat.std(0, ddof=1) - posterior.sd) / mcse_sd
    assert np.all(np.abs(z_mean) < 5), dict(zip(posterior.keys, np.round(z_mean, 2)))
    assert np.all(np.abs(z_sd) < 5), dict(zip(posterior.keys, np.round(z_sd, 2)))
