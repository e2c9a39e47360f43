"""β < 0 by the default path (no step size given: the step is chosen and tuned by the
sampler), on every orbit system whose Gibbs law is normalisable there; and a loud refusal
where it is not (the heavy top: its orbits are not compact)."""

import math

import arviz as az
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample import systems
from liesample.systems.zeitlin import random_vorticity
from liesample.targets import RestrictedGaussian

INERTIA, RADIUS = (1.0, 2.0, 3.0), 1.0


def _z(tree, values, exact):
    """``(mean − exact) / MCSE`` of draws ``values (chain, draw, k)``, MCSE from ArviZ."""
    posterior = az.from_dict({"posterior": {"f": values}})
    mcse = az.mcse(posterior, method="mean")["f"].values
    return (values.reshape(-1, values.shape[-1]).mean(0) - exact) / mcse


@pytest.mark.parametrize(
    "beta",
    [
        # slow: the adjusted rigid body's law again; the default suite checks the adjusted
        # sampler's exact law with tests/test_zeitlin.py's N = 3 orbit at a large step
        pytest.param(-2.0, marks=pytest.mark.slow),
        pytest.param(-6.0, marks=pytest.mark.slow),
    ],
)
def test_adjusted_rigid_body_at_negative_beta_by_the_default_path(beta):
    """The restricted Gaussian at β < 0 concentrates on the largest-inertia axis (maximum
    energy); the adjusted sampler tunes its step by dual averaging and is exact."""
    target = RestrictedGaussian(INERTIA, beta, RADIUS)
    exact = np.diag(np.asarray(target.second_moments()))
    system = systems.rigid_body(INERTIA)
    sampler = liesample.adjusted_lie_poisson(system, beta=beta)
    starts = target.sample(jax.random.key(1), 16)
    tree = liesample.sample(sampler, jax.random.key(2), starts, 1000, progress_bar=False)
    step = tree.attrs["step_size"]
    assert np.isfinite(step) and step > 0
    z = _z(tree, tree.posterior["mu"].values ** 2, exact)
    assert np.all(np.abs(z) < 4.5), z
    # not vacuous: the β > 0 law differs by many MCSE
    mirror = np.diag(np.asarray(RestrictedGaussian(INERTIA, -beta, RADIUS).second_moments()))
    assert np.max(np.abs(_z(tree, tree.posterior["mu"].values ** 2, mirror))) > 10


def test_unadjusted_rigid_body_at_negative_beta_by_the_default_path():
    """The unadjusted sampler picks its step from the bias model at β < 0; its moments agree
    with the exact law within 4.5 MCSE plus the bias the model allows (a fraction
    ``bias_tolerance`` of the sd)."""
    beta = -2.0
    target = RestrictedGaussian(INERTIA, beta, RADIUS)
    second = np.asarray(target.second_moments())
    sampler = liesample.lie_poisson_langevin(systems.rigid_body(INERTIA), beta=beta)
    starts = target.sample(jax.random.key(3), 16)
    tree = liesample.sample(sampler, jax.random.key(4), starts, 1000, progress_bar=False)
    assert tree.attrs["step_size_source"].startswith("warm-up bias model")
    mu = tree.posterior["mu"].values
    posterior = az.from_dict({"posterior": {"mu": mu}})
    mcse = az.mcse(posterior, method="mean")["mu"].values
    sd = np.sqrt(np.diag(second))
    error = np.abs(mu.reshape(-1, 3).mean(0))  # exact mean 0
    tolerance = liesample.integrators.accuracy.DEFAULT_RELATIVE_TOLERANCE
    np.testing.assert_array_less(error, 4.5 * mcse + tolerance * sd)


