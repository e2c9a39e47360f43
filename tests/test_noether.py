"""Stochastic Noether (paper ``prop:stoch-noether``): a momentum map is kept pathwise when every
Hamiltonian — ``h`` and each noise Hamiltonian — is invariant under the symmetry.

The Lagrange top (``I₁ = I₂``, ``χ = e₃``) is invariant under body rotations about ``e₃``, whose
momentum map is ``Π₃``. With noise Hamiltonians sharing the symmetry (``σΠ₃``, ``σΓ₃``) the
derived dissipation shares it too, and the ``splitting`` integrator over the declared exactly
solvable pieces (``heavy_top(..., split_hamiltonian=True)``, each piece invariant) keeps
``Π₃`` to round-off. Generic noise (``σΠ₁``) or a broken symmetry (``I₁ ≠ I₂``) make it move.
The joint-generator integrators keep it only to integrator accuracy (measured below).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample.integrators.drivers import DriftedBrownianMotion, TimeChangedBrownianMotion, simulate
from liesample.systems import heavy_top

LAGRANGE = {"inertia": (1.0, 1.0, 2.5), "mgl": 1.3, "chi": (0.0, 0.0, 1.0)}
START = np.array([0.4, -0.7, 0.9, 0.6, 0.3, -0.74])
NUM_STEPS = 2000


def invariant_noise(mu):
    return jnp.stack([mu[2], mu[5]])  # Π₃, Γ₃: invariant under rotations about e₃


def generic_noise(mu):
    return jnp.stack([mu[0], mu[2], mu[5]])  # adds Π₁, not invariant


def lagrange_top(noise=invariant_noise, **changes):
    # a noise sharing the symmetry keeps Π₃: it reaches only Π₃'s level set, on purpose
    reach = "level_set" if noise is invariant_noise else "test"
    top = heavy_top(**(LAGRANGE | changes), split_hamiltonian=True)
    return top.with_noise(noise, noise_reach=reach)


def pi3_drift_along_sampler(system, integrator="splitting", beta=2.0, sigma=1.0, dt=0.05):
    """max |Π₃(t) − Π₃(0)| over 4 Langevin chains (noise + derived dissipation + Hamiltonian).

    The sampler is built as a user would (its checks run) and stepped through its structure, as
    the runner does: ``dt``, ``σ`` and ``θ`` traced, so one compilation per system and
    integrator serves every step size."""
    algorithm = liesample.lie_poisson_langevin(
        system, beta=beta, sigma=sigma, step_size=dt, integrator=integrator
    )
    build, values = algorithm.structure
    values = {name: jnp.asarray(value) for name, value in values.items()}
    keys = jax.random.split(jax.random.key(11), 4)
    pi3 = _pi3_along_chains(algorithm.init(START), keys, values, build=build)
    return float(jnp.max(jnp.abs(pi3 - START[2])))


@functools.partial(liesample.jit, static_argnames=("build",))
def _pi3_along_chains(state, keys, values, *, build):
    """Π₃ along one chain per key from ``state`` (step ``k`` keyed ``fold_in(key, k)``)."""
    sampler = build(**values)

    def chain(key):
        def step(state, k):
            state, _ = sampler.step(jax.random.fold_in(key, k), state)
            return state, state.position[2]

        return jax.lax.scan(step, state, jnp.arange(NUM_STEPS))[1]

    return jax.vmap(chain)(keys)


def test_invariant_noise_keeps_pi3_to_round_off():
    assert pi3_drift_along_sampler(lagrange_top()) < 1e-12


@pytest.mark.slow  # the negative control; the kept invariant runs by default (the test above)
def test_generic_noise_breaks_it():
    assert pi3_drift_along_sampler(lagrange_top(generic_noise)) > 0.1


# slow: a second way to break the symmetry, beside test_generic_noise_breaks_it
@pytest.mark.slow
def test_broken_symmetry_breaks_it():
    """``I₁ ≠ I₂``: ``h`` is no longer invariant, so ``Π₃`` moves even with invariant noise."""
    assert pi3_drift_along_sampler(lagrange_top(inertia=(1.0, 1.6, 2.5))) > 0.1


@pytest.mark.slow  # generic noise breaking it runs by default
def test_tilted_centre_of_mass_breaks_it():
    assert pi3_drift_along_sampler(lagrange_top(chi=(0.3, 0.0, 1.0))) > 0.1


def test_joint_generator_keeps_it_to_integrator_accuracy():
    """Heun on the joint generator is equivariant but not a composition of invariant exact
    flows: Π₃ wanders at the size of the local error, shrinking with dt."""
    system = lagrange_top()
    coarse = pi3_drift_along_sampler(system, integrator="rkmk_heun", dt=0.05)
    fine = pi3_drift_along_sampler(system, integrator="rkmk_heun", dt=0.0125)
    assert 1e-10 < fine < coarse < 0.2, (coarse, fine)


@pytest.mark.parametrize(
    "driver",
    [
        # slow: Π₃ kept under a drifted driver; the default suite checks this with
        # test_noether.py::test_invariant_noise_keeps_pi3_to_round_off and, for the drifted
        # driver, test_drivers.py::test_casimirs_kept_pathwise_under_every_driver[splitting-drifted]
        pytest.param(
            DriftedBrownianMotion(drift=0.8, scale=1.2), id="drifted", marks=pytest.mark.slow
        ),
        pytest.param(
            TimeChangedBrownianMotion(lambda t: t + t**2), id="time-changed", marks=pytest.mark.slow
        ),
    ],
)
def test_kept_under_semimartingale_drivers(driver):
    """Without dissipation and with non-Brownian drivers the conservation law is the same."""
    for noise, bound in ((invariant_noise, None), (generic_noise, 0.1)):
        system = lagrange_top(noise)

        def one(key, system=system):
            return simulate(
                system,
                key,
                START,
                step_size=0.02,
                num_steps=1000,
                sigma=1.0,
                driver=driver,
                save_every=10,
            ).positions[:, 2]

        drift = float(
            jnp.max(jnp.abs(jax.vmap(one)(jax.random.split(jax.random.key(4), 4)) - START[2]))
        )
        if bound is None:
            assert drift < 1e-12
        else:
            assert drift > bound


def test_pieces_sum_to_the_hamiltonian():
    rng = np.random.default_rng(0)
    for gravity in (True, False):
        system = heavy_top(**LAGRANGE, gravity=gravity, split_hamiltonian=True)
        for mu in rng.normal(size=(5, 6)):
            total = sum(piece(mu) for piece in system.hamiltonian_pieces)
            np.testing.assert_allclose(total, system.hamiltonian(mu), rtol=1e-13)
    general = heavy_top(inertia=(1.0, 2.0, 4.0), split_hamiltonian=True)
    assert len(general.hamiltonian_pieces) == 4
    assert len(lagrange_top().hamiltonian_pieces) == 3  # the I₂ − I₁ piece is absent
