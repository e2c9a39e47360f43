"""Geometric HMC on Lie groups, spheres and products with ``Rᵈ``: Metropolis-adjusted.

A BlackJAX-shaped module (``init``, ``build_kernel``, ``as_top_level_api``). One transition
(:func:`liesample.samplers.cotangent._core.hamiltonian_transition`):

1. draw ``p ~ N(0, M)`` in algebra coordinates (tangent on spheres), or refresh it partially,
   ``p ← α p + √(1 − α²) ξ`` (``momentum_persistence = α``);
2. ``L`` steps of the ``integrator`` scheme (:mod:`liesample.geometry.cotangent`; by default
   the leapfrog ``B A B``): half kick by the trivialised gradient, exact exp-map drift
   ``g ← g exp(ε M⁻¹p)`` (geodesic flow on spheres; on the ``Euclidean`` coordinates with a
   magnetic field ``G`` the exact kinetic–magnetic flow of ``q̇ = M⁻¹p, ṗ = sGM⁻¹p``), half
   kick;
3. accept with probability ``min(1, e^{−ΔH})``, then flip ``(p, s) ↦ (−p, −s)`` (``s`` the
   sign of the field; ``persistent=True``). Every palindromic scheme of these exact flows
   (the leapfrog, the two-stage ``minimal_norm``, one's own) is symplectic and reversible on
   ``T*G ≅ G × g*`` (with ``G ↦ −G``), so the chain leaves ``π(g) dHaar(g)`` exactly invariant
   at any step size (the HMC of lattice gauge theory, Duane et al. 1987; magnetic HMC,
   Tripuraneni et al. 2017, on ``Rᵈ``).

The drift is exact only for a bi-invariant kinetic energy (``M ∝ I`` on every copy of a
non-abelian group: see :mod:`liesample.geometry.spaces`), which is why the inverse mass is one
scalar per copy of a group or sphere; ``Euclidean`` blocks take a diagonal or a dense ``M⁻¹``. A
rejected or non-finite proposal keeps the state; a non-finite one is flagged ``is_divergent``, as
is a trajectory whose energy error exceeds ``divergence_threshold`` at any of its steps.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from liesample.foundation.types import LogDensityFn, PyTree
from liesample.foundation.validation import concrete_array
from liesample.geometry.spaces import SpaceTree
from liesample.samplers.contract import (
    Recipe,
    Sampler,
    Tunable,
    sampling_api,
    setting,
    step_key,
)
from liesample.samplers.cotangent._core import (
    GeometricInfo,
    GeometricState,
    Move,
    check_divergence_threshold,
    check_positive_step_size,
    hamiltonian_scheme,
    hamiltonian_transition,
    init,
    kernel_move,
    make_move,
    model_values,
    partial_refresh,
    scheme_setting,
    space_sampler,
    space_settings,
    trajectory_cost,
    unset_step,
    with_model_arguments,
)

__all__ = ["ADAPTATION", "as_top_level_api", "build_kernel", "geometric_hmc", "init"]

ADAPTATION = Tunable(
    "window",
    target_acceptance_rate=0.8,
    adapted=("step_size", "inverse_mass_matrix", "num_integration_steps"),
    accepts=("num_integration_steps", "inverse_mass_matrix", "magnetic_field"),
    options=("divergence_threshold", "momentum_persistence", "persistent", "integrator"),
)
"""How :func:`liesample.window_adaptation` tunes geometric HMC (``sampling_api(adaptation=)``)."""


def check_integer(name, value):
    """A scalar integer ``>= 1`` (value checked when concrete)."""
    array = concrete_array(value)
    if np.ndim(value) != 0:
        raise ValueError(f"{name} must be a scalar integer, got shape {np.shape(value)}")
    if array is None:
        return
    integral = array.dtype.kind in "iu" or (array.dtype.kind == "f" and float(array).is_integer())
    if array.dtype.kind == "b" or not integral or array < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")


def check_options(momentum_persistence, divergence_threshold, persistent) -> tuple:
    """``(divergence_threshold, momentum_persistence, persistent)``, checked: the options a
    transition takes after its step count."""
    value = concrete_array(momentum_persistence)
    if np.ndim(momentum_persistence) != 0 or (value is not None and not 0.0 <= value < 1.0):
        raise ValueError(
            f"momentum_persistence must be a scalar in [0, 1), got {momentum_persistence!r}"
        )
    check_divergence_threshold(divergence_threshold)
    if not isinstance(persistent, bool):
        raise TypeError(f"persistent must be a bool, got {persistent!r}")
    return divergence_threshold, momentum_persistence, persistent


def transition(
    rng_key,
    state: GeometricState,
    move: Move,
    num_integration_steps,
    divergence_threshold,
    momentum_persistence=0.0,
    persistent=True,
):
    """One geometric HMC transition (``move`` from
    :func:`liesample.samplers.cotangent._core.make_move` for a palindromic scheme)."""
    key_momentum, key_accept = jax.random.split(rng_key)
    fresh = move.bundle.sample_momentum(key_momentum, state.position)
    momentum = partial_refresh(fresh, state.momentum, momentum_persistence)
    new_state, outcome = hamiltonian_transition(
        key_accept,
        state,
        momentum,
        move,
        num_integration_steps,
        divergence_threshold,
        persistent,
    )
    is_accepted, acceptance_rate, is_divergent, _, proposal_energy = outcome
    info = GeometricInfo(
        acceptance_rate,
        is_accepted,
        is_divergent,
        proposal_energy,
        jnp.asarray(num_integration_steps),
        acceptance_rate,
        trajectory_cost(move, num_integration_steps),
    )
    return new_state, info


def build_kernel(
    divergence_threshold: float = 1000.0,
    *,
    momentum_persistence: float = 0.0,
    persistent: bool = True,
    integrator="leapfrog",
):
    """``kernel(rng_key, state, logdensity_fn, space, step_size, num_integration_steps,
    inverse_mass_matrix=None, magnetic_field=None, metric=None) -> (state, info)``; parameters
    may be traced (adaptation): the kinetic–magnetic exponential is then computed per
    transition. ``metric``: ``cotangent_bundle(space, inverse_mass_matrix, dtype=…).metric``
    (:mod:`liesample.geometry.cotangent`, in the dtype of ``state.logdensity``) when the caller
    keeps it from one transition to the next, so that a dense ``M⁻¹`` is not decomposed in
    each; the draws are the same."""
    if callable(divergence_threshold):  # BlackJAX's warm-ups pass their integrator first
        raise TypeError(
            "geometric_hmc.build_kernel got a function for divergence_threshold: "
            "blackjax.window_adaptation(liesample.geometric_hmc, …) passes its Euclidean "
            "integrator there, and its Euclidean mass cannot move a sphere or a group. Tune with "
            "liesample.window_adaptation(liesample.geometric_hmc, logdensity_fn, space) instead "
            "(the same Stan windows, with the mass in algebra coordinates)."
        )
    scheme = hamiltonian_scheme(integrator)
    options = check_options(momentum_persistence, divergence_threshold, persistent)

    def kernel(
        rng_key,
        state: GeometricState,
        logdensity_fn: Callable,
        space,
        step_size,
        num_integration_steps,
        inverse_mass_matrix=None,
        magnetic_field=None,
        metric=None,
    ):
        check_positive_step_size(step_size)
        check_integer("num_integration_steps", num_integration_steps)
        move = kernel_move(
            state, logdensity_fn, space, step_size, inverse_mass_matrix, magnetic_field, scheme,
            metric,
        )  # fmt: skip
        return transition(rng_key, state, move, num_integration_steps, *options)

    return kernel


def as_top_level_api(
    logdensity_fn: LogDensityFn,
    space: SpaceTree,
    step_size: float | jax.Array | None = None,
    num_integration_steps: int | jax.Array | None = None,
    inverse_mass_matrix: PyTree = None,
    magnetic_field: ArrayLike | None = None,
    *,
    divergence_threshold: float = 1000.0,
    momentum_persistence: float = 0.0,
    persistent: bool = True,
    integrator: str | Sequence[tuple[str, float]] = "leapfrog",
    jitter: bool = False,
    model_args: tuple = (),
    model_kwargs: dict | None = None,
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
        From :mod:`liesample.geometry.spaces` (``Euclidean``, ``Sphere``, ``SO``, ``SU``, ``U1``).
    step_size : float or None
        Step ``ε > 0`` of the integration scheme. ``None`` (default): tuned by the warm-up of
        :func:`liesample.sample` (``num_warmup > 0``), with the mass and the trajectory length,
        all chains together (Stan's windows, :func:`liesample.window_adaptation`); such a
        sampler cannot step on its own. A given step is kept unless ``sample(adapt=True)``.
    num_integration_steps : int or None
        Steps of the scheme per transition; required with a given ``step_size``. Left unset,
        the warm-up learns the integration time ``T`` (a ChEES-type rule) and the sampler
        integrates a jittered ``ceil(u T / ε)`` steps; given, the warm-up keeps it.
    inverse_mass_matrix : None, float or pytree
        ``M⁻¹``: unit by default (the warm-up then adapts it; a given one it keeps); a
        positive scalar; or a pytree like ``space`` with one value
        per copy of a group or sphere and one per coordinate of ``Euclidean`` and ``U1``
        (what :func:`liesample.window_adaptation` returns). A ``Euclidean`` block of ``n``
        coordinates may take a dense symmetric positive definite ``(n, n)`` matrix instead.
    magnetic_field : array (D, D), optional
        A constant antisymmetric ``G`` on the ``D`` Euclidean coordinates (every ``Euclidean``
        block raveled, in the order of the space's pytree leaves). It changes the dynamics,
        not the target; ``None`` (default) is plain geometric HMC. See
        :func:`liesample.samplers.cotangent._euclidean.default_magnetic_field`.
    divergence_threshold : float
        Energy error ``H(z_k) − H(z_0)`` above which a transition is flagged divergent, at
        any step ``k`` of its trajectory (as NUTS does; default 1000, NUTS's and Stan's).
    momentum_persistence : float in [0, 1)
        ``α`` of the partial momentum refreshment; 0 (default) draws a fresh momentum.
    persistent : bool
        Apply the flip ``(p, s) ↦ (−p, −s)`` after each Metropolis test (default); with
        ``False`` the field's sign flips on acceptance instead (Tripuraneni et al. 2017).
    integrator : str or sequence of (effect, fraction) pairs
        The scheme of one step (BlackJAX's ``integrator=``): ``"leapfrog"`` (default, one
        gradient per step), ``"minimal_norm"`` (two), or one's own palindromic coefficient
        list of kicks ``"B"`` and drifts ``"A"`` whose fractions of each sum to 1, e.g.
        ``(("B", 0.5), ("A", 1.0), ("B", 0.5))`` (:mod:`liesample.geometry.cotangent`).
        ``info.num_gradient_evaluations`` counts what it costs (a scheme that ends with a
        drift also evaluates the gradient at the end of every step).
    jitter : bool
        Draw the steps of each transition afresh, ``L ~ ceil(u · num_integration_steps)`` with
        ``u ~ Uniform(0, 1)`` (what :func:`liesample.window_adaptation` returns, with the
        ``T`` its ChEES rule learnt): a fixed length can sit at a resonance of the target (a
        direction whose half period is ``L ε`` barely moves). ``False`` (default): ``L`` steps.
    model_args, model_kwargs : tuple, dict
        Arguments of ``logdensity_fn`` after the position (its data and constants, as in
        NumPyro): ``log π(x) = logdensity_fn(x, *model_args, **model_kwargs)``. They are numbers
        of the compiled program, so :func:`liesample.sample` of the same ``logdensity_fn`` at
        other data or constants compiles nothing new (a closure per value would).

    Examples
    --------
    The matrix Fisher law ``∝ exp(tr R)`` on SO(3); a step keeps ``R`` a rotation:

    >>> from liesample.spaces import SO
    >>> sampler = liesample.geometric_hmc(jnp.trace, SO(3), step_size=0.1, num_integration_steps=5)
    >>> state = sampler.init(jnp.eye(3))
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> bool(jnp.allclose(state.position.T @ state.position, jnp.eye(3), atol=1e-12))
    True
    """
    options = check_options(momentum_persistence, divergence_threshold, persistent)
    scheme = hamiltonian_scheme(integrator)
    density = with_model_arguments(logdensity_fn, model_args, model_kwargs)
    if not isinstance(jitter, bool):
        raise TypeError(f"jitter must be a bool, got {jitter!r}")
    if num_integration_steps is not None:
        check_integer("num_integration_steps", num_integration_steps)
    elif step_size is not None:
        raise ValueError(
            "num_integration_steps is unset but step_size is given: give both, or leave both "
            "unset for liesample.sample's warm-up to tune them"
        )
    settings = _settings(
        space, step_size, num_integration_steps, divergence_threshold, magnetic_field,
        momentum_persistence, persistent, integrator, jitter,
    )  # fmt: skip
    tunable = ADAPTATION._replace(given=step_size is not None)
    fixed: dict[str, Any] = {"divergence_threshold": divergence_threshold, "integrator": integrator,
             "momentum_persistence": momentum_persistence, "persistent": persistent,
             "jitter": jitter}  # fmt: skip
    numbers = {"step_size": step_size, "inverse_mass_matrix": inverse_mass_matrix,
               "magnetic_field": magnetic_field}  # fmt: skip
    numbers.update(model_values(model_args, model_kwargs))
    if jitter and num_integration_steps is not None:  # drawn per transition: a number
        numbers["num_integration_steps"] = jnp.asarray(num_integration_steps)
    else:
        fixed["num_integration_steps"] = num_integration_steps
    recipe = Recipe(geometric_hmc, (logdensity_fn, space), fixed, numbers)
    if step_size is None:
        unset = unset_step("geometric_hmc")
        return space_sampler(density, space, unset, settings, tunable, recipe=recipe)
    check_positive_step_size(step_size)
    move = make_move(density, space, step_size, inverse_mass_matrix, magnetic_field, scheme)
    step_fn = functools.partial(_step, move, num_integration_steps, jitter, options)
    return space_sampler(density, space, step_fn, settings, tunable, recipe=recipe)


