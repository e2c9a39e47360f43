"""Kinetic Langevin on Lie groups, spheres and products with ``Rᵈ``: the dissipative
symplectic diffusion on ``T*G`` (paper, ``sec:dissipation``) before reduction.

The SDE is ``dg = g (M⁻¹p)^ dt``, ``dp = ∇log π(g) dt + G M⁻¹p dt − γ M⁻¹p dt + √(2γ) dW`` in
the left trivialisation (on a non-abelian group with ``M ∝ I`` per copy the Lie–Poisson term
``ad*_{M⁻¹p} p`` vanishes; the magnetic term ``G M⁻¹p``, optional, acts on the ``Euclidean``
coordinates). Its invariant law is ``exp(−H)`` for every antisymmetric ``G``, and its
``G``-marginal is ``π dHaar``. One transition (BlackJAX-shaped: ``init``, ``build_kernel``,
``as_top_level_api``), from the one-effect steps of :mod:`liesample.geometry.cotangent`:

- ``adjusted=False`` (default): one step of the scheme ``O B A B`` (``O`` the exact
  Ornstein–Uhlenbeck step ``p ← e^{−γm⁻¹h} p + √(1 − e^{−2γm⁻¹h}) ξ``, ``ξ ~ N(0, M)``;
  ``B A B`` a geometric leapfrog step), every finite step taken: the irreversible kinetic
  Langevin chain, biased by ``O(h²)`` in the position law (the sequence ``O B A B O B A B …``
  has the position marginal of ``O_{h/2} BAB O_{h/2}``, which is second order).
  (:func:`liesample.magnetic_langevin` runs the scheme ``B A O A B`` instead.)
- ``adjusted=True``: the ``O`` step, then one-step HMC with the momentum (and the field's
  sign) flipped on rejection (Horowitz's generalised HMC): the proposal
  ``(g, p, s) ↦ (g', −p', −s)`` is an involution preserving the Liouville measure, so the
  Metropolis test followed by the flip ``(p, s) ↦ (−p, −s)`` keeps ``exp(−H)`` exactly, at any
  step size.

A non-finite step is rejected (state kept) and flagged ``is_divergent`` in both variants.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from liesample.foundation.validation import concrete_array, finite_float
from liesample.geometry.cotangent import LEAPFROG, OBAB
from liesample.samplers.contract import Sampler, sampling_api, setting
from liesample.samplers.cotangent.geometric import (
    GeometricInfo,
    GeometricState,
    Integrator,
    check_divergence_threshold,
    check_starts,
    hamiltonian_transition,
    init,
    make_integrator,
    unadjusted_transition,
)
from liesample.samplers.cotangent.magnetic import check_step_size

__all__ = ["as_top_level_api", "build_kernel", "geometric_langevin", "init"]


def check_friction(friction):
    if jnp.ndim(friction) != 0:
        raise ValueError(f"friction must be a scalar, got shape {jnp.shape(friction)}")
    if concrete_array(friction) is not None:  # traced values are checked where concrete
        finite_float("friction", friction, positive=True)


def transition(
    rng_key,
    state: GeometricState,
    integrator: Integrator,
    friction,
    adjusted,
    divergence_threshold,
    scheme=OBAB,
):
    """One geometric Langevin transition (``integrator`` from
    :func:`liesample.samplers.cotangent.geometric.make_integrator` for ``scheme``, or for the leapfrog
    when ``adjusted``)."""
    if not adjusted:
        new_state, outcome = unadjusted_transition(
            rng_key, state, integrator, friction, scheme, divergence_threshold
        )
        is_accepted, metropolis_rate, is_divergent, new_energy = outcome
        acceptance_rate = is_accepted.astype(metropolis_rate.dtype)
    else:
        key_noise, key_accept = jax.random.split(rng_key)
        momentum = integrator.bundle.ornstein_uhlenbeck(
            key_noise, state.position, state.momentum, friction, integrator.step_size
        )
        new_state, outcome = hamiltonian_transition(
            key_accept, state, momentum, integrator, 1, divergence_threshold
        )
        is_accepted, metropolis_rate, is_divergent, initial_energy, proposal_energy = outcome
        acceptance_rate = metropolis_rate
        new_energy = jnp.where(is_accepted, proposal_energy, initial_energy)
    info = GeometricInfo(
        acceptance_rate,
        is_accepted,
        is_divergent,
        new_energy,
        jnp.asarray(1),
        metropolis_rate,
    )
    return new_state, info


def build_kernel(adjusted: bool = False, divergence_threshold: float = 1000.0):
    """``kernel(rng_key, state, logdensity_fn, space, step_size, friction,
    inverse_mass_matrix=None, magnetic_field=None) -> (state, info)``; parameters may be traced
    (adaptation)."""
    if not isinstance(adjusted, bool):
        raise TypeError(f"adjusted must be a bool, got {adjusted!r}")
    check_divergence_threshold(divergence_threshold)
    scheme = LEAPFROG if adjusted else OBAB

    def kernel(
        rng_key,
        state: GeometricState,
        logdensity_fn: Callable,
        space,
        step_size,
        friction,
        inverse_mass_matrix=None,
        magnetic_field=None,
    ):
        check_step_size(step_size)
        check_friction(friction)
        integrator = make_integrator(
            logdensity_fn,
            space,
            step_size,
            inverse_mass_matrix,
            magnetic_field,
            scheme,
            jnp.asarray(state.logdensity).dtype,
            precompute=False,
        )
        return transition(rng_key, state, integrator, friction, adjusted, divergence_threshold)

    return kernel


def as_top_level_api(
    logdensity_fn: Callable,
    space,
    step_size,
    friction,
    inverse_mass_matrix=None,
    magnetic_field=None,
    *,
    adjusted: bool = False,
    divergence_threshold: float = 1000.0,
) -> Sampler:
    """Geometric kinetic Langevin on Lie groups, spheres and products with ``Rᵈ``.

    Parameters
    ----------
    logdensity_fn, space, inverse_mass_matrix, magnetic_field
        As for :func:`liesample.geometric_hmc` (``log π`` with respect to Haar / uniform /
        Lebesgue measure; the field acts on the Euclidean coordinates).
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
    check_friction(friction)
    if not isinstance(adjusted, bool):
        raise TypeError(f"adjusted must be a bool, got {adjusted!r}")
    check_divergence_threshold(divergence_threshold)
    scheme = LEAPFROG if adjusted else OBAB
    integrator = make_integrator(
        logdensity_fn, space, step_size, inverse_mass_matrix, magnetic_field, scheme
    )

    settings = {
        "sampler": "geometric_langevin",
        "space": repr(space),
        "step_size": setting(step_size),
        "step_size_source": "given",
        "friction": setting(friction),
        "adjusted": adjusted,
        "divergence_threshold": setting(divergence_threshold),
    }
    if magnetic_field is not None:
        settings["magnetic"] = True

    def init_fn(position, rng_key=None):
        del rng_key
        return init(position, logdensity_fn, space)

    def step_fn(rng_key, state):
        return transition(rng_key, state, integrator, friction, adjusted, divergence_threshold)

    return Sampler(init_fn, step_fn, settings=settings, check_positions=check_starts(space))


geometric_langevin = sampling_api(
    as_top_level_api, init, build_kernel, "geometric_langevin", __name__
)
