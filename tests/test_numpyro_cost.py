"""What a GeometricHMC transition on the NumPyro path does not recompute: the decomposition of a
dense inverse mass (kept in the state while the mass is unchanged) and the kernel's ``init``
before a run from a warm-up's state."""

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
from numpyro.infer import MCMC

from liesample.geometry.cotangent import cotangent_bundle
from liesample.geometry.spaces import Euclidean
from liesample.numpyro_mcmc import GeometricHMC
from liesample.samplers.cotangent.geometric_hmc import geometric_hmc

COVARIANCE = jnp.array([[1.0, 0.8, 0.0], [0.8, 1.0, 0.3], [0.0, 0.3, 2.0]])


def correlated():
    numpyro.sample("x", dist.MultivariateNormal(jnp.zeros(3), COVARIANCE))


def test_the_kept_metric_is_the_decomposition_of_the_mass_in_use():
    kernel = GeometricHMC(correlated, dense_mass=True)  # one dense block of 3
    mcmc = MCMC(kernel, num_warmup=60, num_samples=5, num_chains=2,
                chain_method="vectorized", progress_bar=False)  # fmt: skip
    mcmc.run(jax.random.key(0))
    state = mcmc.last_state
    (mass,) = state.adapt_state.inverse_mass_matrix.values()
    assert mass.shape == (2, 3, 3)  # dense, one per chain (shared)
    assert not np.allclose(mass[0], np.eye(3))  # adapted: the kept metric had to follow it
    space = kernel._layout.inner_space
    inner_mass = jax.tree.map(lambda x: x[0], state.adaptation.inverse_mass)
    expected = cotangent_bundle(space, inner_mass, None, jnp.float64).metric
    kept = jax.tree.map(lambda x: x[0], state.metric)
    for a, b in zip(jax.tree.leaves(kept), jax.tree.leaves(expected), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_diagonal_mass_keeps_no_metric():
    kernel = GeometricHMC(correlated, dense_mass=False)
    mcmc = MCMC(kernel, num_warmup=20, num_samples=2, progress_bar=False)
    mcmc.run(jax.random.key(0))
    assert mcmc.last_state.metric is None


def test_the_kernel_with_a_precomputed_metric_moves_as_without():
    space = Euclidean((3,))
    mass = jnp.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.2], [0.0, 0.2, 0.5]])
    logdensity = lambda x: -0.5 * x @ jnp.linalg.solve(COVARIANCE, x)
    state = geometric_hmc.init(jnp.array([0.3, -0.2, 1.0]), logdensity, space)
    kernel = geometric_hmc.build_kernel()
    metric = cotangent_bundle(space, mass, None, state.logdensity.dtype).metric
    key = jax.random.key(1)
    plain = kernel(key, state, logdensity, space, 0.3, 7, inverse_mass_matrix=mass)
    cached = kernel(key, state, logdensity, space, 0.3, 7, inverse_mass_matrix=mass,
                    metric=metric)  # fmt: skip
    for a, b in zip(jax.tree.leaves(plain), jax.tree.leaves(cached), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_run_after_the_warmup_does_not_initialise_the_kernel_again(monkeypatch):
    kernel = GeometricHMC(correlated)
    calls = []
    init = kernel.init
    monkeypatch.setattr(kernel, "init", lambda *a, **k: calls.append(1) or init(*a, **k))
    mcmc = MCMC(kernel, num_warmup=20, num_samples=5, num_chains=2,
                chain_method="sequential", progress_bar=False)  # fmt: skip
    mcmc.warmup(jax.random.key(0))
    assert len(calls) == 2  # one per chain
    mcmc.run(jax.random.key(1))
    assert len(calls) == 2  # the warm-up's states go on, as with numpyro.infer.HMC
    assert mcmc.get_samples()["x"].shape == (10, 3)
