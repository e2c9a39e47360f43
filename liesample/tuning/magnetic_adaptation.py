"""Magnetic HMC's warm-up: several chains tuned together, the field with the mass and step.

``liesample.window_adaptation(liesample.magnetic_hmc, logdensity_fn)``, i.e.
:func:`magnetic_window_adaptation`: the chains share Stan's schedule; the field is off until
the first slow window closes (the chains converge and the first mass is estimated without it),
then re-derived from the current mass and step size at every step (a fixed rotation angle per
leapfrog step), so the step size is dual-averaged with the field on, and the trajectory length
is learnt by a ChEES-type rule over jittered lengths
(:mod:`liesample.tuning.trajectory`); sample with
:func:`liesample.samplers.cotangent.magnetic_hmc.jittered_magnetic_hmc`. It is the instance of
:func:`liesample.tuning.windows.windows_adaptation` for magnetic HMC, run by
:func:`liesample.tuning.protocol.run_adaptation` as one compiled program per plan
(:class:`liesample.foundation.identity.Program`).
"""

from __future__ import annotations

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
from liesample.samplers.contract import (
    SamplingAPI,
    Tunable,
    as_sampler,
    first_bad_chain,
)
from liesample.samplers.cotangent._core import (
    check_logdensity_fn,
    with_model_arguments,
)
from liesample.samplers.cotangent._euclidean import default_magnetic_field
from liesample.samplers.cotangent.magnetic_hmc import magnetic_hmc
from liesample.tuning.adaptation_runs import GeometricAdaptation, check_flags, steps_first
from liesample.tuning.protocol import run_adaptation, schedule
from liesample.tuning.trajectory import (
    CHEES_LEARNING_RATE,
    DEFAULT_INTEGRATION_TIME,
    MAX_NUM_INTEGRATION_STEPS,
    ChainMove,
    TrajectoryAdaptation,
    trajectory_adaptation,
)
from liesample.tuning.windows import (
    Windows,
    regularised_variance,
    windows_adaptation,
)

__all__ = [
    "CHEES_TARGET_ACCEPTANCE_RATE",
    "DEFAULT_ANGLE",
    "MagneticAdaptationInfo",
    "magnetic_window_adaptation",
]


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
    check_flags(progress_bar=progress_bar)
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
    initial_step_size: float | None  # None in the plan a compiled warm-up is keyed by
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
    info = MagneticAdaptationInfo(*steps_first(info[:2]), *(x[0] for x in info[2:]))
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
