"""Window adaptation for the geometric and magnetic samplers: step size, mass, trajectory length.

``liesample.window_adaptation(algorithm, logdensity_fn, space, **parameters)`` mirrors
``blackjax.window_adaptation``: ``.run(rng_key, initial_position, num_steps)`` returns
``((state, parameters), info)`` and ``algorithm(logdensity_fn, space, **parameters)`` is the
tuned sampler. What is tuned, and how, the sampler declares: ``algorithm.adaptation`` (a
:class:`liesample.samplers.contract.Tunable`, given to
:func:`liesample.samplers.contract.sampling_api`) names the method, the adapted parameters,
the kernel's parameters and ``build_kernel`` options (the integration scheme ``integrator``
among them, passed through) and the default target. Stan's schedule (:func:`window_schedule`):
a fast window (step size only), doubling slow windows (step size and mass; the step size is
restarted at the end of each), a final fast window. The step size is tuned by dual averaging
(``blackjax.adaptation.step_size.dual_averaging_adaptation``) towards a target Metropolis rate
(``info.metropolis_rate``: for unadjusted Langevin the rate the step *would* have).

**Mass, in algebra coordinates.** ``Euclidean`` blocks: ``M⁻¹`` is the Welford variance of the
position (as BlackJAX, with Stan's shrinkage towards ``1e-3``). Group, sphere and ``U1`` blocks
have no global coordinates whose variance means anything (an angle's variance depends on where
it is cut), so there the mass is the mean squared trivialised gradient,
``M = E[(X_k log π)²] + 1`` (one value per copy of a group or sphere, the mean over its
algebra coordinates; one per angle for ``U1``). Integration by parts against Haar measure
(left-invariant fields are divergence-free) gives ``E[(X_k log π)²] = −E[X_k² log π]``, the
mean curvature of ``−log π`` along ``X_k``: for a Gaussian ``N(0, Σ)`` it is ``Σ⁻¹``, i.e. the
ideal mass. The ``+ 1`` is the unit sphere's own curvature scale: it keeps the mass finite for
a nearly uniform law, where any mass would do.

**Trajectory length (HMC).** Default: each transition integrates ``u T`` (``u`` the base-2
Halton point of its index), ``T`` learnt by the ChEES-type rule of
:mod:`liesample.tuning.trajectory` from ``π/2`` in the units set by the mass; the tuned
sampler gets ``num_integration_steps = ceil(T / step_size)`` and ``jitter=True``. Pass
``integration_time`` to fix ``T`` (still jittered) or ``num_integration_steps`` to fix ``L``
instead (then the integration time follows the step size, as in
``blackjax.window_adaptation``).

**One protocol.** Both adaptations are the instance of
:func:`liesample.tuning.windows.windows_adaptation` for their sampler, run by
:func:`liesample.tuning.protocol.run_adaptation`: every chain runs the chain loop of the
sampling that follows (chain ``c`` with key ``split(rng_key, chains)[c]``), and the chains share
one adaptation state.

**Magnetic HMC** (``liesample.window_adaptation(liesample.magnetic_hmc, logdensity_fn)``, i.e.
:func:`magnetic_window_adaptation`): several chains tuned together on the same schedule; the
field is off until the first slow window closes (the chains converge and the first mass is
estimated without it), then re-derived from the current mass and step size at every step (a
fixed rotation angle per leapfrog step), so the step size is dual-averaged with the field on,
and the trajectory length is learnt by a ChEES-type rule over jittered lengths; sample with
:func:`liesample.samplers.cotangent.magnetic_hmc.jittered_magnetic_hmc`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple, cast

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from liesample.foundation.identity import Program, run_program
from liesample.foundation.types import LogDensityFn
from liesample.foundation.validation import finite_float, prng_key
from liesample.geometry import spaces
from liesample.geometry.spaces import SpaceTree
from liesample.samplers.contract import (
    Sampler,
    SamplingAPI,
    Tunable,
    as_sampler,
    first_bad_chain,
)
from liesample.samplers.cotangent._core import (
    check_logdensity_fn,
    check_starts,
    with_model_arguments,
)
from liesample.samplers.cotangent._euclidean import default_magnetic_field
from liesample.samplers.cotangent.magnetic_hmc import magnetic_hmc
from liesample.tuning.protocol import run_adaptation, schedule
from liesample.tuning.trajectory import (
    CHEES_LEARNING_RATE,
    DEFAULT_INTEGRATION_TIME,
    MAX_NUM_INTEGRATION_STEPS,
    ChainMove,
    TrajectoryAdaptation,
    chain_move,
    euclidean_size,
    trajectory_adaptation,
)
from liesample.tuning.windows import (
    Windows,
    inverse_mass,
    regularised_variance,
    statistic,
    windows_adaptation,
)

__all__ = [
    "DEFAULT_ANGLE",
    "DEFAULT_INTEGRATION_TIME",
    "MagneticAdaptationInfo",
    "magnetic_window_adaptation",
    "window_adaptation",
    "window_schedule",
]


class GeometricAdaptation(NamedTuple):
    """What ``window_adaptation`` returns: ``run(rng_key, initial_position, num_steps)``."""

    run: Callable


class AdaptationInfo(NamedTuple):
    """Per warm-up step: the sampler's state and info, the step size and trajectory length."""

    state: object
    info: object
    step_size: jax.Array
    num_integration_steps: jax.Array


