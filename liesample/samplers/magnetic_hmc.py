"""Metropolis-adjusted magnetic HMC (Tripuraneni et al. 2017) for any ``logdensity_fn``.

A BlackJAX-shaped module (``MagneticHMCState``/``MagneticHMCInfo``, ``init``, ``build_kernel``,
``as_top_level_api``). The extended target is ``π(q) · N(p; 0, M) · ½`` over ``(q, p, s)``,
``s = ±1`` the sign of the field. One transition (MATH.md §3):

1. momentum refreshment ``p ← α p + √(1 − α²) ξ``, ``ξ ~ N(0, M)`` (``α`` =
   ``momentum_persistence``; ``α = 0``, the default, is full refreshment as in ``blackjax.hmc``);
2. ``L`` magnetic leapfrog steps: half kick ``p += ε/2 ∇log π(q)``, the *exact* kinetic+magnetic
   flow of ``q̇ = M⁻¹p, ṗ = sG M⁻¹p`` over ``ε`` (:func:`liesample.samplers.magnetic.magnetic_flow`,
   one ``expm`` per transition, valid for singular ``G``), half kick. Each piece preserves
   volume (``tr(GM⁻¹) = 0``), the composition is symmetric;
3. the proposal ``(q, p, s) ↦ (q', −p', −s)`` is an involution (running the flow of ``−sG`` from
   ``(q', −p')`` retraces the path), so it is accepted with probability ``min(1, e^{−ΔH})``,
   ``H = −log π(q) + ½pᵀM⁻¹p`` (the field does no work);
4. with ``persistent=True`` (default) the chain then applies the measure-preserving flip
   ``(p, s) ↦ (−p, −s)`` (Horowitz 1991): an accepted move keeps the field's sign and the
   direction of motion, a rejection reverses both. With ``persistent=False`` the sign flips on
   acceptance, literally as in Tripuraneni et al. (2017, Alg. 1); combined with partial
   refreshment that reverses the momentum on every acceptance, so the chain backtracks
   (valid, but slow: use ``persistent=True`` with ``momentum_persistence > 0``).

Non-finite energies are rejected and flagged ``is_divergent``; the state is then kept.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import blackjax
import jax
import jax.numpy as jnp
import numpy as np

from liesample._validation import concrete_array
from liesample.samplers.contract import Sampler, sampling_api, setting
from liesample.samplers.magnetic import (
    MagneticFlow,
    check_inverse_mass_matrix,
    check_magnetic_field,
    check_starts,
    check_step_size,
    initial_values,
    magnetic_flow,
    make_metric,
    ravel,
    ravel_logdensity,
)

__all__ = [
    "MagneticHMCInfo",
    "MagneticHMCState",
    "as_top_level_api",
    "build_kernel",
    "init",
    "magnetic_hmc",
    "magnetic_leapfrog",
]


class MagneticHMCState(NamedTuple):
    """State of a chain.

    position : the point ``q`` (any pytree of arrays).
    logdensity, logdensity_grad : ``log π(q)`` and its gradient (pytree like ``position``).
    momentum : flat ``(d,)`` momentum carried between transitions (used only when
        ``momentum_persistence > 0``; ``init`` sets it to zero).
    magnetic_sign : ``s = ±1``, the sign of the field for the next trajectory.
    """

    position: jax.Array
    logdensity: jax.Array
    logdensity_grad: jax.Array
    momentum: jax.Array
    magnetic_sign: jax.Array


class MagneticHMCInfo(NamedTuple):
    """What one transition did (the Info contract of :mod:`liesample.samplers.contract`, in
    BlackJAX's field order).

    acceptance_rate : ``min(1, e^{−ΔH})`` (0 for a non-finite proposal).
    is_accepted : whether the proposal was accepted.
    is_divergent : ``ΔH`` above ``divergence_threshold``, or a non-finite proposal (rejected).
    energy : ``H`` of the proposal (``-log π + kinetic``; ``inf`` for a non-finite one), as in
        BlackJAX's HMC.
    num_integration_steps : leapfrog steps (gradient evaluations) of the trajectory.
    magnetic_sign : sign of the field used for this trajectory.
    """

    acceptance_rate: jax.Array
    is_accepted: jax.Array
    is_divergent: jax.Array
    energy: jax.Array
    num_integration_steps: jax.Array
    magnetic_sign: jax.Array


def init(position, logdensity_fn: Callable, rng_key=None) -> MagneticHMCState:
    """Initial state (no key needed; ``rng_key`` is ignored). Raises if ``log π`` is non-finite."""
    del rng_key
    logdensity, grad, momentum = initial_values(position, logdensity_fn)
    return MagneticHMCState(position, logdensity, grad, momentum, jnp.ones((), momentum.dtype))


def magnetic_leapfrog(flat_logdensity_fn, metric, flow: MagneticFlow, step_size):
    """One magnetic leapfrog step ``(q, p, ∇log π) -> (q, p, log π, ∇log π)``.

    Kick ``ε/2``, exact kinetic+magnetic flow ``ε``, kick ``ε/2`` (the flow replaces the drift
    of velocity Verlet; with ``G = 0`` this *is* velocity Verlet).
    """
    value_and_grad = jax.value_and_grad(flat_logdensity_fn)

    def step(position, momentum, grad):
        momentum = momentum + 0.5 * step_size * grad
        position, momentum = flow(metric, position, momentum)
        logdensity, grad = value_and_grad(position)
        momentum = momentum + 0.5 * step_size * grad
        return position, momentum, logdensity, grad

    return step


def _check_integer(name, value):
    array = concrete_array(value)
    if np.ndim(value) != 0:
        raise ValueError(f"{name} must be a scalar integer, got shape {np.shape(value)}")
    if array is None:
        return
    integral = array.dtype.kind in "iu" or (array.dtype.kind == "f" and float(array).is_integer())
    if array.dtype.kind == "b" or not integral or array < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")


def _transition(
    rng_key,
    state: MagneticHMCState,
    logdensity_fn,
    step_size,
    metric,
    flows,
    num_integration_steps,
    momentum_persistence,
    divergence_threshold,
    persistent,
):
    """The transition given the flows ``(flow(+G), flow(−G))`` already computed."""
    flat_q, flat_logdensity_fn, unravel = ravel_logdensity(state.position, logdensity_fn)
    flat_grad = ravel(state.logdensity_grad)
    dtype = flat_q.dtype
    sign = state.magnetic_sign
    positive = sign > 0
    flow = jax.tree.map(lambda a, b: jnp.where(positive, a, b), *flows)

    key_momentum, key_accept = jax.random.split(rng_key)
    xi = metric.sample_momentum(key_momentum, dtype)
    alpha = jnp.asarray(momentum_persistence, dtype)
    momentum = alpha * state.momentum + jnp.sqrt(1.0 - alpha**2) * xi

    step = magnetic_leapfrog(flat_logdensity_fn, metric, flow, step_size)

    def body(_, carry):
        return step(*carry[:2], carry[3])

    q, p, logdensity, grad = jax.lax.fori_loop(
        0, num_integration_steps, body, (flat_q, momentum, state.logdensity, flat_grad)
    )
    initial_energy = -state.logdensity + metric.kinetic_energy(momentum)
    new_energy = -logdensity + metric.kinetic_energy(p)
    delta = new_energy - initial_energy
    finite = jnp.isfinite(delta) & jnp.all(jnp.isfinite(q)) & jnp.all(jnp.isfinite(grad))
    delta = jnp.where(finite, delta, jnp.inf)
    acceptance_rate = jnp.where(finite, jnp.minimum(1.0, jnp.exp(-delta)), 0.0)
    is_divergent = ~finite | (delta > divergence_threshold)
    is_accepted = jax.random.uniform(key_accept, (), dtype) < acceptance_rate

    # Involution (q, p, s) -> (q', -p', -s); then, if persistent, the flip (p, s) -> (-p, -s).
    after = -1.0 if persistent else 1.0
    new_momentum = after * jnp.where(is_accepted, -p, momentum)
    new_sign = after * jnp.where(is_accepted, -sign, sign)
    new_state = MagneticHMCState(
        jax.tree.map(lambda new, old: jnp.where(is_accepted, new, old), unravel(q), state.position),
        jnp.where(is_accepted, logdensity, state.logdensity),
        jax.tree.map(
            lambda new, old: jnp.where(is_accepted, new, old),
            unravel(grad),
            state.logdensity_grad,
        ),
        new_momentum.astype(dtype),
        new_sign.astype(sign.dtype),
    )
    info = MagneticHMCInfo(
        acceptance_rate,
        is_accepted,
        is_divergent,
        jnp.where(finite, new_energy, jnp.inf),
        jnp.asarray(num_integration_steps),
        sign,
    )
    return new_state, info


def _flows(magnetic_field, metric, step_size):
    return magnetic_flow(magnetic_field, metric, step_size), magnetic_flow(
        -jnp.asarray(magnetic_field), metric, step_size
    )


def _check_parameters(state_or_position, step_size, inverse_mass_matrix, magnetic_field):
    d = ravel(state_or_position).shape[0]
    check_step_size(step_size)
    check_inverse_mass_matrix(inverse_mass_matrix, d)
    check_magnetic_field(magnetic_field, d)


def _check_options(momentum_persistence, divergence_threshold, persistent):
    value = concrete_array(momentum_persistence)
    if np.ndim(momentum_persistence) != 0 or (value is not None and not 0.0 <= value < 1.0):
        raise ValueError(
            f"momentum_persistence must be a scalar in [0, 1), got {momentum_persistence!r}"
        )
    if not (np.ndim(divergence_threshold) == 0 and float(divergence_threshold) > 0):
        raise ValueError(f"divergence_threshold must be > 0, got {divergence_threshold!r}")
    if not isinstance(persistent, bool):
        raise TypeError(f"persistent must be a bool, got {persistent!r}")


def build_kernel(
    integrator=None,
    *,
    divergence_threshold: float = 1000.0,
    momentum_persistence: float = 0.0,
    persistent: bool = True,
):
    """Build ``kernel(rng_key, state, logdensity_fn, step_size, inverse_mass_matrix,
    num_integration_steps, magnetic_field) -> (state, info)``.

    ``integrator`` exists so that ``blackjax.window_adaptation`` (which calls
    ``build_kernel(blackjax.mcmc.integrators.velocity_verlet)``) can build this kernel: ``None``
    or velocity Verlet both mean the magnetic leapfrog (velocity Verlet whose drift is the
    exact kinetic+magnetic flow); anything else is an error.
    """
    if integrator not in (None, "magnetic_leapfrog", blackjax.mcmc.integrators.velocity_verlet):
        raise ValueError(
            "magnetic_hmc integrates with the magnetic leapfrog only; integrator must be None "
            f"(or blackjax's velocity_verlet, which it generalises), got {integrator!r}"
        )
    _check_options(momentum_persistence, divergence_threshold, persistent)

    def kernel(
        rng_key,
        state: MagneticHMCState,
        logdensity_fn: Callable,
        step_size,
        inverse_mass_matrix,
        num_integration_steps,
        magnetic_field,
    ):
        _check_parameters(state.position, step_size, inverse_mass_matrix, magnetic_field)
        _check_integer("num_integration_steps", num_integration_steps)
        dtype = ravel(state.logdensity_grad).dtype
        metric = make_metric(inverse_mass_matrix, dtype)
        field = jnp.asarray(magnetic_field, dtype)
        # One expm per transition, for the sign this trajectory uses.
        flow = magnetic_flow(state.magnetic_sign * field, metric, step_size)
        return _transition(
            rng_key,
            state,
            logdensity_fn,
            step_size,
            metric,
            (flow, flow),
            num_integration_steps,
            momentum_persistence,
            divergence_threshold,
            persistent,
        )

    return kernel


def as_top_level_api(
    logdensity_fn: Callable,
    step_size,
    inverse_mass_matrix,
    num_integration_steps: int,
    magnetic_field,
    *,
    divergence_threshold: float = 1000.0,
    momentum_persistence: float = 0.0,
    persistent: bool = True,
) -> Sampler:
    """Magnetic HMC: the arguments of ``blackjax.hmc`` plus ``magnetic_field``.

    Parameters
    ----------
    logdensity_fn : callable
        ``log π`` of a pytree position (flattened internally with ``ravel_pytree``).
    step_size : float
        Leapfrog step ``ε > 0``.
    inverse_mass_matrix : array, (d,) or (d, d)
        Diagonal (> 0) or dense (symmetric positive definite) ``M⁻¹``.
    num_integration_steps : int
        Leapfrog steps per transition (= gradient evaluations).
    magnetic_field : array, (d, d)
        Antisymmetric ``G`` (any rank, ``0`` allowed), in the order of the raveled position;
        see :func:`liesample.samplers.magnetic.default_magnetic_field`.
    divergence_threshold : float
        ``ΔH`` above which a transition is flagged divergent (default 1000).
    momentum_persistence : float in [0, 1)
        ``α`` of the partial momentum refreshment; 0 (default) refreshes fully.
    persistent : bool
        Apply the ``(p, s) ↦ (−p, −s)`` flip after each Metropolis step (default ``True``; see
        the module docstring).

    Returns
    -------
    liesample.samplers.contract.Sampler
        ``init(position, rng_key=None)`` and ``step(rng_key, state) -> (state, info)``. The two
        flows ``e^{±εGM⁻¹}`` are computed once here, not per step. Tune ``step_size`` and
        ``inverse_mass_matrix`` with ``blackjax.window_adaptation(liesample.magnetic_hmc, …)``.
    """
    check_step_size(step_size)
    check_inverse_mass_matrix(inverse_mass_matrix)
    check_magnetic_field(magnetic_field, np.shape(inverse_mass_matrix)[0])
    _check_integer("num_integration_steps", num_integration_steps)
    _check_options(momentum_persistence, divergence_threshold, persistent)
    metric = make_metric(inverse_mass_matrix)
    flows = _flows(jnp.asarray(magnetic_field, metric.eigenvalues.dtype), metric, step_size)

    def init_fn(position, rng_key=None):
        state = init(position, logdensity_fn, rng_key)
        _check_parameters(position, step_size, inverse_mass_matrix, magnetic_field)
        return state

    def step_fn(rng_key, state):
        return _transition(
            rng_key,
            state,
            logdensity_fn,
            step_size,
            metric,
            flows,
            num_integration_steps,
            momentum_persistence,
            divergence_threshold,
            persistent,
        )

    def check_positions(positions, **_):
        check_starts(positions, logdensity_fn, np.shape(inverse_mass_matrix)[0])

    settings = {
        "sampler": "magnetic_hmc",
        "step_size": setting(step_size),
        "step_size_source": "given",
        "num_integration_steps": setting(num_integration_steps),
        "divergence_threshold": setting(divergence_threshold),
        "momentum_persistence": setting(momentum_persistence),
        "persistent": persistent,
    }
    return Sampler(init_fn, step_fn, settings=settings, check_positions=check_positions)


magnetic_hmc = sampling_api(as_top_level_api, init, build_kernel, "magnetic_hmc", __name__)
