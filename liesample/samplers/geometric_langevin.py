"""Kinetic Langevin on Lie groups, spheres and products with ``Rᵈ``: the dissipative
symplectic diffusion on ``T*G`` (paper, ``sec:dissipation``) before reduction.

The SDE is ``dg = g (M⁻¹p)^ dt``, ``dp = ∇log π(g) dt − γ M⁻¹p dt + √(2γ) dW`` in the
left trivialisation (on a non-abelian group with ``M ∝ I`` per copy the Lie–Poisson term
``ad*_{M⁻¹p} p`` vanishes). Its invariant law is ``exp(−H)``, whose ``G``-marginal is
``π dHaar``. One transition (BlackJAX-shaped: ``init``, ``build_kernel``,
``as_top_level_api``):

1. the exact Ornstein–Uhlenbeck step of the friction and noise over ``h``:
   ``p ← e^{−γm⁻¹h} p + √(1 − e^{−2γm⁻¹h}) ξ``, ``ξ ~ N(0, M)`` (partial refreshment);
2. one geometric leapfrog step of size ``h`` (:func:`liesample.samplers.geometric.leapfrog`).

``adjusted=False`` (default) takes every finite step: the irreversible kinetic Langevin chain,
biased by ``O(h²)`` in the position law (the sequence ``O B A B O B A B …`` has the position
marginal of ``O_{h/2} BAB O_{h/2}``, which is second order). ``adjusted=True`` replaces 2. by
one-step HMC with the momentum flipped on rejection (Horowitz's generalised HMC): the proposal
``(g, p) ↦ (g', −p')`` is an involution preserving the Liouville measure, so the Metropolis
test followed by the flip ``p ↦ −p`` keeps ``exp(−H)`` exactly, at any step size.
A non-finite step is rejected (state kept) and flagged ``is_divergent`` in both variants.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from liesample import spaces
from liesample._validation import concrete_array, finite_float
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

__all__ = ["as_top_level_api", "build_kernel", "geometric_langevin", "init"]


def _check_friction(friction):
    if jnp.ndim(friction) != 0:
        raise ValueError(f"friction must be a scalar, got shape {jnp.shape(friction)}")
    if concrete_array(friction) is not None:  # traced values are checked where concrete
        finite_float("friction", friction, positive=True)


def _transition(
    rng_key,
    state: GeometricState,
    logdensity_fn,
    space,
    step_size,
    friction,
    inverse_mass,
    adjusted,
    divergence_threshold,
):
    key_noise, key_accept = jax.random.split(rng_key)
    momentum = spaces.ornstein_uhlenbeck(
        key_noise, space, state.position, state.momentum, inverse_mass, friction, step_size
    )
    value_and_grad = spaces.trivialised_value_and_grad(logdensity_fn, space)
    proposal = trajectory(value_and_grad, space, inverse_mass, step_size, 1, state, momentum)
    is_accepted, metropolis_rate, is_divergent, initial_energy, proposal_energy = metropolis(
        key_accept,
        space,
        inverse_mass,
        state,
        momentum,
        proposal,
        divergence_threshold,
        accept=adjusted,
    )
    position, new_momentum, logdensity, grad = proposal
    # Accepted: (g', p'). Rejected: (g, −p) when adjusted (the flip after the involution).
    kept_momentum = jax.tree.map(jnp.negative, momentum) if adjusted else momentum
    new_state = GeometricState(
        select(is_accepted, position, state.position),
        jnp.where(is_accepted, logdensity, state.logdensity),
        select(is_accepted, grad, state.logdensity_grad),
        select(is_accepted, new_momentum, kept_momentum),
    )
    acceptance_rate = metropolis_rate if adjusted else is_accepted.astype(metropolis_rate.dtype)
    info = GeometricInfo(
        acceptance_rate,
        is_accepted,
        is_divergent,
        jnp.where(is_accepted, proposal_energy, initial_energy),  # the new state's H
        jnp.asarray(1),
        metropolis_rate,
    )
    return new_state, info


def build_kernel(adjusted: bool = False, divergence_threshold: float = 1000.0):
    """``kernel(rng_key, state, logdensity_fn, space, step_size, friction,
    inverse_mass_matrix=None) -> (state, info)``; parameters may be traced (adaptation)."""
    if not isinstance(adjusted, bool):
        raise TypeError(f"adjusted must be a bool, got {adjusted!r}")
    check_divergence_threshold(divergence_threshold)

    def kernel(
        rng_key,
        state: GeometricState,
        logdensity_fn: Callable,
        space,
        step_size,
        friction,
        inverse_mass_matrix=None,
    ):
        check_step_size(step_size)
        _check_friction(friction)
        dtype = jnp.asarray(state.logdensity).dtype
        inverse_mass = spaces.check_inverse_mass(space, inverse_mass_matrix, dtype)
        return _transition(
            rng_key,
            state,
            logdensity_fn,
            space,
            step_size,
            friction,
            inverse_mass,
            adjusted,
            divergence_threshold,
        )

    return kernel


def as_top_level_api(
    logdensity_fn: Callable,
    space,
    step_size,
    friction,
    inverse_mass_matrix=None,
    *,
    adjusted: bool = False,
    divergence_threshold: float = 1000.0,
) -> Sampler:
    """Geometric kinetic Langevin on Lie groups, spheres and products with ``Rᵈ``.

    Parameters
    ----------
    logdensity_fn, space, inverse_mass_matrix
        As for :func:`liesample.geometric_hmc` (``log π`` with respect to Haar / uniform /
        Lebesgue measure).
    step_size : float
        ``h > 0``, the time step of the OU step and of the leapfrog step.
    friction : float
        ``γ > 0``; the momentum keeps a fraction ``e^{−γm⁻¹h}`` per step.
    adjusted : bool
        Metropolis-adjust each step (exact law) instead of taking it unadjusted.
    divergence_threshold : float
        ``ΔH`` above which a step is flagged divergent.
    """
    check_step_size(step_size)
    _check_friction(friction)
    if not isinstance(adjusted, bool):
        raise TypeError(f"adjusted must be a bool, got {adjusted!r}")
    check_divergence_threshold(divergence_threshold)
    inverse_mass = spaces.check_inverse_mass(space, inverse_mass_matrix)

    settings = {
        "sampler": "geometric_langevin",
        "space": repr(space),
        "step_size": setting(step_size),
        "step_size_source": "given",
        "friction": setting(friction),
        "adjusted": adjusted,
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
            friction,
            inverse_mass,
            adjusted,
            divergence_threshold,
        )

    return Sampler(init_fn, step_fn, settings=settings, check_positions=check_starts(space))


geometric_langevin = sampling_api(
    as_top_level_api, init, build_kernel, "geometric_langevin", __name__
)
