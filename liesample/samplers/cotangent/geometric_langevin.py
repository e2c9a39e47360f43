"""Kinetic Langevin on Lie groups, spheres and products with ``Rᵈ``: the dissipative
symplectic diffusion on ``T*G`` (paper, ``sec:dissipation``) before reduction.

The SDE is ``dg = g (M⁻¹p)^ dt``, ``dp = ∇log π(g) dt + G M⁻¹p dt − γ M⁻¹p dt + √(2γ) dW`` in
the left trivialisation (on a non-abelian group with ``M ∝ I`` per copy the Lie–Poisson term
``ad*_{M⁻¹p} p`` vanishes; the magnetic term ``G M⁻¹p``, optional, acts on the ``Euclidean``
coordinates). Its invariant law is ``exp(−H)`` for every antisymmetric ``G``, and its
``G``-marginal is ``π dHaar``. One transition (BlackJAX-shaped: ``init``, ``build_kernel``,
``as_top_level_api``), from the one-effect steps of :mod:`liesample.geometry.cotangent`:

- ``adjusted=False`` (default): one step of the ``integrator`` scheme, by default
  ``O B A B`` (``O`` the exact
  Ornstein–Uhlenbeck step ``p ← e^{−γm⁻¹h} p + √(1 − e^{−2γm⁻¹h}) ξ``, ``ξ ~ N(0, M)``;
  ``B A B`` a geometric leapfrog step), every finite step taken: the irreversible kinetic
  Langevin chain, biased by ``O(h²)`` in the position law (the sequence ``O B A B O B A B …``
  has the position marginal of ``O_{h/2} BAB O_{h/2}``, which is second order).
  (:func:`liesample.magnetic_langevin` runs the scheme ``B A O A B`` by default.)
- ``adjusted=True``: the ``O`` step, then one-step HMC with the momentum (and the field's
  sign) flipped on rejection (Horowitz's generalised HMC); a scheme whose ``O`` steps stand at
  its ends (``obab``, ``obabo``) puts them before and after the one-step HMC. The proposal
  ``(g, p, s) ↦ (g', −p', −s)`` is an involution preserving the Liouville measure, so the
  Metropolis test followed by the flip ``(p, s) ↦ (−p, −s)`` keeps ``exp(−H)`` exactly, at any
  step size.

A non-finite step is rejected (state kept) and flagged ``is_divergent`` in both variants.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from liesample.foundation.types import LogDensityFn, PyTree
from liesample.foundation.validation import concrete_array, finite_float
from liesample.geometry.cotangent import check_scheme
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
    energy,
    hamiltonian_scheme,
    hamiltonian_transition,
    init,
    kernel_move,
    make_move,
    model_values,
    scheme_setting,
    space_sampler,
    space_settings,
    trajectory_cost,
    unadjusted_advice,
    unadjusted_transition,
    unset_step,
    with_model_arguments,
)

__all__ = ["ADAPTATION", "as_top_level_api", "build_kernel", "geometric_langevin", "init"]

ADAPTATION = Tunable(
    "window",
    target_acceptance_rate=0.9,
    adapted=("step_size", "inverse_mass_matrix"),
    accepts=("friction", "inverse_mass_matrix", "magnetic_field"),
    options=("adjusted", "divergence_threshold", "integrator"),
    defaults={"friction": 1.0},
)
"""How :func:`liesample.window_adaptation` tunes geometric Langevin (``adaptation=``)."""


def langevin_scheme(integrator, adjusted: bool = False) -> tuple:
    """The checked scheme of ``integrator=`` (a name of
    :data:`liesample.geometry.cotangent.SCHEMES` or a coefficient list of ``B``, ``A`` and
    ``O``, each present). With ``adjusted`` its ``O`` steps must stand at its ends, around a
    palindromic ``B``/``A`` core (the one-step HMC that the Metropolis test adjusts)."""
    scheme = check_scheme(integrator, "ABO")
    missing = sorted({"A", "B", "O"} - {effect for effect, _ in scheme})
    if missing:
        raise ValueError(
            f"integrator of a Langevin sampler needs the effects A, B and O; {scheme} lacks "
            f"{missing}; e.g. 'obab', 'baoab' or 'obabo'"
        )
    if adjusted:
        core = split_refresh(scheme)[1]
        if any(effect == "O" for effect, _ in core):
            raise ValueError(
                f"adjusted=True needs the O steps at the ends of the scheme, got {scheme}; "
                "e.g. 'obab' or 'obabo'"
            )
        hamiltonian_scheme(core)
    return scheme


def split_refresh(scheme) -> tuple:
    """``(fraction of O before, core, fraction of O after)`` of a scheme ``O… core O…``."""
    start, stop = 0, len(scheme)
    while start < stop and scheme[start][0] == "O":
        start += 1
    while stop > start and scheme[stop - 1][0] == "O":
        stop -= 1
    before = sum(fraction for _, fraction in scheme[:start])
    after = sum(fraction for _, fraction in scheme[stop:])
    return before, tuple(scheme[start:stop]), after


def check_friction(friction):
    if jnp.ndim(friction) != 0:
        raise ValueError(f"friction must be a scalar, got shape {jnp.shape(friction)}")
    if concrete_array(friction) is not None:  # traced values are checked where concrete
        finite_float("friction", friction, positive=True)


def _refreshed(rng_key, move: Move, state: GeometricState, friction, fraction):
    """``state`` with its momentum moved by the exact OU step over ``fraction`` of the step."""
    time = move.step_size if fraction == 1.0 else fraction * move.step_size
    momentum = move.bundle.ornstein_uhlenbeck(
        rng_key, state.position, state.momentum, friction, time
    )
    return state._replace(momentum=momentum)


def transition(
    rng_key, state: GeometricState, move: Move, friction, adjusted, divergence_threshold
):
    """One geometric Langevin transition (``move`` from
    :func:`liesample.samplers.cotangent._core.make_move` for a :func:`langevin_scheme`)."""
    if not adjusted:
        new_state, outcome = unadjusted_transition(
            rng_key, state, move, friction, divergence_threshold
        )
        is_accepted, metropolis_rate, is_divergent, new_energy = outcome
        acceptance_rate = is_accepted.astype(metropolis_rate.dtype)
    else:
        before, core, after = split_refresh(move.scheme)
        keys = jax.random.split(rng_key, 3 if after else 2)
        if before:
            state = _refreshed(keys[0], move, state, friction, before)
        new_state, outcome = hamiltonian_transition(
            keys[1], state, state.momentum, move._replace(scheme=core), 1, divergence_threshold
        )
        is_accepted, metropolis_rate, is_divergent, initial_energy, proposal_energy = outcome
        acceptance_rate = metropolis_rate
        new_energy = jnp.where(is_accepted, proposal_energy, initial_energy)
        if after:
            new_state = _refreshed(keys[2], move, new_state, friction, after)
            new_energy = energy(move.bundle, new_state.logdensity, new_state.momentum)
    info = GeometricInfo(
        acceptance_rate,
        is_accepted,
        is_divergent,
        new_energy,
        jnp.asarray(1),
        metropolis_rate,
        trajectory_cost(move, 1),
    )
    return new_state, info


def check_options(adjusted, divergence_threshold, integrator) -> tuple:
    """Validate the options; the checked scheme."""
    if not isinstance(adjusted, bool):
        raise TypeError(f"adjusted must be a bool, got {adjusted!r}")
    check_divergence_threshold(divergence_threshold)
    return langevin_scheme(integrator, adjusted)


def build_kernel(
    adjusted: bool = False, divergence_threshold: float = 1000.0, *, integrator="obab"
):
    """``kernel(rng_key, state, logdensity_fn, space, step_size, friction,
    inverse_mass_matrix=None, magnetic_field=None) -> (state, info)``; parameters may be traced
    (adaptation)."""
    scheme = check_options(adjusted, divergence_threshold, integrator)

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
        check_positive_step_size(step_size)
        check_friction(friction)
        move = kernel_move(
            state, logdensity_fn, space, step_size, inverse_mass_matrix, magnetic_field, scheme
        )
        return transition(rng_key, state, move, friction, adjusted, divergence_threshold)

    return kernel


def as_top_level_api(
    logdensity_fn: LogDensityFn,
    space: SpaceTree,
    step_size: float | jax.Array | None = None,
    friction: float | jax.Array = 1.0,
    inverse_mass_matrix: PyTree = None,
    magnetic_field: ArrayLike | None = None,
    *,
    adjusted: bool = False,
    divergence_threshold: float = 1000.0,
    integrator: str | Sequence[tuple[str, float]] = "obab",
    model_args: tuple = (),
    model_kwargs: dict | None = None,
) -> Sampler:
    """Geometric kinetic Langevin on Lie groups, spheres and products with ``Rᵈ``.

    Parameters
    ----------
    logdensity_fn, space, inverse_mass_matrix, magnetic_field
        As for :func:`liesample.geometric_hmc` (``log π`` with respect to Haar / uniform /
        Lebesgue measure; the field acts on the Euclidean coordinates).
    step_size : float or None
        ``h > 0``, the time step of the OU step and of the leapfrog step. ``None`` (default):
        tuned with the mass by the warm-up of :func:`liesample.sample` (``num_warmup > 0``),
        all chains together (:func:`liesample.window_adaptation`, to a Metropolis rate of 0.9
        the step would have); such a sampler cannot step on its own. A given step is kept
        unless ``sample(adapt=True)``; a given ``inverse_mass_matrix`` is kept.
    friction : float
        ``γ > 0`` (default 1); the momentum keeps a fraction ``e^{−γm⁻¹h}`` per step.
    adjusted : bool
        Metropolis-adjust each step (exact law) instead of taking it unadjusted.
    divergence_threshold : float
        ``ΔH`` above which a step is flagged divergent.
    integrator : str or sequence of (effect, fraction) pairs
        The splitting of one step: ``"obab"`` (default), ``"baoab"``, ``"obabo"``, or one's own
        coefficient list of kicks ``"B"``, drifts ``"A"`` and OU steps ``"O"``, the fractions
        of each summing to 1 (:mod:`liesample.geometry.cotangent`). With ``adjusted=True`` the
        ``O`` steps must stand at the ends, around a palindromic ``B``/``A`` core.
    model_args, model_kwargs : tuple, dict
        Arguments of ``logdensity_fn`` after the position, numbers of the compiled program
        (:func:`liesample.geometric_hmc`).

    Examples
    --------
    The von Mises–Fisher law ``∝ exp(2 x_z)`` on S²:

    >>> from liesample.spaces import Sphere
    >>> sampler = liesample.geometric_langevin(lambda x: 2.0 * x[2], Sphere(2), step_size=0.1)
    >>> state = sampler.init(jnp.array([1.0, 0.0, 0.0]))
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> bool(jnp.isclose(jnp.linalg.norm(state.position), 1.0)), bool(info.is_divergent)
    (True, False)
    """
    check_friction(friction)
    scheme = check_options(adjusted, divergence_threshold, integrator)
    density = with_model_arguments(logdensity_fn, model_args, model_kwargs)
    settings = space_settings(
        "geometric_langevin",
        space,
        step_size,
        friction=setting(friction),
        adjusted=adjusted,
        divergence_threshold=setting(divergence_threshold),
    )
    if magnetic_field is not None:
        settings["magnetic"] = True
    settings.update(scheme_setting(integrator, "obab"))
    tunable = ADAPTATION._replace(given=step_size is not None)
    fixed = {"adjusted": adjusted, "divergence_threshold": divergence_threshold,
             "integrator": integrator}  # fmt: skip
    numbers = {"step_size": step_size, "friction": friction, "magnetic_field": magnetic_field,
               "inverse_mass_matrix": inverse_mass_matrix}  # fmt: skip
    numbers.update(model_values(model_args, model_kwargs))
    recipe = Recipe(geometric_langevin, (logdensity_fn, space), fixed, numbers)
    if step_size is None:
        unset = unset_step("geometric_langevin")
        return space_sampler(density, space, unset, settings, tunable, recipe=recipe)
    check_positive_step_size(step_size)
    move = make_move(density, space, step_size, inverse_mass_matrix, magnetic_field, scheme)

    def step_fn(rng_key, state):
        key = step_key(rng_key)
        return transition(key, state, move, friction, adjusted, divergence_threshold)

    advice = (
        None
        if adjusted
        else unadjusted_advice(
            "liesample.geometric_langevin(logdensity_fn, space, adjusted=True) or "
            "liesample.geometric_hmc(logdensity_fn, space)"
        )
    )
    return space_sampler(density, space, step_fn, settings, tunable, advice, recipe)


geometric_langevin = sampling_api(
    as_top_level_api, init, build_kernel, "geometric_langevin", __name__, adaptation=ADAPTATION
)