def _settings(space, step_size, num_integration_steps, divergence_threshold, magnetic_field,
              momentum_persistence, persistent, integrator, jitter) -> dict:  # fmt: skip
    """What :func:`as_top_level_api` records in the run's attributes."""
    settings = space_settings(
        "geometric_hmc",
        space,
        step_size,
        num_integration_steps=setting(num_integration_steps),
        divergence_threshold=setting(divergence_threshold),
    )
    if magnetic_field is not None:
        settings["magnetic"] = True
    if momentum_persistence != 0:
        settings["momentum_persistence"] = setting(momentum_persistence)
        settings["persistent"] = persistent
    settings.update(scheme_setting(integrator))
    if jitter:
        settings["jitter"] = True
    return settings


def _step(move, num_integration_steps, jitter, options, rng_key, state):
    """One transition: ``L`` steps, or ``ceil(u L)`` with ``u`` uniform when ``jitter``."""
    rng_key, steps = step_key(rng_key), num_integration_steps
    if jitter:
        key_length, rng_key = jax.random.split(rng_key)
        u = jax.random.uniform(key_length, (), state.logdensity.dtype)
        steps = jnp.clip(jnp.ceil(u * steps), 1, steps).astype(int)
    return transition(rng_key, state, move, steps, *options)


geometric_hmc = sampling_api(
    as_top_level_api, init, build_kernel, "geometric_hmc", __name__, adaptation=ADAPTATION
)
