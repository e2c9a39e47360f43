"""Funnels are loud: a centred hierarchy's scale is found in the model, and a run that shows
the funnel (divergences, or the scale's R-hat or ESS failing) warns naming the scale, the
sites it scales and ``numpyro.infer.reparam.LocScaleReparam``
(``numpyro_sites.hierarchical_scales``, ``numpyro_checks.funnel_warnings``, through
``check_mcmc`` and ``GeometricHMC(check_convergence=True)``). The model is traced, nothing is
compiled, except in the slow test: posteriordb's centred eight schools through NumPyro's
``MCMC`` is right or warned.
"""

import sys
import warnings
from pathlib import Path

import jax
import numpy as np
import pytest

numpyro = pytest.importorskip("numpyro")
import numpyro.distributions as dist
from numpyro.infer import MCMC

from liesample.interop.numpyro_checks import check_mcmc, funnel_warnings
from liesample.interop.numpyro_kernel import GeometricHMC
from liesample.interop.numpyro_sites import hierarchical_scales

SIGMA = np.array([15.0, 10.0, 16.0, 11.0, 9.0, 11.0, 10.0, 18.0])
Y = np.array([28.0, 8.0, -3.0, 7.0, -1.0, 1.0, 18.0, 12.0])


def centred(sigma, y=None):
    tau = numpyro.sample("tau", dist.HalfCauchy(5.0))
    mu = numpyro.sample("mu", dist.Normal(0.0, 5.0))
    theta = numpyro.sample("theta", dist.Normal(mu, tau).expand([len(sigma)]))
    numpyro.sample("y", dist.Normal(theta, sigma), obs=y)


def non_centred(sigma, y=None):
    tau = numpyro.sample("tau", dist.HalfCauchy(5.0))
    mu = numpyro.sample("mu", dist.Normal(0.0, 5.0))
    z = numpyro.sample("z", dist.Normal(0.0, 1.0).expand([len(sigma)]))
    numpyro.sample("y", dist.Normal(mu + tau * z, sigma), obs=y)


def test_the_scale_of_a_centred_hierarchy_is_found():
    key = jax.random.key(0)
    assert hierarchical_scales(centred, key, (SIGMA, Y), {}) == {"tau": ("theta",)}
    # non-centred, tau scales only an observed site: nothing to reparametrise
    assert hierarchical_scales(non_centred, key, (SIGMA,), {"y": Y}) == {}


def _mixed(seed, shape=(4, 200)):
    return np.exp(np.random.default_rng(seed).standard_normal(shape))


def test_a_funnel_warning_names_the_scale_its_sites_and_the_reparametrisation():
    tau = _mixed(1)
    diverging = np.zeros(tau.shape, bool)
    diverging[2, 17] = True
    messages = funnel_warnings({"tau": tau}, {"diverging": diverging}, {"tau": ("theta",)})
    assert len(messages) == 1
    assert messages[0].startswith("tau is the scale of theta")
    assert "1 divergent transition(s)" in messages[0]
    assert "{'theta': LocScaleReparam(0)}" in messages[0] and "numpyro.infer.reparam" in messages[0]


def test_a_scale_whose_chains_disagree_warns_without_divergences():
    tau = _mixed(2)
    tau[0] *= 0.05  # one chain never leaves small values: the chains disagree
    messages = funnel_warnings({"tau": tau}, {"diverging": np.zeros(tau.shape, bool)},
                               {"tau": ("theta",)})  # fmt: skip
    assert len(messages) == 1 and "R-hat > 1.01 for 1 element(s): tau: " in messages[0]


def test_a_well_mixed_scale_without_divergences_is_quiet():
    tau = _mixed(3)
    fields = {"diverging": np.zeros(tau.shape, bool)}
    assert funnel_warnings({"tau": tau}, fields, {"tau": ("theta",)}) == []
    assert funnel_warnings({"tau": tau}, {"diverging": ~fields["diverging"]}, {}) == []


sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root


@pytest.mark.slow
@pytest.mark.parametrize("chain_method", ["vectorized", "sequential"])
def test_centred_eight_schools_is_right_or_warned(chain_method):
    """posteriordb's centred eight schools, 4 chains x (1000 + 1000), the kernel's defaults:
    every posterior mean within 5 combined MCSE (the run's and the reference's) of the
    reference and every sd within 10 %, or a warning from ``check_mcmc``."""
    import arviz_stats

    from benchmarks import posteriordb_models as pdb

    posterior = pdb.load("eight_schools-eight_schools_centered")
    mcmc = MCMC(GeometricHMC(posterior.model), num_warmup=1000, num_samples=1000,
                num_chains=4, chain_method=chain_method, progress_bar=False)  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mcmc.run(jax.random.key(0), **posterior.model_kwargs())
        check_mcmc(mcmc)
    samples = mcmc.get_samples(group_by_chain=True)
    values = {k: np.asarray(v) for k, v in samples.items() if k in posterior.reported}
    draws = pdb.flatten(values, posterior.keys, batch_ndim=2)  # (chains, draws, keys)
    mcse = np.array([float(arviz_stats.mcse(draws[..., k], method="mean"))
                     for k in range(draws.shape[-1])])  # fmt: skip
    error = np.abs(draws.mean((0, 1)) - posterior.mean)
    sd_ratio = draws.std((0, 1)) / posterior.sd
    right = np.all(error <= 5.0 * np.sqrt(mcse**2 + posterior.mcse_mean**2)) and np.all(
        np.abs(sd_ratio - 1.0) <= 0.1
    )
    messages = [str(w.message) for w in caught]
    assert right or messages, (posterior.keys, error, mcse, sd_ratio)
    if not right:  # the funnel is named, with its fix and the divergences seen
        named = [m for m in messages if "tau is the scale of theta" in m]
        assert named, messages
        divergent = int(np.sum(mcmc.get_extra_fields()["diverging"]))
        if divergent:
            assert f"{divergent} divergent transition(s)" in named[0], named