def window_schedule(num_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Stan's warm-up windows for ``num_steps`` transitions: ``(stage, window_end)`` per step,
    ``stage`` 0 in a fast window and 1 in a slow one, ``window_end`` true at the last step of a
    slow window (:func:`liesample.tuning.protocol.schedule`)."""
    rows = schedule(num_steps)
    return np.asarray(rows.stage), np.asarray(rows.window_end)  # numpy already: no copy


def integration_steps(step_size, integration_time):
    """``L = ceil(T / ε)``, clipped to ``[1, MAX_NUM_INTEGRATION_STEPS]`` (traceable)."""
    steps = jnp.ceil(integration_time / step_size)
    return jnp.clip(steps, 1, MAX_NUM_INTEGRATION_STEPS).astype(int)


def _num_chains(space, position) -> int | None:
    """The chains of a batch of starts (one more leading axis than ``space``'s points), or
    ``None`` for one point."""
    leaves = jax.tree.leaves(position)
    extra = {
        np.ndim(x) - len(s.position_array_shape)
        for s, x in zip(spaces._spaces(space), leaves, strict=False)
    }
    if extra == {1} and len(leaves) == len(spaces._spaces(space)):
        sizes = {np.shape(x)[0] for x in leaves}
        if len(sizes) != 1:
            raise ValueError(f"the starts' leaves have different numbers of chains: {sizes}")
        return sizes.pop()
    return None


def window_adaptation(
    algorithm: SamplingAPI[...],
    logdensity_fn: LogDensityFn,
    space: SpaceTree | None = None,
    *,
    initial_step_size: float = 0.1,
    target_acceptance_rate: float | None = None,
    integration_time: float | None = None,
    adapt_mass: bool = True,
    progress_bar: bool = False,
    model_args: tuple = (),
    model_kwargs: dict | None = None,
    **parameters: Any,
) -> GeometricAdaptation:
    """Tune ``algorithm`` (``liesample.geometric_hmc``, ``liesample.geometric_langevin``, or
    ``liesample.magnetic_hmc``: then :func:`magnetic_window_adaptation`, without ``space``).

    Parameters
    ----------
    algorithm
        The sampler's API object; its ``adaptation`` declaration (module docstring) says what is
        adapted, and its ``build_kernel`` takes the declared options in ``parameters`` (e.g.
        ``adjusted=True`` for Langevin, ``integrator``).
    logdensity_fn, space
        As for the sampler.
    initial_step_size : float
        Starting point of dual averaging.
    target_acceptance_rate : float, optional
        Target Metropolis rate; by default the sampler's declared one (0.8 for HMC, 0.9 for
        Langevin: one step per transition, unadjusted chains are biased by the step size).
    integration_time : float, optional
        HMC only: ``T`` of the trajectory (default ``π/2``) unless ``num_integration_steps`` is
        given.
    adapt_mass : bool
        Adapt the inverse mass (else keep ``inverse_mass_matrix`` or unit mass).
    model_args, model_kwargs : tuple, dict
        Arguments of ``logdensity_fn`` after the position, as for the sampler
        (:func:`liesample.geometric_hmc`): numbers of the compiled warm-up, so the same
        ``logdensity_fn`` at other data compiles nothing new. ``magnetic_hmc`` takes none here.
    parameters
        The sampler's other arguments: ``num_integration_steps`` (HMC, fixes ``L``),
        ``friction`` (Langevin, default 1), ``inverse_mass_matrix`` (the starting mass),
        and ``build_kernel`` options (``adjusted``, ``divergence_threshold``, ``integrator``).

    Examples
    --------
    Tune geometric HMC's step size and mass on SO(3) (20 warm-up steps: only a sketch; use
    hundreds), then sample with the tuned parameters:

    >>> from liesample.spaces import SO
    >>> adaptation = liesample.window_adaptation(liesample.geometric_hmc, jnp.trace, SO(3),
    ...                                          num_integration_steps=3)
    >>> (state, parameters), info = adaptation.run(jax.random.key(0), jnp.eye(3), num_steps=20)
    >>> sorted(parameters)
    ['inverse_mass_matrix', 'num_integration_steps', 'step_size']
    >>> sampler = liesample.geometric_hmc(jnp.trace, SO(3), **parameters)
    """
    name = type(algorithm).__name__
    declared = getattr(algorithm, "adaptation", None)
    if declared is None:
        raise TypeError(
            f"{name} declares no window adaptation (no adaptation= in its sampling_api)"
        )
    if declared.method == "chees":
        if space is not None:
            raise TypeError(
                f"{name} samples on R^d and takes no space; call "
                f"window_adaptation(liesample.{name}, logdensity_fn, **options)"
            )
        if target_acceptance_rate is not None:
            parameters["target_acceptance_rate"] = target_acceptance_rate
        return magnetic_window_adaptation(
            logdensity_fn,
            initial_step_size=initial_step_size,
            integration_time=integration_time,
            adapt_mass=adapt_mass,
            algorithm=algorithm,
            **parameters,
        )
    if space is None:
        raise TypeError(f"window_adaptation({name}, logdensity_fn, space): give the space")
    with_model_arguments(logdensity_fn, model_args, model_kwargs)  # each argument checked
    model = (tuple(model_args), dict(model_kwargs or {}))
    _check_flags(adapt_mass=adapt_mass, progress_bar=progress_bar)
    del progress_bar  # accepted for BlackJAX compatibility; the warm-up runs in one compiled loop
    spaces._spaces(space)
    finite_float("initial_step_size", initial_step_size, positive=True)
    plan = _window_plan(algorithm, declared, target_acceptance_rate, integration_time, parameters)
    warm_up = functools.partial(
        _window_run, plan, algorithm, logdensity_fn, model, space, initial_step_size, adapt_mass
    )

    def run(rng_key, initial_position, num_steps: int = 1000):
        """Warm up for ``num_steps`` transitions: ``((state, parameters), info)``.

        ``initial_position`` is one point, or a batch of starts with a leading chain axis (one
        per chain, as for :func:`liesample.sample`): the chains then adapt together (shared
        step size and mass) and ``state`` holds every chain's final state, the starts of the
        run that follows. One point gives one chain's state (BlackJAX's shape); to sample it
        with :func:`liesample.sample`, give it a chain axis of one
        (``jax.tree.map(lambda x: x[None], state.position)``)."""
        return warm_up(rng_key, initial_position, num_steps)

    return GeometricAdaptation(run)


def _check_flags(**flags) -> None:
    """A ``TypeError`` naming the first flag that is not a bool (``"no"`` would read as true)."""
    for name, value in flags.items():
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{name} must be a bool (True or False), got {value!r}")


class _WindowPlan(NamedTuple):
    """What :func:`window_adaptation` checked: the sampler's API object and its kernel's
    options, the sampler's other parameters, the target rate, the starting mass, a fixed ``L``
    (or ``None``) and the rule for ``T`` (HMC with ``L`` unset: jittered): its initial time and
    whether it learns. Values only, so that equal plans share one compiled warm-up."""

    algorithm: Any
    build_options: dict
    parameters: dict
    target: float
    initial_mass: object
    is_hmc: bool
    fixed_steps: int | None
    time: float
    learn: bool

    @property
    def lengths(self):
        """The trajectory rule (:func:`liesample.tuning.trajectory.trajectory_adaptation`)."""
        return trajectory_adaptation(self.time, learn=self.learn)


def _window_plan(algorithm, declared, target_acceptance_rate, integration_time, parameters):
    """Validate ``window_adaptation``'s arguments against the sampler's declaration."""
    name = type(algorithm).__name__
    build_options = {k: parameters.pop(k) for k in declared.options if k in parameters}
    algorithm.build_kernel(**build_options)  # its options checked now, by name
    is_hmc = "num_integration_steps" in declared.adapted
    fixed_steps = parameters.pop("num_integration_steps", None)
    if not is_hmc and (fixed_steps is not None or integration_time is not None):
        raise ValueError("num_integration_steps and integration_time are HMC parameters")
    if fixed_steps is not None and integration_time is not None:
        raise ValueError("give integration_time or num_integration_steps, not both")
    if fixed_steps is not None and (
        isinstance(fixed_steps, bool) or int(fixed_steps) != fixed_steps or fixed_steps < 1
    ):
        raise ValueError(f"num_integration_steps must be an integer >= 1, got {fixed_steps!r}")
    time = DEFAULT_INTEGRATION_TIME if integration_time is None else integration_time
    time = finite_float("integration_time", time, positive=True)
    learn = is_hmc and fixed_steps is None and integration_time is None
    for key, value in declared.defaults.items():
        parameters.setdefault(key, value)
    if target_acceptance_rate is None:
        target_acceptance_rate = declared.target_acceptance_rate
    target = finite_float("target_acceptance_rate", target_acceptance_rate, rate=True)
    if "step_size" in parameters:
        raise TypeError("step_size is what window_adaptation tunes: give initial_step_size")
    unknown = set(parameters) - set(declared.accepts)
    if unknown:
        raise TypeError(
            f"unknown parameters for {name}: {sorted(unknown)}; it takes "
            f"{sorted(declared.accepts)} and the options {sorted(declared.options)}"
        )
    initial_mass = parameters.pop("inverse_mass_matrix", None)
    fixed = None if fixed_steps is None else int(fixed_steps)
    return _WindowPlan(
        algorithm, build_options, parameters, target, initial_mass, is_hmc, fixed, time, learn
    )


def _window_run(plan, algorithm, logdensity_fn, model, space, initial_step_size, adapt_mass,
                rng_key, initial_position, num_steps):  # fmt: skip
    """``run`` of :func:`window_adaptation`: the chains' states, the warm-up (the adaptation of
    :func:`_window_windows` run by :func:`liesample.tuning.protocol.run_adaptation`) and the
    tuned parameters."""
    if isinstance(num_steps, bool) or int(num_steps) != num_steps or num_steps < 20:
        raise ValueError(f"num_steps must be an integer >= 20, got {num_steps!r}")
    rng_key = prng_key(rng_key)
    num_chains = _num_chains(space, initial_position)
    batched = num_chains is not None
    init = Program(_init_program, algorithm, logdensity_fn, space)  # compiled once per value
    if batched:
        check_starts(space)(initial_position)
        states = run_program(init, initial_position, model)
    else:
        spaces.check_position(space, initial_position, "initial_position")
        one = jax.tree.map(lambda leaf: leaf[None], initial_position)
        states = run_program(init, one, model)
    chain = first_bad_chain(np.isfinite(np.asarray(states.logdensity)))
    if chain is not None:  # under jit, init does not check log π
        raise ValueError(
            f"initial_position{f'[{chain}]' if batched else ''}: logdensity_fn is not finite "
            "there; start every chain where log π is finite"
        )
    dtype = jnp.asarray(states.logdensity).dtype
    start = {
        "step_size": jnp.asarray(initial_step_size, dtype),
        "inverse_mass_matrix": spaces.check_inverse_mass(space, plan.initial_mass, dtype),
    }
    warmup = Program(
        _window_program, plan._replace(initial_mass=None), logdensity_fn, space, adapt_mass,
        int(num_steps),
    )  # fmt: skip
    chain_keys = jax.random.split(rng_key, num_chains or 1)
    states, tuned, info = run_program(warmup, chain_keys, states, start, model)
    info = AdaptationInfo(*_steps_first(info[:2]), *(x[0] for x in info[2:]))
    if not batched:
        states, info = (
            jax.tree.map(lambda leaf: leaf[0], states),
            info._replace(
                state=jax.tree.map(lambda x: x[:, 0], info.state),
                info=jax.tree.map(lambda x: x[:, 0], info.info),
            ),
        )
    step_size = float(tuned["step_size"])
    parameters = {**plan.parameters, "step_size": step_size,
                  "inverse_mass_matrix": tuned["inverse_mass_matrix"]}  # fmt: skip
    if plan.fixed_steps is not None:
        parameters["num_integration_steps"] = plan.fixed_steps
    elif plan.is_hmc:
        time = float(tuned["integration_time"])
        parameters["num_integration_steps"] = int(integration_steps(step_size, time))
        parameters["jitter"] = True
    parameters.update(plan.build_options)
    return (states, parameters), info


def _init_program(algorithm, logdensity_fn, space):
    """Every chain's initial state, for the model's arguments ``model``
    (:class:`liesample.foundation.identity.Program`)."""

    def init(positions, model):
        density = with_model_arguments(logdensity_fn, *model)
        return jax.vmap(lambda x: algorithm.init(x, density, space))(positions)

    return init


def _window_program(plan, logdensity_fn, space, adapt_mass, num_steps):
    """The warm-up of :func:`_window_run` as a function of the chains' keys, states and start
    (:class:`liesample.foundation.identity.Program`: one compilation for equal plans)."""
    kernel = plan.algorithm.build_kernel(**plan.build_options)
    adaptation = windows_adaptation(_window_windows(plan, space, adapt_mass))

    def warmup(chain_keys, states, start, model):
        density = with_model_arguments(logdensity_fn, *model)

        def init(position):
            return plan.algorithm.init(position, density, space)

        def sampler_at(step_size, inverse_mass_matrix, num_integration_steps=None,
                       integration_time=None):  # fmt: skip
            del integration_time
            extra = {"step_size": step_size, "inverse_mass_matrix": inverse_mass_matrix}
            if num_integration_steps is not None:
                extra["num_integration_steps"] = num_integration_steps

            def step(key, state):
                return kernel(key, state, density, space, **extra, **plan.parameters)

            return Sampler(init, step)

        def record(parameters, state, info):
            steps = parameters.get("num_integration_steps", jnp.asarray(plan.fixed_steps or 1))
            return AdaptationInfo(state, info, parameters["step_size"], steps)

        return run_adaptation(adaptation, sampler_at, chain_keys, states, start, num_steps, record)

    return warmup


def _steps_first(records):
    """Per-chain records of :func:`liesample.tuning.protocol.run_adaptation` (chains,
    transitions, …) as BlackJAX lays them out (transitions, chains, …)."""
    return jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), records)


def _window_windows(plan, space, adapt_mass) -> Windows:
    """:class:`liesample.tuning.windows.Windows` of a T*G sampler on ``space``: dual averaging
    of the Metropolis rate, the mass of :func:`liesample.tuning.windows.inverse_mass`, ``T`` by
    the trajectory rule when ``L`` is jittered."""
    jittered = plan.is_hmc and plan.fixed_steps is None
    return Windows(
        plan.target,
        "metropolis_rate",
        jax.vmap(functools.partial(statistic, space)),
        functools.partial(inverse_mass, space),
        adapt_mass,
        lengths=plan.lengths if jittered else None,
        move=lambda before, after, infos, mass: chain_move(space, before, after, infos, mass, True),
        dimension=euclidean_size(space),
        fixed_steps=plan.fixed_steps if plan.is_hmc else None,
    )


# --------------------------------------------------------------------------- magnetic HMC

DEFAULT_ANGLE = 0.0
"""Default field of :func:`magnetic_window_adaptation`, as the angle (rad) per step: no field.
A field helps on some targets (strongly correlated or curved ones) and slows the slowest
directions of others, so it is opt-in; ``angle > 0`` turns it on, adapted jointly."""
_MAGNETIC_HMC_WARMUP = cast(Tunable, magnetic_hmc.adaptation)  # declared with a target rate
CHEES_TARGET_ACCEPTANCE_RATE = cast(float, _MAGNETIC_HMC_WARMUP.target_acceptance_rate)


class MagneticAdaptationInfo(NamedTuple):
    """Per warm-up step, every chain: state and info after the step; the shared step size,
    leapfrog steps (jittered), trajectory length ``T`` (before jitter) and field strength."""

    state: object
    info: object
    step_size: jax.Array
    num_integration_steps: jax.Array
    trajectory_length: jax.Array
    strength: jax.Array


def _rotation(dimension: int) -> np.ndarray:
    """``J̃`` of :func:`default_magnetic_field`: its field for unit mass and unit strength."""
    return np.asarray(default_magnetic_field(np.ones(dimension), 1.0))


def _field(rotation, inverse_mass, strength):
    """``default_magnetic_field(M⁻¹, strength)`` for a diagonal ``M⁻¹``, traceable:
    ``G = strength · M^{1/2} J̃ M^{1/2}``, i.e. ``G_ij = strength · J̃_ij / √(m⁻¹_i m⁻¹_j)``."""
    scale = jax.lax.rsqrt(inverse_mass)
    return strength * rotation * scale[:, None] * scale[None, :]


def _field_from(ends) -> int:
    """Last warm-up step without the field: the end of the first slow window (``-1``, the field
    on throughout, when the schedule has no slow window).

    The field is scaled to the step (``angle / ε`` in the whitened frame) and the step is set by
    the stiffest direction, so relative to the slower directions the field is strong, and a
    strong field turns a force into a drift across it, along the level sets of ``log π``
    (``E × B`` drift). Chains started far from the typical set then barely descend: they slide
    along level sets, far out along weakly bound directions; the first slow window's variance
    counts that excursion, the mass it gives calls for a much smaller step, which strengthens
    the field further, and the step collapses. Without the field the chains converge and the
    first mass is the target's; dual averaging restarts there (when the mass is adapted), with
    the field on. The field changes the dynamics, never the target: every transition is exact.
    """
    closes = np.flatnonzero(ends)
    return int(closes[0]) if closes.size else -1


def magnetic_window_adaptation(
    logdensity_fn: LogDensityFn,
    *,
    angle: float = DEFAULT_ANGLE,
    initial_step_size: float = 0.1,
    target_acceptance_rate: float = CHEES_TARGET_ACCEPTANCE_RATE,
    integration_time: float | None = None,
    initial_integration_time: float = DEFAULT_INTEGRATION_TIME,
    learning_rate: float = CHEES_LEARNING_RATE,
    adapt_mass: bool = True,
    divergence_threshold: float = 1000.0,
    max_num_integration_steps: int = MAX_NUM_INTEGRATION_STEPS,
    progress_bar: bool = False,
    integrator: str | Sequence[tuple[str, float]] | None = None,
    algorithm: SamplingAPI[...] = magnetic_hmc,
    model_args: tuple = (),
    model_kwargs: dict | None = None,
) -> GeometricAdaptation:
    """Tune ``liesample.magnetic_hmc`` on several chains at once: step size, diagonal mass, the
    field (jointly with both) and the trajectory length (ChEES).

    Also reached as ``liesample.window_adaptation(liesample.magnetic_hmc, logdensity_fn, ...)``.
    ``.run(rng_key, initial_positions, num_steps=1000)`` takes positions with a leading chain
    axis (``C >= 2`` chains; ChEES estimates the target's mean across them, 4 or more are
    better) and returns ``((states, parameters), info)``: the chains' last states (leading
    chain axis), ``parameters`` for ``liesample.magnetic_hmc(logdensity_fn, **parameters)``
    (``step_size``, diagonal ``inverse_mass_matrix``, ``magnetic_field``,
    ``num_integration_steps``) and :class:`MagneticAdaptationInfo` per step. The adapted
    trajectory length ``T`` is ``info.trajectory_length[-1]``; ``num_integration_steps`` is the
    mean of the jittered lengths, ``round(T / (2ε))``.

    **Schedule.** Stan's windows (as :func:`window_adaptation`), all chains sharing one set of
    parameters: the step size is dual-averaged towards ``target_acceptance_rate`` of the chains'
    pooled acceptance probability (:func:`pooled_rate`) *with the field on*; the inverse mass is the
    regularised variance of every chain's draws in a slow window. The field is off up to the end of
    the first slow window (:func:`_field_from`: a field scaled to the step slows the chains'
    convergence and would spoil the first mass); from there on, at every step, it is
    ``default_magnetic_field(M⁻¹, angle / ε)`` for the current ``M⁻¹`` and ``ε``, so the whitened
    velocity turns by ``angle`` rad per leapfrog step.

    **Trajectory length (ChEES).** Each transition integrates for ``t = u T`` with ``u`` from the
    base-2 Halton sequence (the same for every chain), ``L = ceil(t / ε)`` steps; ``log T`` is
    learnt by the ChEES-type rule of :mod:`liesample.tuning.trajectory` (stochastic ascent on
    the squared distance's ESS per gradient, the same per gradient for every ``integrator``,
    bounded above by the chains' spread). The returned ``T`` is ``exp`` of the mean of
    ``log T`` over the last slow window and the final fast window; ``integration_time=T``
    fixes ``T`` instead.

    Parameters
    ----------
    logdensity_fn : callable
        ``log π`` of a position (a pytree; flattened as the sampler flattens it).
    angle : float
        Rotation (rad) of the whitened velocity per step; 0 (:data:`DEFAULT_ANGLE`) is plain
        HMC with the same rules.
    initial_step_size, target_acceptance_rate
        Dual averaging's start and target (0.651, ChEES-HMC's, by default).
    integration_time, initial_integration_time, learning_rate
        Fixed ``T`` (no ChEES), or the rule's starting ``T`` (``π/2``) and step on ``log T``.
    adapt_mass : bool
        Adapt the diagonal inverse mass (else unit mass).
    divergence_threshold : float
        As for the sampler.
    max_num_integration_steps : int
        Cap on ``L`` per transition (and on ``T / ε``).
    integrator : str or sequence of (effect, fraction) pairs, optional
        The sampler's integration scheme (``liesample.magnetic_hmc``'s ``integrator``), used in
        the warm-up and returned in ``parameters`` when given.
    algorithm
        The sampler tuned: ``liesample.magnetic_hmc`` or one with its signature.

    Examples
    --------
    Four chains on a standard normal (20 warm-up steps: only a sketch; use hundreds):

    >>> adaptation = liesample.magnetic_window_adaptation(lambda x: -0.5 * x @ x, angle=0.25)
    >>> (states, parameters), info = adaptation.run(jax.random.key(0), jnp.zeros((4, 2)),
    ...                                             num_steps=20)
    >>> states.position.shape, sorted(parameters)
    ((4, 2), ['inverse_mass_matrix', 'magnetic_field', 'num_integration_steps', 'step_size'])
    >>> sampler = liesample.jittered_magnetic_hmc(lambda x: -0.5 * x @ x, **parameters)
    """
    _check_flags(progress_bar=progress_bar)
    del progress_bar  # accepted for BlackJAX compatibility; the warm-up is one compiled loop
    with_model_arguments(logdensity_fn, model_args, model_kwargs)  # each argument checked
    model = (tuple(model_args), dict(model_kwargs or {}))
    plan = _magnetic_plan(
        algorithm, logdensity_fn, angle, initial_step_size, target_acceptance_rate,
        integration_time, initial_integration_time, learning_rate, adapt_mass,
        divergence_threshold, max_num_integration_steps, integrator,
    )  # fmt: skip

    def run(rng_key, initial_positions, num_steps: int = 1000):
        """Warm up ``C`` chains for ``num_steps`` transitions; ``((states, parameters), info)``."""
        return _magnetic_run(plan, model, rng_key, initial_positions, num_steps)

    return GeometricAdaptation(run)


class _MagneticPlan(NamedTuple):
    """What :func:`magnetic_window_adaptation` checked."""

    algorithm: Any  # magnetic_hmc: called for a sampler, with an ``init`` of its own
    logdensity_fn: Callable
    angle: float
    target: float
    initial_step_size: float
    adapt_mass: bool
    max_steps: int
    options: dict  # the sampler's keywords: divergence_threshold and the scheme
    trajectory: tuple  # trajectory_adaptation's arguments (values: equal plans, one program)

    @property
    def lengths(self) -> TrajectoryAdaptation:
        """The trajectory rule (:func:`liesample.tuning.trajectory.trajectory_adaptation`)."""
        time, learning_rate, max_steps, learn = self.trajectory
        return trajectory_adaptation(time, learning_rate, max_steps, learn=learn)


def _magnetic_plan(algorithm, logdensity_fn, angle, initial_step_size, target_acceptance_rate,
                   integration_time, initial_integration_time, learning_rate, adapt_mass,
                   divergence_threshold, max_num_integration_steps,
                   integrator) -> _MagneticPlan:  # fmt: skip
    """:func:`magnetic_window_adaptation`'s arguments checked, each error naming its parameter."""
    check_logdensity_fn(logdensity_fn)
    if not callable(getattr(algorithm, "build_kernel", None)):
        raise TypeError(
            f"algorithm must be liesample.magnetic_hmc or a sampler with its signature (a "
            f"build_kernel), got {algorithm!r}"
        )
    scheme = {} if integrator is None else {"integrator": integrator}
    algorithm.build_kernel(**scheme)  # validates the scheme now
    angle = finite_float("angle", angle, nonnegative=True)
    finite_float("initial_step_size", initial_step_size, positive=True)
    target = finite_float("target_acceptance_rate", target_acceptance_rate, rate=True)
    if integration_time is not None:
        integration_time = finite_float("integration_time", integration_time, positive=True)
    initial_time = finite_float("initial_integration_time", initial_integration_time, positive=True)
    learning_rate = finite_float("learning_rate", learning_rate, positive=True)
    if not isinstance(adapt_mass, bool):
        raise TypeError(f"adapt_mass must be a bool, got {adapt_mass!r}")
    max_steps = max_num_integration_steps
    if isinstance(max_steps, bool) or int(max_steps) != max_steps or max_steps < 1:
        raise ValueError(f"max_num_integration_steps must be an integer >= 1, got {max_steps!r}")
    max_steps = int(max_steps)
    divergence_threshold = finite_float("divergence_threshold", divergence_threshold, positive=True)
    trajectory = (
        initial_time if integration_time is None else integration_time,
        learning_rate,
        max_steps,
        integration_time is None,
    )
    trajectory_adaptation(*trajectory[:3])  # its arguments checked now, by name
    options = {"divergence_threshold": divergence_threshold, **scheme}
    return _MagneticPlan(
        algorithm, logdensity_fn, angle, target, initial_step_size, adapt_mass, max_steps,
        options, trajectory,
    )  # fmt: skip


