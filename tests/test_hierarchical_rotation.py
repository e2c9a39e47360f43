"""A hierarchical rotation model with a latent concentration, written as a NumPyro user writes it,
sampled by GeometricHMC with 4 chains, against its exact posterior.

    κ   ~ Gamma(a, b)
    R   ~ MatrixFisher(κ I₃)                    on SO(3)
    y_i ~ VonMisesFisher(R e_{j_i}, τ)          τ known, i = 1…n

Conjugacy: ``Π_i exp(τ y_iᵀ R e_{j_i}) = exp(tr((τY)ᵀR))`` with ``Y = Σ_i y_i e_{j_i}ᵀ``, so
``R | κ, y ~ MatrixFisher(κI + τY)`` and ``p(y | κ) ∝ c(κI + τY) / c(κI)`` (``c`` the matrix
Fisher normaliser, an exact 1-D integral given the singular values). The marginal posterior of
``κ`` is then exact by 1-D quadrature over ``log κ``, and ``E[R | y] = E_κ[E[R | κ, y]]``. The
reference uses :class:`liesample.targets.groups.MatrixFisherLaw` (SciPy quadrature), independent
of the JAX normaliser the model uses. Tolerances: 5 MCSE (ArviZ); fixed keys.
"""

import arviz_stats
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

numpyro = pytest.importorskip("numpyro")
import numpyro.distributions as dist
from numpyro.infer import MCMC

from liesample.interop.numpyro_distributions import MatrixFisher, VonMisesFisher
from liesample.numpyro_mcmc import GeometricHMC
from liesample.targets.groups import MatrixFisherLaw

SHAPE, RATE, TAU = 2.0, 0.5, 4.0
AXES = np.array([0, 1, 2] * 3)  # y_i measures the column R e_{j_i}


def model(y, axes):
    kappa = numpyro.sample("kappa", dist.Gamma(SHAPE, RATE))
    R = numpyro.sample("R", MatrixFisher(kappa * jnp.eye(3)))
    with numpyro.plate("obs", y.shape[0]):
        numpyro.sample("y", VonMisesFisher(R[:, axes].T, TAU), obs=y)


def simulate(seed=0, kappa=4.0):
    k_rotation, k_data = jax.random.split(jax.random.key(seed))
    R = np.asarray(MatrixFisher(kappa * np.eye(3)).sample(k_rotation))
    return np.asarray(VonMisesFisher(R[:, AXES].T, TAU).sample(k_data))


def exact_posterior(y, num_nodes=80, lo=-4.0, hi=4.0):
    """``E[κ]``, ``E[log κ]`` and ``E[R]`` under ``p(κ | y)``, by Gauss–Legendre over ``η = log κ``
    on ``[lo, hi]`` (the tails beyond hold < 1e−6 of the mass: checked)."""
    Y = np.zeros((3, 3))
    for yi, j in zip(y, AXES):
        Y[:, j] += yi
    x, w = np.polynomial.legendre.leggauss(num_nodes)
    eta = lo + 0.5 * (x + 1.0) * (hi - lo)
    kappa = np.exp(eta)
    log_post = np.array([
        stats.gamma.logpdf(k, SHAPE, scale=1.0 / RATE) + e  # dκ = κ dη
        + MatrixFisherLaw(k * np.eye(3) + TAU * Y).log_normalizer()
        - MatrixFisherLaw(k * np.eye(3)).log_normalizer()
        for k, e in zip(kappa, eta)
    ])  # fmt: skip
    p = w * np.exp(log_post - log_post.max())
    p /= p.sum()
    assert p[:4].sum() < 1e-6 and p[-4:].sum() < 1e-6  # the grid holds the posterior
    rotation_mean = sum(
        pk * MatrixFisherLaw(k * np.eye(3) + TAU * Y).mean() for pk, k in zip(p, kappa)
    )
    return {"kappa": p @ kappa, "log_kappa": p @ eta, "R": rotation_mean}


def _within(draws, exact, name, z=5.0):
    """``draws`` (chain, draw): chains mixed, mean within ``z`` MCSE of ``exact``."""
    draws = np.asarray(draws)
    mcse = float(arviz_stats.mcse(draws, method="mean"))
    assert float(arviz_stats.rhat(draws)) < 1.05, name
    assert abs(float(draws.mean()) - exact) < z * mcse, (name, float(draws.mean()), exact, mcse)


# A latent concentration inside a model runs by default (test_numpyro_distributions).
@pytest.mark.slow
def test_latent_concentration_posterior_matches_quadrature_with_four_chains():
    y = simulate()
    mcmc = MCMC(
        GeometricHMC(model),
        num_warmup=200,
        num_samples=300,
        num_chains=4,
        chain_method="vectorized",
        progress_bar=False,
    )
    mcmc.run(jax.random.key(1), jnp.asarray(y), jnp.asarray(AXES))
    samples = mcmc.get_samples(group_by_chain=True)
    kappa, R = np.asarray(samples["kappa"]), np.asarray(samples["R"])
    assert kappa.shape == (4, 300) and R.shape == (4, 300, 3, 3)
    assert np.allclose(np.swapaxes(R, -1, -2) @ R, np.eye(3), atol=1e-10)
    exact = exact_posterior(y)
    _within(kappa, exact["kappa"], "kappa")
    _within(np.log(kappa), exact["log_kappa"], "log_kappa")
    for i in range(3):
        for j in range(3):
            _within(R[..., i, j], exact["R"][i, j], f"R[{i},{j}]")
