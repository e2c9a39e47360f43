"""Observations off the support under ``MCMC(GeometricHMC(model))``: the likelihood is only
evaluated traced, where ``validate_args`` checks nothing, so the kernel's ``init`` checks every
observed site's concrete value (``check_observed_sites``) and raises naming the site, for each
liesample.numpyro distribution. Every refusal comes before anything is compiled."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

pytest.importorskip("numpyro")

import numpyro
import numpyro.distributions as dist
from numpyro.handlers import seed, trace
from numpyro.infer import MCMC

from liesample.interop.numpyro_distributions import check_observed_sites
from liesample.numpyro import Bingham, MatrixFisher, VonMisesFisher
from liesample.numpyro_mcmc import GeometricHMC

NORTH = jnp.array([0.0, 0.0, 1.0])
ON_SPHERE = np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [1.0, 0.0, 0.0]])
OFF_SPHERE = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [1.0, 0.0, 0.0]])  # as users measured


def vmf_model(x, validate_args=True):
    kappa = numpyro.sample("kappa", dist.Exponential(0.1))
    law = VonMisesFisher(NORTH, kappa, validate_args=validate_args)
    numpyro.sample("obs", law, obs=x)


def bingham_model(x):
    scale = numpyro.sample("scale", dist.Exponential(1.0))
    law = Bingham(scale * jnp.array([0.0, 1.0, 2.0]), validate_args=True)
    numpyro.sample("directions", law, obs=x)


def matrix_fisher_model(rotations):
    kappa = numpyro.sample("kappa", dist.Exponential(1.0))
    law = MatrixFisher(kappa * jnp.eye(3), validate_args=True)
    numpyro.sample("attitudes", law, obs=rotations)


def _run(model, data):
    mcmc = MCMC(GeometricHMC(model), num_warmup=5, num_samples=5, progress_bar=False)
    mcmc.run(jax.random.key(0), data)


def test_vmf_observation_off_the_sphere_is_refused_naming_the_site():
    """Was sampled (κ̂ = 3.62) without a word."""
    with pytest.raises(ValueError, match=r"observed site 'obs'.*VonMisesFisher.*index \(1,\)"):
        _run(vmf_model, OFF_SPHERE)


@pytest.mark.parametrize(
    ("model", "data", "site"),
    [
        (bingham_model, OFF_SPHERE, "directions"),
        (matrix_fisher_model, np.stack([np.eye(3), np.diag([1.0, 1.0, -1.0])]), "attitudes"),
    ],
    ids=["Bingham", "MatrixFisher"],
)
def test_the_other_distributions_refuse_data_off_their_support(model, data, site):
    with pytest.raises(ValueError, match=rf"observed site '{site}'.*batch index \(1,\)"):
        _run(model, data)


def _trace(model, *args):
    return trace(seed(model, jax.random.key(0))).get_trace(*args)


def test_observations_inside_the_support_or_not_validated_pass():
    check_observed_sites(_trace(vmf_model, ON_SPHERE))
    check_observed_sites(_trace(vmf_model, OFF_SPHERE, False))  # validate_args off: as NumPyro
    with numpyro.validation_enabled():  # NumPyro's switch validates every distribution
        with pytest.raises(ValueError, match="observed site 'obs'"):
            check_observed_sites(_trace(vmf_model, OFF_SPHERE, None))


def test_traced_observations_are_not_checked():
    """Under ``jit`` (``MCMC(..., jit_model_args=True)`` traces the data) nothing is concrete."""
    jax.jit(lambda x: check_observed_sites(_trace(vmf_model, x)) or 0.0)(OFF_SPHERE)