def _magnetic_run(plan: _MagneticPlan, model, rng_key, initial_positions, num_steps):
    """``run`` of :func:`magnetic_window_adaptation`: the adaptation of
    :func:`_magnetic_windows` run by :func:`liesample.tuning.protocol.run_adaptation`."""
    if isinstance(num_steps, bool) or int(num_steps) != num_steps or num_steps < 20:
        raise ValueError(f"num_steps must be an integer >= 20, got {num_steps!r}")
    num_steps = int(num_steps)
    rng_key = prng_key(rng_key)
    density = with_model_arguments(plan.logdensity_fn, *model)
    flat = _flat_starts(initial_positions, density)
    num_chains, dimension = flat.shape
    states = jax.vmap(lambda x: plan.algorithm.init(x, density))(initial_positions)
    start = {"step_size": jnp.asarray(plan.initial_step_size, flat.dtype),
             "inverse_mass_matrix": jnp.ones(dimension, flat.dtype)}  # fmt: skip
    warmup = Program(
        _magnetic_program, plan._replace(initial_step_size=None), num_steps, dimension,
        np.dtype(flat.dtype).name,
    )  # fmt: skip
    keys = jax.random.split(rng_key, num_chains)
    states, tuned, info = run_program(warmup, keys, states, start, model)
    step_size = float(tuned["step_size"])
    trajectory = float(tuned["integration_time"])
    inverse_mass = np.asarray(tuned["inverse_mass_matrix"])
    if not (np.isfinite(step_size) and np.all(np.isfinite(inverse_mass))):
        raise FloatingPointError(
            "magnetic_window_adaptation ended with a non-finite step size or mass: the "
            "chains diverged (check logdensity_fn and the starts)"
        )
    steps = int(np.clip(math.ceil(trajectory / step_size), 1, plan.max_steps))
    parameters = {
        "step_size": step_size,
        "inverse_mass_matrix": inverse_mass,
        "num_integration_steps": steps,
        "magnetic_field": default_magnetic_field(inverse_mass, plan.angle / step_size),
        **{k: v for k, v in plan.options.items() if k == "integrator"},
    }
    info = MagneticAdaptationInfo(*_steps_first(info[:2]), *(x[0] for x in info[2:]))
    times = info.trajectory_length  # the T of each transition, then the tuned one last
    info = info._replace(trajectory_length=times.at[-1].set(trajectory))
    return (states, parameters), info


