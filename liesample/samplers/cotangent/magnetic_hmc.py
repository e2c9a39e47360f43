"""Metropolis-adjusted magnetic HMC (Tripuraneni et al. 2017) for any ``logdensity_fn``.

A BlackJAX-shaped module (``MagneticHMCState``/``MagneticHMCInfo``, ``init``, ``build_kernel``,
``as_top_level_api``): geometric HMC (:mod:`liesample.samplers.cotangent.geometric_hmc`) on
``spaces.Euclidean((d,))``, the position raveled with ``ravel_pytree``, with the magnetic field.
The extended target is ``π(q) · N(p; 0, M) · ½`` over ``(q, p, s)``, ``s = ±1`` the sign of the
field. One transition (paper, ``sec:brownian-particle``):

1. momentum refreshment ``p ← α p + √(1 − α²) ξ``, ``ξ ~ N(0, M)`` (``α`` =
   ``momentum_persistence``; ``α = 0``, the default, is full refreshment as in ``blackjax.hmc``);
2. ``L`` steps of the ``integrator`` scheme, by default the magnetic leapfrog: half kick
   ``p += ε/2 ∇log π(q)``, the *exact* kinetic+magnetic flow of ``q̇ = M⁻¹p, ṗ = sG M⁻¹p``
   over ``ε`` (:func:`liesample.geometry.cotangent.kinetic_magnetic_flow`, computed once per
   sign, valid for singular ``G``), half kick. Each piece preserves volume
   (``tr(GM⁻¹) = 0``), the composition is symmetric;
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
:func:`jittered_magnetic_hmc` draws the number of steps afresh at every transition.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import blackjax
import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from liesample.foundation.schemes import Schemes
from liesample.foundation.types import LogDensityFn
from liesample.geometry.cotangent import LEAPFROG, PhasePoint, compose, drift, kick
from liesample.samplers.contract import (
    Recipe,
    Sampler,
    Tunable,
    sampling_api,
    setting,
    step_key,
)
from liesample.samplers.cotangent._core import (
    UNSET,
    hamiltonian_scheme,
    model_values,
    ravelled,
    scheme_setting,
    unset_step,
    with_model_arguments,
)
from liesample.samplers.cotangent._euclidean import (
    MagneticFlow,
    check_parameters,
    check_starts,
    euclidean_move,
    initial_values,
    ravel,
)
from liesample.samplers.cotangent.geometric_hmc import check_integer, check_options, transition

__all__ = [
    "ADAPTATION",
    "MagneticHMCInfo",
    "MagneticHMCState",
    "as_top_level_api",
    "build_kernel",
    "init",
    "jittered_magnetic_hmc",
    "magnetic_hmc",
    "magnetic_leapfrog",
]

ADAPTATION = Tunable(
    "chees",
    target_acceptance_rate=0.651,
    adapted=("step_size", "inverse_mass_matrix", "num_integration_steps", "magnetic_field"),
    accepts=(),
    options=("divergence_threshold", "integrator"),
)
"""How window adaptation tunes magnetic HMC: several chains together, the trajectory length by ChEES
(:func:`liesample.tuning.adaptation.magnetic_window_adaptation`)."""

BLACKJAX_SCHEMES = Schemes(
    "T*Rⁿ with a magnetic field, as BlackJAX's integrators",
    {
        blackjax.mcmc.integrators.velocity_verlet: "leapfrog",
        blackjax.mcmc.integrators.mclachlan: "minimal_norm",
    },
)
"""BlackJAX integrators and the schemes with the same coefficients (the drift here is the
exact kinetic+magnetic flow; :class:`liesample.foundation.schemes.Schemes`)."""


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
    is_divergent : the energy error above ``divergence_threshold`` at some step of the
        trajectory, or a non-finite energy on it (then rejected).
    energy : ``H`` of the proposal (``-log π + kinetic``; ``inf`` for a non-finite one), as in
        BlackJAX's HMC.
    num_integration_steps : steps of the integration scheme in the trajectory.
    magnetic_sign : sign of the field used for this trajectory.
    num_gradient_evaluations : gradients of ``log π`` the trajectory evaluated.
    """

    acceptance_rate: jax.Array
    is_accepted: jax.Array
    is_divergent: jax.Array
    energy: jax.Array
    num_integration_steps: jax.Array
    magnetic_sign: jax.Array
    num_gradient_evaluations: jax.Array


