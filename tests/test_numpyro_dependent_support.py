"""GeometricHMC on a model whose support depends on another site (``Uniform(0, 1 − a)``).

The bijection of such a site is rebuilt from the support the model gives at every evaluation,
as NumPyro's ``potential_energy`` does: the kernel's log density is NumPyro's at any point,
including where ``a`` differs from its value at the initial point, and the draws match the
exact posterior (``a ~ U(0, 1)``, ``b | a ~ U(0, 1 − a)``: ``E a = 1/2``, ``E b = 1/4``,
``Var b = 7/144``), within 5 MCSE (ArviZ), fixed keys.
"""

import arviz_stats
import jax
import numpy as np
import pytest

numpyro = pytest.importorskip("numpyro")
import numpyro.distributions as dist
from numpyro.infer import MCMC
from numpyro.infer.util import potential_energy

from liesample.interop.numpyro_kernel import GeometricHMC


def triangle_model():
    a = numpyro.sample("a", dist.Uniform(0.0, 1.0))
    numpyro.sample("b", dist.Uniform(0.0, 1.0 - a))


def test_log_density_follows_a_bound_that_depends_on_another_site():
    # a ranges over (0.05, 0.95) in the chains, so b's bound 1 − a differs between them.
    raw = jax.random.uniform(jax.random.key(0), (6, 2), minval=-3.0, maxval=3.0)
    params = {"a": raw[:, 0], "b": raw[:, 1]}
    kernel = GeometricHMC(triangle_model)
    state = kernel.init(jax.random.split(jax.random.key(1), 6), 0, params, (), {})
    for c in range(6):
        one = {name: value[c] for name, value in params.items()}
        expected = potential_energy(triangle_model, (), {}, one)
        np.testing.assert_allclose(state.potential_energy[c], expected, rtol=1e-12)
    values = jax.vmap(kernel.postprocess_fn((), {}))(state.z)
    a = 1.0 / (1.0 + np.exp(-np.asarray(raw[:, 0])))
    b = (1.0 - a) / (1.0 + np.exp(-np.asarray(raw[:, 1])))
    np.testing.assert_allclose(values["a"], a, rtol=1e-12)
    np.testing.assert_allclose(values["b"], b, rtol=1e-12)


# slow: a statistical run; the default suite checks this with
# test_numpyro_dependent_support.py::test_log_density_follows_a_bound_that_depends_on_another_site
# (the kernel's law: test_numpyro_mcmc.py::test_vmf_posterior_matches_quadrature_and_arviz_...)
@pytest.mark.slow
def test_draws_match_the_exact_posterior_with_a_dependent_bound():
    mcmc = MCMC(
        GeometricHMC(triangle_model),
        num_warmup=300,
        num_samples=1000,
        num_chains=4,
        chain_method="vectorized",
        progress_bar=False,
    )
    mcmc.run(jax.random.key(7))
    draws = mcmc.get_samples(group_by_chain=True)
    a, b = np.asarray(draws["a"]), np.asarray(draws["b"])
    assert np.all(b < 1.0 - a) and np.all(b > 0.0)
    for name, x, method, exact in (
        ("a", a, "mean", 0.5),
        ("b", b, "mean", 0.25),
        ("b", b, "sd", np.sqrt(7.0 / 144.0)),
        ("a", a, "sd", np.sqrt(1.0 / 12.0)),
    ):
        mcse = float(arviz_stats.mcse(x, method=method))
        value = float(np.mean(x) if method == "mean" else np.std(x, ddof=1))
        assert abs(value - exact) < 5.0 * mcse, (name, method, value, exact, mcse)