def _magnetic_program(plan: _MagneticPlan, num_steps, dimension, dtype):
    """The warm-up of :func:`_magnetic_run` as a function of the chains' keys, states and start
    (:class:`liesample.foundation.identity.Program`: one compilation for equal plans)."""
    adaptation = windows_adaptation(_magnetic_windows(plan, num_steps, dimension, dtype))

    def record(p, state, info):
        return MagneticAdaptationInfo(state, info, p["step_size"], p["num_integration_steps"],
                                      p["integration_time"], p["strength"])  # fmt: skip

    def warmup(chain_keys, states, start, model):
        args, kwargs = model
        options = {**plan.options, **({"model_args": args} if args else {}),
                   **({"model_kwargs": kwargs} if kwargs else {})}  # fmt: skip

        def sampler_at(step_size, inverse_mass_matrix, num_integration_steps, integration_time,
                       magnetic_field, strength):  # fmt: skip
            del integration_time, strength
            # the top-level API: the flows e^{±εGM⁻¹} are computed once per step for all chains
            sampler = plan.algorithm(plan.logdensity_fn, step_size, inverse_mass_matrix,
                                     num_integration_steps, magnetic_field, **options)  # fmt: skip
            return as_sampler(sampler)

        return run_adaptation(adaptation, sampler_at, chain_keys, states, start, num_steps, record)

    return warmup


