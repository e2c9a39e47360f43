"""Geometric HMC on Lie groups, spheres and products with ``Rᵈ``: Metropolis-adjusted.

A BlackJAX-shaped module (``init``, ``build_kernel``, ``as_top_level_api``). One transition:

1. draw ``p ~ N(0, M)`` in algebra coordinates (tangent on spheres);
2. ``L`` leapfrog steps (:func:`liesample.samplers.geometric.leapfrog`): half kick by the
   trivialised gradient, exact exp-map drift ``g ← g exp(ε M⁻¹p)`` (geodesic flow on spheres),
   half kick;
3. accept with probability ``min(1, e^{−ΔH})``. The leapfrog is symplectic and reversible on
   ``T*G ≅ G × g*``, so the chain leaves ``π(g) dHaar(g)`` exactly invariant at any step size
   (the HMC of lattice gauge theory, Duane et al. 1987).

The drift is exact only for a bi-invariant kinetic energy (``M ∝ I`` on every copy of a
non-abelian group: see :mod:`liesample.spaces`), which is why the inverse mass is one scalar
per copy of a group or sphere. A rejected or non-finite proposal keeps the state; a non-finite
one is flagged ``is_divergent``.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from liesample import spaces
from liesample.samplers.contract import Sampler, sampling_api, setting
from liesample.samplers.geometric import (
    GeometricInfo,
    GeometricState,
    check_divergence_threshold,
    check_starts,
    init,
    metropolis,
    select,
    trajectory,
)
from liesample.samplers.magnetic import check_step_size
from liesample.samplers.magnetic_hmc import _check_integer

__all__ = ["as_top_level_api", "build_kernel", "geometric_hmc", "init"]


def _transition(
    rng_key,
    state: GeometricState,
    logdensity_fn,
    space,
    step_size,
    num_integration_steps,
    inverse_mass,
    divergence_threshold,
):
    key_momentum, key_accept = jax.random.split(rng_key)
    momentum = spaces.sample_momentum(key_momentum, space, state.position, inverse_mass)
    value_and_grad = spaces.trivialised_value_and_grad(logdensity_fn, space)
    proposal = trajectory(
        value_and_grad, space, inverse_mass, step_size, num_integration_steps, state, momentum
    )
    is_accepted, acceptance_rate, is_divergent, _, proposal_energy = metropolis(
        key_accept, space, inverse_mass, state, momentum, proposal, divergence_threshold
    )
    position, new_momentum, logdensity, grad = proposal
    new_state = GeometricState(
        select(is_accepted, position, state.position),
        jnp.where(is_accepted, logdensity, state.logdensity),
        select(is_accepted, grad, state.logdensity_grad),
        select(is_accepted, new_momentum, momentum),
    )
    info = GeometricInfo(
        acceptance_rate,
        is_accepted,
        is_divergent,
        proposal_energy,
        jnp.asarray(num_integration_steps),
        acceptance_rate,
    )
    return new_state, info


def build_kernel(divergence_threshold: float = 1000.0):
    """``kernel(rng_key, state, logdensity_fn, space, step_size, num_integration_steps,
    inverse_mass_matrix=None) -> (state, info)``; parameters may be traced (adaptation)."""
    check_divergence_threshold(divergence_threshold)

    def kernel(
        rng_key,
        state: GeometricState,
        logdensity_fn: Callable,
        space,
        step_size,
        num_integration_steps,
        inverse_mass_matrix=None,
    ):
        check_step_size(step_size)
        _check_integer("num_integration_steps", num_integration_steps)
        dtype = jnp.asarray(state.logdensity).dtype
        inverse_mass = spaces.check_inverse_mass(space, inverse_mass_matrix, dtype)
        return _transition(
            rng_key,
            state,
            logdensity_fn,
            space,
            step_size,
            num_integration_steps,
            inverse_mass,
            divergence_threshold,
        )

    return kernel


def as_top_level_api(
    logdensity_fn: Callable,
    space,
    step_size,
    num_integration_steps: int,
    inverse_mass_matrix=None,
    *,
    divergence_threshold: float = 1000.0,
) -> Sampler:
    """Geometric HMC on Lie groups, spheres and products with ``Rᵈ`` (Metropolis-adjusted).

    Parameters
    ----------
    logdensity_fn : callable
        ``log π`` of a position (pytree like ``space``), with respect to Haar measure on groups,
        the uniform law on spheres and Lebesgue measure on ``Euclidean`` blocks (constants
        do not matter). It must be differentiable in the ambient coordinates (matrix entries,
        unit vectors, angles): the trivialised gradient is taken by autodiff along
        ``g (I + εX)``, which has the velocity of ``g exp(εX)``.
    space : Space or pytree of spaces
        From :mod:`liesample.spaces` (``Euclidean``, ``Sphere``, ``SO``, ``SU``, ``U1``).
    step_size : float
        Leapfrog step ``ε > 0``.
    num_integration_steps : int
        Leapfrog steps per transition.
    inverse_mass_matrix : None, float or pytree
        ``M⁻¹``: unit by default; a positive scalar; or a pytree like ``space`` with one value
        per copy of a group or sphere and one per coordinate of ``Euclidean`` and ``U1``
        (what :func:`liesample.window_adaptation` returns).
    divergence_threshold : float
        ``ΔH`` above which a transition is flagged divergent.
    """
    check_step_size(step_size)
    _check_integer("num_integration_steps", num_integration_steps)
    check_divergence_threshold(divergence_threshold)
    inverse_mass = spaces.check_inverse_mass(space, inverse_mass_matrix)

    settings = {
        "sampler": "geometric_hmc",
        "space": repr(space),
        "step_size": setting(step_size),
        "step_size_source": "given",
        "num_integration_steps": setting(num_integration_steps),
        "divergence_threshold": setting(divergence_threshold),
    }

    def init_fn(position, rng_key=None):
        del rng_key
        return init(position, logdensity_fn, space)

    def step_fn(rng_key, state):
        return _transition(
            rng_key,
            state,
            logdensity_fn,
            space,
            step_size,
            num_integration_steps,
            inverse_mass,
            divergence_threshold,
        )

    return Sampler(init_fn, step_fn, settings=settings, check_positions=check_starts(space))


geometric_hmc = sampling_api(as_top_level_api, init, build_kernel, "geometric_hmc", __name__)