def init(position, logdensity_fn: Callable, rng_key=None) -> MagneticHMCState:
    """Initial state (no key needed; ``rng_key`` is ignored). Raises if ``log π`` is non-finite."""
    del rng_key
    logdensity, grad, momentum = initial_values(position, logdensity_fn)
    return MagneticHMCState(position, logdensity, grad, momentum, jnp.ones((), momentum.dtype))


def magnetic_leapfrog(flat_logdensity_fn, metric, flow: MagneticFlow, step_size):
    """One magnetic leapfrog step ``(q, p, ∇log π) -> (q, p, log π, ∇log π)`` on flat ``q``.

    The scheme ``B A B`` of :mod:`liesample.geometry.cotangent` with the exact kinetic+magnetic
    ``flow`` as the drift (with ``G = 0`` this *is* velocity Verlet).
    """
    value_and_grad = jax.value_and_grad(flat_logdensity_fn)
    bundle = euclidean_move(step_size, metric.inverse_mass_matrix, None, LEAPFROG).bundle
    drift_flow = bundle.kinetic_flow(step_size)._replace(euclidean=flow)
    effects = {"B": kick(value_and_grad, step_size), "A": drift(bundle, {1.0: drift_flow})}
    step = compose(LEAPFROG, effects)

    def one(position, momentum, grad):
        point = step(PhasePoint(position, momentum, None, grad))
        return point.position, point.momentum, point.logdensity, point.logdensity_grad

    return one


def _transition(rng_key, state: MagneticHMCState, logdensity_fn, move, num_steps, options):
    """Geometric HMC on the raveled position (``options``: divergence threshold, momentum
    persistence, persistent)."""

    def flat_transition(flat_state, flat_move):
        return transition(rng_key, flat_state, flat_move, num_steps, *options)

    new, info, unravel = ravelled(state, logdensity_fn, move, flat_transition)
    new_state = MagneticHMCState(
        unravel(new.position),
        new.logdensity,
        unravel(new.logdensity_grad),
        new.momentum,
        new.magnetic_sign,
    )
    info = MagneticHMCInfo(
        info.acceptance_rate,
        info.is_accepted,
        info.is_divergent,
        info.energy,
        info.num_integration_steps,
        state.magnetic_sign,
        info.num_gradient_evaluations,
    )
    return new_state, info


def build_kernel(
    integrator=None,
    *,
    divergence_threshold: float = 1000.0,
    momentum_persistence: float = 0.0,
    persistent: bool = True,
):
    """Build ``kernel(rng_key, state, logdensity_fn, step_size, inverse_mass_matrix,
    num_integration_steps, magnetic_field) -> (state, info)``.

    ``integrator`` is a scheme as for :func:`as_top_level_api` (``None``: the leapfrog), or
    BlackJAX's ``velocity_verlet`` or ``mclachlan`` (what ``blackjax.window_adaptation`` passes),
    which mean the schemes with their coefficients and the exact kinetic+magnetic drift.
    """
    scheme = _scheme(integrator)
    options = check_options(momentum_persistence, divergence_threshold, persistent)

    def kernel(
        rng_key,
        state: MagneticHMCState,
        logdensity_fn: Callable,
        step_size,
        inverse_mass_matrix,
        num_integration_steps,
        magnetic_field,
    ):
        d = ravel(state.position).shape[0]
        check_parameters(step_size, inverse_mass_matrix, magnetic_field, d)
        check_integer("num_integration_steps", num_integration_steps)
        dtype = ravel(state.logdensity_grad).dtype
        # One expm per transition, for the sign this trajectory uses.
        move = euclidean_move(
            step_size, inverse_mass_matrix, magnetic_field, scheme, dtype, precompute=False
        )
        return _transition(rng_key, state, logdensity_fn, move, num_integration_steps, options)

    return kernel