def test_heat_bath_spin_chain_at_negative_beta():
    """An antiferromagnetic chain: the heat bath at β < 0 matches the exact bond energy."""
    beta, length = -1.5, 16
    system = systems.heisenberg((length,), coupling=1.0)
    reference = system.reference(beta)
    sampler = liesample.heisenberg_heat_bath(system, beta=beta)
    starts = np.tile(system.default_position, (8, 1, 1))
    tree = liesample.sample(
        sampler, jax.random.key(5), starts, 400, event_dims=("site", "component"),
        progress_bar=False,
    )  # fmt: skip
    energy = tree.sample_stats["hamiltonian"].values[..., None]
    z = _z(tree, energy, reference.energy_mean())
    assert abs(float(z[0])) < 4.5, z


@pytest.mark.slow  # the default path at β < 0 runs by default on the rigid body and the spin chain
def test_zeitlin_n3_at_negative_beta_by_the_default_path():
    """Zeitlin su(3) at β < 0 (energy pushed into the largest scale): the adjusted sampler with
    no step size given matches the exact orbit law (Haar importance sampling)."""
    beta = -3.0
    system = systems.zeitlin_euler(3, noise_degree=2, position=random_vorticity(3, seed=2))
    law = system.reference(beta, system.default_position)
    starts = law.orbit_samples(np.random.default_rng(0), 16)
    sampler = liesample.adjusted_lie_poisson(system, beta=beta)
    tree = liesample.sample(sampler, jax.random.key(6), starts, 1500, progress_bar=False)
    assert np.isfinite(tree.attrs["step_size"])
    energy = tree.sample_stats["hamiltonian"].values
    exact, exact_error, _ = law.expectations(
        lambda x: np.asarray(system.hamiltonian(jnp.asarray(x)))[:, None], num_samples=100_000
    )
    means = energy.mean(axis=1)
    mcse = means.std(ddof=1) / math.sqrt(len(means))
    z = (means.mean() - exact[0]) / math.hypot(mcse, exact_error[0])
    assert abs(z) < 4.5, (means.mean(), exact, z)
    uniform, _, _ = law.__class__(law.hamiltonian, law.position, 0.0).expectations(
        lambda x: np.asarray(system.hamiltonian(jnp.asarray(x)))[:, None], num_samples=20_000
    )
    assert means.mean() > uniform[0]  # β < 0 raises the energy above the uniform law's


@pytest.mark.parametrize("beta", [0.0, -1.0])
def test_heavy_top_refuses_beta_where_its_law_is_not_normalisable(beta):
    system = systems.heavy_top()
    for build in (liesample.lie_poisson_langevin, liesample.adjusted_lie_poisson):
        with pytest.raises(ValueError, match="not normalisable"):
            build(system, beta=beta)


@pytest.mark.slow  # dual averaging on Zeitlin runs by default in the condensation example
def test_adjusted_zeitlin_at_beta_zero_keeps_a_bounded_step_and_the_uniform_law():
    """At β = 0 every proposal is accepted: the warm-up's step stays bounded
    (``MAX_STEP_FACTOR`` times the construction's step) and the energy is that of the uniform
    law on the orbit."""
    from liesample.samplers.orbit.adjusted_lie_poisson import MAX_STEP_FACTOR

    system = systems.zeitlin_euler(3, noise_degree=2, position=random_vorticity(3, seed=2))
    law = system.reference(0.0, system.default_position)
    sampler = liesample.adjusted_lie_poisson(system, beta=0.0)
    starts = law.orbit_samples(np.random.default_rng(1), 8)
    tree = liesample.sample(sampler, jax.random.key(7), starts, 300, progress_bar=False)
    assert tree.attrs["step_size"] <= MAX_STEP_FACTOR * sampler.settings["step_size"] * (1 + 1e-12)
    energy = tree.sample_stats["hamiltonian"].values
    assert np.all(np.isfinite(energy))
    exact, exact_error, _ = law.expectations(
        lambda x: np.asarray(system.hamiltonian(jnp.asarray(x)))[:, None], num_samples=100_000
    )
    means = energy.mean(axis=1)
    mcse = means.std(ddof=1) / math.sqrt(len(means))
    assert abs(means.mean() - exact[0]) < 4.5 * math.hypot(mcse, exact_error[0])
