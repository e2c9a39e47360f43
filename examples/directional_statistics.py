"""Directional statistics: the mean direction and concentration of von Mises–Fisher data on S².

Run with ``.venv/bin/python examples/directional_statistics.py`` (about 15 s on 2 cores).

Data ``x_1…x_N`` are drawn from ``vMF(μ₀, κ₀)`` on the unit sphere S² with
``scipy.stats.vonmises_fisher`` (fixed seed). The model: ``μ`` uniform on S²,
``η = log κ ~ N(PRIOR_MEAN, PRIOR_SD²)``, and the likelihood ``∏ (κ / 4π sinh κ) e^{κ μ·x_i}``.
The parameter lives on the product space ``{"mu": Sphere(2), "log_kappa": Euclidean(())}``:

1. ``liesample.window_adaptation(liesample.geometric_hmc, ...)`` tunes the step size, the mass
   and the number of leapfrog steps on one chain;
2. ``liesample.sample`` runs ``NUM_CHAINS`` chains of the tuned ``liesample.geometric_hmc``
   from dispersed starts (random directions) and returns an ArviZ DataTree with the posterior
   variables ``mu`` (dims ``mu_dim_0`` = x, y, z) and ``log_kappa``;
3. the ArviZ summary is printed, and the posterior means are compared with the exact ones of
   :class:`liesample.targets.groups.VonMisesFisherPosterior` (one-dimensional quadrature over
   ``η``: given ``κ``, ``μ`` is ``vMF(S/|S|, κ|S|)`` with ``S = Σ x_i``).

ESS, R-hat and MCSE of ``mu`` are those of its three ambient coordinates.
"""

from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)

import arviz_stats
import jax.numpy as jnp
import numpy as np
from scipy.stats import vonmises_fisher

import liesample
from liesample.geometry.spaces import Euclidean, Sphere
from liesample.targets.groups import VonMisesFisherPosterior

TRUE_DIRECTION = np.array([1.0, 2.0, 2.0]) / 3.0
TRUE_KAPPA = 8.0
PRIOR_MEAN = 1.0
PRIOR_SD = 1.5
NUM_DATA = 40
NUM_CHAINS = 4
NUM_ADAPTATION = 400
NUM_WARMUP = 100
NUM_DRAWS = 1000

SPACE = {"mu": Sphere(2), "log_kappa": Euclidean(())}


def simulate_data(num_data: int, seed: int) -> np.ndarray:
    """``num_data`` unit vectors from ``vMF(TRUE_DIRECTION, TRUE_KAPPA)``."""
    law = vonmises_fisher(TRUE_DIRECTION, TRUE_KAPPA)
    return law.rvs(num_data, random_state=np.random.default_rng(seed))


def main(
    seed: int = 0,
    *,
    num_data: int = NUM_DATA,
    num_chains: int = NUM_CHAINS,
    num_adaptation: int = NUM_ADAPTATION,
    num_warmup: int = NUM_WARMUP,
    num_draws: int = NUM_DRAWS,
    progress: bool = True,
):
    """Fit, print the summary and the comparison; return ``(tree, exact)``."""
    data = simulate_data(num_data, seed)
    posterior = VonMisesFisherPosterior(data, prior_mean=PRIOR_MEAN, prior_sd=PRIOR_SD)

    def logdensity(p):  # w.r.t. uniform on S² × Lebesgue
        return posterior.logdensity({"direction": p["mu"], "log_kappa": p["log_kappa"]})

    adapt_key, start_key, sample_key = jax.random.split(jax.random.key(seed), 3)
    start = {"mu": jnp.array([0.0, 0.0, 1.0]), "log_kappa": jnp.asarray(PRIOR_MEAN)}
    (_, parameters), _ = liesample.window_adaptation(
        liesample.geometric_hmc, logdensity, SPACE
    ).run(adapt_key, start, num_adaptation)
    sampler = liesample.geometric_hmc(logdensity, SPACE, **parameters)

    # Dispersed starts: uniform directions, log κ at the prior mean.
    directions = jax.random.normal(start_key, (num_chains, 3))
    starts = {
        "mu": directions / jnp.linalg.norm(directions, axis=1, keepdims=True),
        "log_kappa": jnp.full((num_chains,), PRIOR_MEAN),
    }
    tree = liesample.sample(
        sampler, sample_key, starts, num_draws, num_warmup=num_warmup, progress_bar=progress
    )

    exact = posterior.expectations()
    print(f"von Mises–Fisher on S²: {num_data} points, true μ₀ = {np.round(TRUE_DIRECTION, 3)}, "
          f"κ₀ = {TRUE_KAPPA}; geometric HMC, step size {float(parameters['step_size']):.3f}, "
          f"{int(parameters['num_integration_steps'])} leapfrog steps")  # fmt: skip
    print(arviz_stats.summary(tree, var_names=["mu", "log_kappa"]))
    mu = np.asarray(tree.posterior["mu"])
    log_kappa = np.asarray(tree.posterior["log_kappa"])
    print("posterior mean of mu: ", np.round(mu.mean(axis=(0, 1)), 4))
    print("exact                 ", np.round(exact["direction"], 4))
    print(f"posterior mean of log_kappa: {log_kappa.mean():.4f} (exact {exact['log_kappa']:.4f})")
    return tree, exact


if __name__ == "__main__":
    main()
