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

**Magnetic HMC** (``liesample.window_adaptation(liesample.magnetic_hmc, logdensity_fn)``) is
:func:`magnetic_window_adaptation`, in :mod:`liesample.tuning.magnetic_adaptation` (re-exported
here).
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from liesample.foundation.identity import Program, run_program
from liesample.foundation.types import LogDensityFn
from liesample.foundation.validation import finite_float, prng_key
from liesample.geometry import spaces
from liesample.geometry.spaces import SpaceTree
from liesample.samplers.contract import (
    Sampler,
    SamplingAPI,
    first_bad_chain,
)
from liesample.samplers.cotangent._core import (
    check_starts,
    with_model_arguments,
)
from liesample.tuning.adaptation_runs import GeometricAdaptation, check_flags, steps_first
from liesample.tuning.magnetic_adaptation import (
    DEFAULT_ANGLE,
    MagneticAdaptationInfo,
    magnetic_window_adaptation,
)
from liesample.tuning.protocol import run_adaptation, schedule
from liesample.tuning.trajectory import (
    DEFAULT_INTEGRATION_TIME,
    MAX_NUM_INTEGRATION_STEPS,
    chain_move,
    euclidean_size,
    trajectory_adaptation,
)
from liesample.tuning.windows import (
    Windows,
    inverse_mass,
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
    check_flags(adapt_mass=adapt_mass, progress_bar=progress_bar)
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
    info = AdaptationInfo(*steps_first(info[:2]), *(x[0] for x in info[2:]))
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
