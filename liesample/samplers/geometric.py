"""Shared pieces of the geometric samplers on ``T*G`` (left-trivialised, ``G × g*``).

The Hamiltonian is ``H(g, p) = −log π(g) + ½ pᵀM⁻¹p`` on a space (or product of spaces) from
:mod:`liesample.spaces`; ``log π`` is a log-density with respect to the product of Haar
(groups), uniform (spheres) and Lebesgue (``Euclidean``) measures. This module holds the chain
state, the ``Info`` contract, ``init`` and the geometric leapfrog shared by
:mod:`liesample.samplers.geometric_hmc` and :mod:`liesample.samplers.geometric_langevin`.

The leapfrog is a Strang splitting of ``H = U + K`` into two exactly solvable pieces:

- the potential ``U``: ``ġ = 0``, ``ṗ = ∇log π(g)`` (left-trivialised gradient; the
  Lie–Poisson term ``ad*_{∂U/∂p} p`` vanishes since ``U`` does not depend on ``p``);
- the kinetic ``K``: the exp-map drift of each space (``g ← g exp(t M⁻¹p)``, the geodesic flow
  on spheres, translations on ``Rᵈ``).

Both are exact Hamiltonian flows on ``T*G`` with its canonical symplectic form, so their
symmetric composition is symplectic (it preserves Haar × Lebesgue, the Liouville measure) and
reversible under ``p ↦ −p``: the ingredients of an exact Metropolis test.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from liesample import spaces
from liesample._validation import concrete_array

__all__ = [
    "GeometricInfo",
    "GeometricState",
    "check_starts",
    "energy",
    "init",
    "leapfrog",
    "metropolis",
    "select",
    "trajectory",
]


class GeometricState(NamedTuple):
    """State of a chain.

    position : a point of the space (pytree like the space).
    logdensity : ``log π(position)``.
    logdensity_grad : the trivialised gradient (algebra coordinates, pytree like the space).
    momentum : the momentum carried between transitions (Langevin; HMC redraws it).
    """

    position: object
    logdensity: jax.Array
    logdensity_grad: object
    momentum: object


class GeometricInfo(NamedTuple):
    """What one transition did.

    acceptance_rate : ``min(1, e^{−ΔH})`` (0 for a non-finite proposal); for the unadjusted
        Langevin sampler 1 for a step taken and 0 for a step rejected as non-finite (the
        library's Info contract for unadjusted samplers).
    is_accepted : whether the proposal was taken.
    is_divergent : the proposal's state or energy is non-finite, or ``ΔH`` exceeds the
        divergence threshold.
    energy : ``H`` of the proposal for HMC (as in BlackJAX), of the new state for Langevin
        (``inf`` when non-finite).
    num_integration_steps : leapfrog steps (gradient evaluations) of the transition.
    metropolis_rate : ``min(1, e^{−ΔH})`` of the proposal, also for unadjusted chains (what
        step-size adaptation targets).
    """

    acceptance_rate: jax.Array
    is_accepted: jax.Array
    is_divergent: jax.Array
    energy: jax.Array
    num_integration_steps: jax.Array
    metropolis_rate: jax.Array


def init(position, logdensity_fn: Callable, space) -> GeometricState:
    """Initial state; raises if ``position`` is off the space or ``log π`` is not finite there."""
    spaces.check_position(space, position)
    value_and_grad = spaces.trivialised_value_and_grad(logdensity_fn, space)
    logdensity, grad = value_and_grad(position)
    values = concrete_array(
        jnp.concatenate([jnp.ravel(g) for g in jax.tree.leaves(grad)] + [jnp.ravel(logdensity)])
    )
    if values is not None and not np.all(np.isfinite(values)):
        raise ValueError(
            "logdensity_fn or its gradient is not finite at the initial position; start the "
            "chain where log π is finite"
        )
    return GeometricState(position, logdensity, grad, spaces.zero_momentum(space, position))


def check_starts(space):
    """The runner's ``check_positions`` hook: every chain's start (leading axis) on the space,
    the first bad one named ``initial_positions[c]``."""

    def check_positions(positions, **_):
        leaves = jax.tree.leaves(positions)
        num_chains = np.shape(leaves[0])[0] if leaves and np.ndim(leaves[0]) else 0
        for chain in range(num_chains):
            start = jax.tree.map(lambda a: a[chain], positions)
            spaces.check_position(space, start, f"initial_positions[{chain}]")

    return check_positions


def check_divergence_threshold(divergence_threshold):
    if not (np.ndim(divergence_threshold) == 0 and float(divergence_threshold) > 0):
        raise ValueError(f"divergence_threshold must be > 0, got {divergence_threshold!r}")


def energy(space, logdensity, momentum, inverse_mass):
    """``H = −log π + ½ pᵀM⁻¹p``."""
    return -logdensity + spaces.kinetic_energy(space, momentum, inverse_mass)


def _axpy(a, x, y):
    return jax.tree.map(lambda u, v: u + a * v, x, y)


def leapfrog(value_and_grad, space, inverse_mass, step_size):
    """One step ``(g, p, ∇log π) -> (g, p, log π, ∇log π)``: half kick, exp-map drift, half
    kick (kicks are tangent on spheres: the gradient is Riemannian)."""

    def step(position, momentum, grad):
        momentum = _axpy(0.5 * step_size, momentum, grad)
        position, momentum = spaces.flow(space, position, momentum, inverse_mass, step_size)
        logdensity, grad = value_and_grad(position)
        momentum = _axpy(0.5 * step_size, momentum, grad)
        return position, momentum, logdensity, grad

    return step


def trajectory(value_and_grad, space, inverse_mass, step_size, num_steps, state, momentum):
    """``num_steps`` leapfrog steps from ``(state.position, momentum)``."""
    step = leapfrog(value_and_grad, space, inverse_mass, step_size)

    def body(_, carry):
        return step(carry[0], carry[1], carry[3])

    return jax.lax.fori_loop(
        0, num_steps, body, (state.position, momentum, state.logdensity, state.logdensity_grad)
    )


def _all_finite(tree):
    return jnp.all(jnp.array([jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(tree)]))


def metropolis(
    rng_key, space, inverse_mass, state, momentum, proposal, divergence_threshold, accept=True
):
    """Accept/reject the proposal ``(g', p', log π', ∇')`` from ``(state, momentum)``.

    Returns ``(is_accepted, acceptance_rate, is_divergent, initial energy, proposal energy)``
    (``acceptance_rate = min(1, e^{−ΔH})``, 0 when non-finite). With
    ``accept=False`` (unadjusted chains) every finite proposal is taken. A non-finite proposal
    (state or energy) is always rejected and flagged divergent.
    """
    position, new_momentum, logdensity, grad = proposal
    initial = energy(space, state.logdensity, momentum, inverse_mass)
    final = energy(space, logdensity, new_momentum, inverse_mass)
    delta = final - initial
    finite = (
        jnp.isfinite(delta)
        & _all_finite(position)
        & _all_finite(new_momentum)
        & _all_finite(grad)
    )
    delta = jnp.where(finite, delta, jnp.inf)
    acceptance_rate = jnp.where(finite, jnp.minimum(1.0, jnp.exp(-delta)), 0.0)
    is_divergent = ~finite | (delta > divergence_threshold)
    if accept:
        u = jax.random.uniform(rng_key, (), acceptance_rate.dtype)
        is_accepted = u < acceptance_rate
    else:
        is_accepted = finite
    final = jnp.where(finite, final, jnp.inf)
    return is_accepted, acceptance_rate, is_divergent, initial, final


def select(condition, new, old):
    """``new`` where ``condition`` else ``old``, leaf by leaf."""
    return jax.tree.map(lambda a, b: jnp.where(condition, a, b), new, old)