def _magnetic_windows(plan: _MagneticPlan, num_steps, dimension, dtype) -> Windows:
    """:class:`liesample.tuning.windows.Windows` of magnetic HMC: dual averaging of the chains'
    acceptance, the regularised variance of the flat positions, ``T`` by the trajectory rule,
    and the field, off until the first slow window closes (:func:`_field_from`), then
    ``default_magnetic_field(M⁻¹, angle / ε)``."""
    rotation = jnp.asarray(_rotation(dimension), dtype)
    zero_field = np.zeros((dimension, dimension))
    field_from = _field_from(schedule(num_steps).window_end)
    angle = plan.angle

    def field(row, step_size, inverse_mass):
        strength = jnp.where(row.index > field_from, angle / step_size, 0.0)
        # angle 0: a concrete zero field, so the sampler takes the free drift (no expm)
        value = zero_field if angle == 0.0 else _field(rotation, inverse_mass, strength)
        return {"magnetic_field": value, "strength": strength}

    def move(before, after, infos, inverse_mass):
        flat = jax.vmap(_ravel)
        return ChainMove(flat(before.position), flat(after.position), after.momentum,
                         infos.is_accepted, infos.acceptance_rate, inverse_mass)  # fmt: skip

    def mass_from(mean, m2, count):
        return regularised_variance(m2 / jnp.maximum(count - 1, 1), count.astype(m2.dtype))

    return Windows(
        plan.target,
        "acceptance_rate",
        lambda states: jax.vmap(_ravel)(states.position),
        mass_from,
        plan.adapt_mass,
        lengths=plan.lengths,
        move=move,
        dimension=dimension,
        max_steps=plan.max_steps,
        extra=field,
    )