def _scheme(integrator) -> tuple:
    """The checked scheme of ``integrator=`` (module docstring of :func:`build_kernel`)."""
    if integrator is None or integrator == "magnetic_leapfrog":
        return hamiltonian_scheme("leapfrog")
    if callable(integrator):
        if integrator not in BLACKJAX_SCHEMES:
            raise ValueError(
                "of BlackJAX's integrators magnetic_hmc takes velocity_verlet and mclachlan "
                f"(their coefficients with the exact kinetic+magnetic drift), got {integrator!r}"
            )
        return hamiltonian_scheme(BLACKJAX_SCHEMES[integrator])
    return hamiltonian_scheme(integrator)


def as_top_level_api(
    logdensity_fn: LogDensityFn,
    step_size: float | jax.Array | None = None,
    inverse_mass_matrix: ArrayLike | None = None,
    num_integration_steps: int | jax.Array | None = None,
    magnetic_field: ArrayLike | None = None,
    *,
    divergence_threshold: float = 1000.0,
    integrator: str | Sequence[tuple[str, float]] = "leapfrog",
    momentum_persistence: float = 0.0,
    persistent: bool = True,
    model_args: tuple = (),
    model_kwargs: dict | None = None,
) -> Sampler:
    """Magnetic HMC: the arguments of ``blackjax.hmc`` (in its order) plus ``magnetic_field``,
    ``momentum_persistence`` and ``persistent``.

    Parameters
    ----------
    logdensity_fn : callable
        ``log π`` of a pytree position (flattened internally with ``ravel_pytree``).
    step_size : float or None
        Step ``ε > 0`` of the integration scheme. ``None``, with the next three unset too
        (``magnetic_hmc(logdensity_fn)``): all four are tuned by the warm-up of
        :func:`liesample.sample` (``num_warmup > 0``, ``>= 2`` chains) with
        :func:`liesample.magnetic_window_adaptation`, which then samples with
        :func:`jittered_magnetic_hmc`; such a sampler cannot step on its own.
    inverse_mass_matrix : array, (d,) or (d, d)
        Diagonal (> 0) or dense (symmetric positive definite) ``M⁻¹``.
    num_integration_steps : int
        Steps of the scheme per transition (gradient evaluations for the leapfrog).
    magnetic_field : array, (d, d)
        Antisymmetric ``G`` (any rank, ``0`` allowed), in the order of the raveled position;
        see :func:`liesample.default_magnetic_field`.
    divergence_threshold : float
        Energy error ``H(z_k) − H(z_0)`` above which a transition is flagged divergent, at
        any step ``k`` of its trajectory (default 1000, as in NUTS).
    integrator : str or sequence of (effect, fraction) pairs
        The scheme of one step, as for :func:`liesample.geometric_hmc`: ``"leapfrog"``
        (default), ``"minimal_norm"``, a palindromic coefficient list of ``"B"`` and ``"A"``,
        or BlackJAX's ``velocity_verlet`` / ``mclachlan``.
    momentum_persistence : float in [0, 1)
        ``α`` of the partial momentum refreshment; 0 (default) refreshes fully.
    persistent : bool
        Apply the ``(p, s) ↦ (−p, −s)`` flip after each Metropolis step (default ``True``; see
        the module docstring).

    model_args, model_kwargs : tuple, dict
        Arguments of ``logdensity_fn`` after the position (its data and constants, as in
        NumPyro): numbers of the compiled program, so the same ``logdensity_fn`` at other data
        compiles nothing new (:func:`liesample.geometric_hmc`).

    Returns
    -------
    liesample.samplers.contract.Sampler
        ``init(position, rng_key=None)`` and ``step(rng_key, state) -> (state, info)``. The two
        flows ``e^{±εGM⁻¹}`` are computed once here, not per step. Tune ``step_size`` and
        ``inverse_mass_matrix`` with ``blackjax.window_adaptation(liesample.magnetic_hmc, …)``.

    Examples
    --------
    A standard normal in four dimensions, with the default field (two unit rotations):

    >>> logdensity_fn = lambda x: -0.5 * x @ x
    >>> field = liesample.default_magnetic_field(jnp.ones(4), strength=1.0)
    >>> sampler = liesample.magnetic_hmc(logdensity_fn, 0.2, jnp.ones(4), 5, magnetic_field=field)
    >>> state = sampler.init(jnp.zeros(4))
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), state)
    >>> state.position.shape, bool(info.is_divergent)
    ((4,), False)
    """
    density = with_model_arguments(logdensity_fn, model_args, model_kwargs)
    options = check_options(momentum_persistence, divergence_threshold, persistent)
    scheme = _scheme(integrator)
    tuned = (step_size, inverse_mass_matrix, num_integration_steps, magnetic_field)
    fixed: dict[str, Any] = {"divergence_threshold": divergence_threshold, "integrator": integrator,
             "momentum_persistence": momentum_persistence, "persistent": persistent}  # fmt: skip
    model = model_values(model_args, model_kwargs)
    if all(value is None for value in tuned):
        return _unset(logdensity_fn, fixed, model)
    if any(value is None for value in tuned):
        raise ValueError(
            "magnetic_hmc takes step_size, inverse_mass_matrix, num_integration_steps and "
            "magnetic_field together, or none of them (liesample.sample's warm-up then tunes "
            "all four on >= 2 chains)"
        )
    d = check_parameters(step_size, inverse_mass_matrix, magnetic_field)
    check_integer("num_integration_steps", num_integration_steps)
    move = euclidean_move(step_size, inverse_mass_matrix, magnetic_field, scheme)

    def init_fn(position, rng_key=None):
        state = init(position, density, rng_key)
        check_parameters(step_size, inverse_mass_matrix, magnetic_field, ravel(position).shape[0])
        return state

    def step_fn(rng_key, state):
        key = step_key(rng_key)
        return _transition(key, state, density, move, num_integration_steps, options)

    settings = {
        "sampler": "magnetic_hmc",
        "step_size": setting(step_size),
        "step_size_source": "given",
        "num_integration_steps": setting(num_integration_steps),
        "divergence_threshold": setting(divergence_threshold),
        "momentum_persistence": setting(momentum_persistence),
        "persistent": persistent,
    }
    if not callable(integrator):
        settings.update(scheme_setting(integrator))
    check_positions = check_starts(logdensity_fn, d, (model_args, model_kwargs))
    numbers = {"step_size": step_size, "inverse_mass_matrix": inverse_mass_matrix,
               "magnetic_field": magnetic_field, **model}  # fmt: skip
    fixed["num_integration_steps"] = num_integration_steps
    return Sampler(
        init_fn,
        step_fn,
        settings=settings,
        check_positions=check_positions,
        stuck_advice=STUCK_ADVICE,
        structure=Recipe(magnetic_hmc, (logdensity_fn,), fixed, numbers).structure(),
    )


