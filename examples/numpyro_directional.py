"""Directional statistics with NumPyro: a mean direction on S² and a concentration, end to end.

Run with ``.venv/bin/python examples/numpyro_directional.py`` (about 30 s on 2 cores).

The model is written in NumPyro; :class:`liesample.interop.numpyro_kernel.GeometricHMC` samples
it with geometric HMC, moving the direction ``mu`` on the sphere itself (no unit-vector trick, no
projected parametrisation) and the concentration ``kappa`` in NumPyro's unconstrained
coordinate ``log κ``::

    mu    ~ VonMisesFisher(any, 0)          uniform on S²
    kappa ~ LogNormal(PRIOR_MEAN, PRIOR_SD)
    x_i   ~ VonMisesFisher(mu, kappa)       i = 1…N

Data: no well-kept installed package ships a directional data set, so ``N`` unit vectors are
simulated with ``scipy.stats.vonmises_fisher`` (fixed seed). ``MCMC`` runs four vectorised
chains; its own summary and an ArviZ summary (``arviz.from_numpyro``) are printed, and the
posterior means are compared with the exact ones of
:class:`liesample.targets.groups.VonMisesFisherPosterior` (quadrature over ``log κ``: given
``κ``, ``mu`` is ``vMF(S/|S|, κ|S|)`` with ``S = Σ x_i``).
"""

from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)

import arviz
import arviz_stats
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
from numpyro.infer import MCMC
from scipy.stats import vonmises_fisher

from liesample.interop.numpyro_distributions import VonMisesFisher
from liesample.interop.numpyro_kernel import GeometricHMC
from liesample.targets.groups import VonMisesFisherPosterior

TRUE_DIRECTION = np.array([1.0, 2.0, 2.0]) / 3.0
TRUE_KAPPA = 8.0
PRIOR_MEAN = 1.0
PRIOR_SD = 1.5
NUM_DATA = 40


def model(x):
    """Uniform mean direction, log-normal concentration, vMF likelihood."""
    mu = numpyro.sample("mu", VonMisesFisher(jnp.array([0.0, 0.0, 1.0]), 0.0))
    kappa = numpyro.sample("kappa", dist.LogNormal(PRIOR_MEAN, PRIOR_SD))
    numpyro.deterministic("log_kappa", jnp.log(kappa))
    with numpyro.plate("data", x.shape[0]):
        numpyro.sample("x", VonMisesFisher(mu, kappa), obs=x)


def simulate_data(num_data: int = NUM_DATA, seed: int = 0) -> np.ndarray:
    """``num_data`` unit vectors from ``vMF(TRUE_DIRECTION, TRUE_KAPPA)``."""
    law = vonmises_fisher(TRUE_DIRECTION, TRUE_KAPPA)
    return law.rvs(num_data, random_state=np.random.default_rng(seed))


def main(
    seed: int = 0,
    *,
    num_warmup: int = 500,
    num_samples: int = 1000,
    num_chains: int = 4,
    progress: bool = True,
):
    """Fit, print the summaries and the comparison; return ``(mcmc, tree, exact)``."""
    data = simulate_data(NUM_DATA, seed)
    mcmc = MCMC(
        GeometricHMC(model),
        num_warmup=num_warmup,
        num_samples=num_samples,
        num_chains=num_chains,
        chain_method="vectorized",
        progress_bar=progress,
    )
    mcmc.run(jax.random.key(seed), jnp.asarray(data), extra_fields=("accept_prob", "step_size"))
    mcmc.print_summary()

    tree = arviz.from_numpyro(mcmc, log_likelihood=True)
    # every column, whatever the terminal's width (pandas elides columns of a wide table)
    print(arviz_stats.summary(tree, var_names=["mu", "kappa", "log_kappa"]).to_string())

    exact = VonMisesFisherPosterior(data, prior_mean=PRIOR_MEAN, prior_sd=PRIOR_SD).expectations()
    samples = mcmc.get_samples()
    print(f"{NUM_DATA} points from vMF(μ₀ = {np.round(TRUE_DIRECTION, 3)}, κ₀ = {TRUE_KAPPA})")
    print("posterior mean of mu: ", np.round(np.asarray(samples["mu"]).mean(0), 4))
    print("exact                 ", np.round(exact["direction"], 4))
    print(f"posterior mean of log kappa: {float(samples['log_kappa'].mean()):.4f} "
          f"(exact {exact['log_kappa']:.4f})")  # fmt: skip
    return mcmc, tree, exact


if __name__ == "__main__":
    main()