def _ravel(tree):
    return ravel_pytree(tree)[0]


def _flat_starts(positions, logdensity_fn):
    """``(C, d)`` flat starts; refuses fewer than 2 chains and non-finite ``log π`` there."""
    leaves = jax.tree.leaves(positions)
    if not leaves:
        raise ValueError("initial_positions is an empty pytree")
    sizes = {np.shape(leaf)[0] if np.ndim(leaf) else None for leaf in leaves}
    if len(sizes) != 1 or None in sizes:
        raise ValueError(
            "initial_positions must have a leading chain axis of the same size on every leaf, "
            f"got leaf shapes {[np.shape(leaf) for leaf in leaves]}"
        )
    (num_chains,) = cast(set[int], sizes)  # a leaf without a chain axis was refused above
    if num_chains < 2:
        raise ValueError(
            f"magnetic_window_adaptation needs >= 2 chains (leading axis), got {num_chains}: "
            "ChEES estimates the target's mean across chains"
        )
    flat = jax.vmap(_ravel)(positions)
    if not jnp.issubdtype(flat.dtype, jnp.floating):
        raise TypeError(f"initial_positions must be real floating point, got {flat.dtype}")
    values = jax.vmap(jax.value_and_grad(logdensity_fn))(positions)
    grads = jax.vmap(_ravel)(values[1])
    ok = np.asarray(jnp.isfinite(values[0]) & jnp.all(jnp.isfinite(grads), -1))
    chain = first_bad_chain(ok)
    if chain is not None:
        raise ValueError(
            f"initial_positions[{chain}]: logdensity_fn or its gradient is not finite there; "
            "start every chain where log π is finite"
        )
    return flat