def _unset(logdensity_fn, fixed: dict, model: dict) -> Sampler:
    """``magnetic_hmc(logdensity_fn)``: a sampler that cannot step, declaring how
    :func:`liesample.sample`'s warm-up tunes it (``"chees"``) and remakes its
    :class:`~liesample.samplers.contract.Recipe` as :func:`jittered_magnetic_hmc` with the other
    arguments, ``fixed``, and the model's arguments ``model``."""
    recipe = Recipe(magnetic_hmc, (logdensity_fn,), fixed, model)
    settings = {"sampler": "magnetic_hmc", "step_size": None, "step_size_source": UNSET}
    density = with_model_arguments(logdensity_fn, *_model_arguments(model))
    return Sampler(
        lambda position, rng_key=None: init(position, density, rng_key),
        unset_step("magnetic_hmc", "logdensity_fn"),
        settings=settings,
        check_positions=check_starts(logdensity_fn, None, _model_arguments(model)),
        adaptation=ADAPTATION,
        stuck_advice=STUCK_ADVICE,
        structure=recipe.structure(),
        recipe=recipe,
    )


def _model_arguments(model: dict) -> tuple:
    """``(model_args, model_kwargs)`` of :func:`liesample.samplers.cotangent._core.model_values`."""
    return model.get("model_args", ()), model.get("model_kwargs")


STUCK_ADVICE = (
    "Give a smaller step_size, or tune it: (states, parameters), _ = "
    "liesample.magnetic_window_adaptation(logdensity_fn).run(rng_key, initial_positions, 1000) "
    "(initial_positions with a leading axis of >= 2 chains), then "
    "liesample.jittered_magnetic_hmc(logdensity_fn, **parameters) started from "
    "states.position with num_warmup=0, exact_starts=True."
)
"""The stuck-chain advice of ``magnetic_hmc`` (``Sampler.stuck_advice``)."""

magnetic_hmc = sampling_api(
    as_top_level_api, init, build_kernel, "magnetic_hmc", __name__, adaptation=ADAPTATION
)


def jittered_magnetic_hmc(
    logdensity_fn: LogDensityFn,
    step_size: float | jax.Array,
    inverse_mass_matrix: ArrayLike,
    num_integration_steps: int | jax.Array,
    magnetic_field: ArrayLike | None,
    **options: Any,
) -> Sampler:
    """``liesample.magnetic_hmc`` whose trajectory has ``L ~ Uniform{1, …, num_integration_steps}``
    steps, drawn afresh at every transition (the jitter ChEES tunes ``T`` for:
    ``num_integration_steps = ceil(T / ε)`` from
    :func:`liesample.tuning.adaptation.magnetic_window_adaptation`).

    Jittering the length keeps the chain from locking onto a period of the target (a Gaussian
    direction whose half-period divides ``Lε`` does not move under a fixed ``L``); each
    transition is a ``magnetic_hmc`` transition, so the law is kept for every ``L``. Same
    arguments and ``options`` (``integrator`` included) as ``liesample.magnetic_hmc``; the flows
    ``e^{±εGM⁻¹}`` do not depend on ``L`` and are computed once per compiled run.

    Examples
    --------
    >>> logdensity_fn = lambda x: -0.5 * x @ x
    >>> field = liesample.default_magnetic_field(jnp.ones(4), strength=1.0)
    >>> sampler = liesample.jittered_magnetic_hmc(logdensity_fn, 0.2, jnp.ones(4), 5, field)
    >>> state, info = jax.jit(sampler.step)(jax.random.key(0), sampler.init(jnp.zeros(4)))
    >>> 1 <= int(info.num_integration_steps) <= 5  # L drawn from {1, …, 5}
    True
    """
    model = model_values(options.pop("model_args", ()), options.pop("model_kwargs", None))
    base = magnetic_hmc(
        logdensity_fn,
        step_size,
        inverse_mass_matrix,
        num_integration_steps,
        magnetic_field,
        **options,
        **model,
    )

    def step_fn(rng_key, state):
        key_length, key_step = jax.random.split(step_key(rng_key))
        u = jax.random.uniform(key_length, (), jnp.asarray(step_size).dtype)
        steps = jnp.clip(jnp.ceil(u * num_integration_steps), 1, num_integration_steps)
        sampler = magnetic_hmc(
            logdensity_fn,
            step_size,
            inverse_mass_matrix,
            steps.astype(int),
            magnetic_field,
            **options,
            **model,
        )
        return sampler.step(key_step, state)

    settings = dict(base.settings)
    settings["sampler"] = "jittered_magnetic_hmc"
    settings["max_num_integration_steps"] = settings.pop("num_integration_steps")
    numbers = {"step_size": step_size, "inverse_mass_matrix": inverse_mass_matrix,
               "num_integration_steps": jnp.asarray(num_integration_steps),
               "magnetic_field": magnetic_field}  # fmt: skip
    numbers.update(model)
    return Sampler(
        base.init,
        step_fn,
        settings=settings,
        check_positions=base.check_positions,
        stuck_advice=STUCK_ADVICE,
        structure=Recipe(jittered_magnetic_hmc, (logdensity_fn,), options, numbers).structure(),
    )
