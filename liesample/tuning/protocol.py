"""The one adaptation protocol of liesample and the one driver that runs it.

An :class:`Adaptation` is BlackJAX's ``(init, update, final)`` plus ``current``, over a batch
of chains that adapt together (the chains' axis first everywhere):

- ``init(states, parameters) -> adaptation state``: from the chains' initial states and the
  sampler's starting parameters (a dict: ``step_size``, ``inverse_mass_matrix``, …);
- ``current(adaptation state, row) -> parameters``: what transition ``row.index`` of every
  chain uses (the shared step size, mass, number of integration steps, field, …);
- ``update(adaptation state, row, parameters, before, after, infos) -> adaptation state``:
  after that transition, from every chain's state before and after it and its info;
  ``None`` for an adaptation that learns nothing from transitions (a rule computed from the
  starts, :func:`fixed`: its ``final(init(…))`` is all there is, and the warm-up's transitions
  are ordinary steps of the sampler at those parameters);
- ``final(adaptation state) -> parameters``: the tuned parameters.

``row`` is one row of Stan's window schedule (:func:`schedule`): the transition's index, its
stage (0 fast, 1 slow window), whether a slow window ends there and whether it is among the
transitions averaged for the tuned trajectory length.

**The driver.** :func:`run_adaptation` runs an adaptation on a sampler built at the current
parameters (``sampler_at(**parameters)``): every chain runs the chain loop of
:func:`liesample.integrators.chain_loop.run_steps` (the key scheme and noise blocks of the
sampling that follows), vmapped over the chains; after each transition the chains' states and
infos are gathered (a collective over the vmapped axis, so the adaptation state is computed
once and shared by every chain) and ``update`` runs on them. It is traceable (one compiled
loop; it can itself be vmapped, over temperatures say). The warm-up of :func:`liesample.sample`
(:mod:`liesample.tuning.warmup`), :func:`liesample.window_adaptation`,
:func:`liesample.magnetic_window_adaptation` all call it; the NumPyro kernel, whose loop NumPyro
drives, calls the same ``current`` and ``update`` once per transition
(:mod:`liesample.interop.numpyro_kernel`).

The pieces adaptations are made of are here too: :func:`pooled_rate` and
:func:`step_size_adaptation` (dual averaging of one step shared by the chains, pooled so that
a stuck chain is freed, or so that a minority cannot move the step), :func:`odd_chains` (the
chains a robust pooled step left behind); the mass and
the trajectory length are in :mod:`liesample.tuning.adaptation` and
:mod:`liesample.tuning.trajectory`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple, cast

import jax
import jax.numpy as jnp
import numpy as np
from blackjax.adaptation.step_size import dual_averaging_adaptation
from blackjax.adaptation.window_adaptation import build_schedule

from liesample.foundation.compile import evaluate
from liesample.integrators.chain_loop import NoiseBlocks, declared_noise_blocks, run_steps
from liesample.samplers.contract import Sampler

__all__ = [
    "CHAINS",
    "ODD_RATE_FRACTION",
    "POOLINGS",
    "RATE_SMOOTHING",
    "STEP_POOLINGS",
    "Adaptation",
    "Row",
    "StepSizeState",
    "carried_sampler",
    "fixed",
    "odd_chains",
    "pooled_rate",
    "run_adaptation",
    "schedule",
    "step_size_adaptation",
]

CHAINS = "chains"
"""The name of the chains' vmapped axis in an adapting program (its collectives gather over it)."""


class Row(NamedTuple):
    """One transition of the warm-up: its index, stage (0: fast window, 1: slow window),
    whether a slow window ends there, whether its trajectory length enters the tuned one, and
    whether it is in the initial fast window (before the first slow window; the first half
    without a slow window)."""

    # Arrays, numpy for the whole schedule and traced for one row. The field ``index`` shadows
    # ``tuple.index``, which a checker reports as an incompatible override.
    index: np.ndarray | jax.Array  # type: ignore[assignment]
    stage: np.ndarray | jax.Array
    window_end: np.ndarray | jax.Array
    average: np.ndarray | jax.Array
    initial: np.ndarray | jax.Array


class Adaptation(NamedTuple):
    """``init``, ``current``, ``update`` (or ``None``), ``final`` (module docstring)."""

    init: Callable
    current: Callable
    update: Callable | None
    final: Callable


def schedule(num_steps: int) -> Row:
    """Stan's windows for ``num_steps`` transitions, one :class:`Row` of numpy arrays
    (``blackjax.adaptation.window_adaptation.build_schedule``; constants, also under ``jit``).
    ``average`` marks the transitions from the start of the last slow window to the end (the
    second half without a slow window)."""
    table = np.asarray(evaluate(build_schedule, int(num_steps)))
    stages = table[:, 0].astype(np.int32)
    ends = table[:, 1].astype(bool)
    slow = np.flatnonzero(stages == 1)
    if not slow.size:
        start = first = num_steps // 2
    else:
        earlier = np.flatnonzero(ends[: slow[-1]])  # window ends before the last window's
        start = int(earlier[-1]) + 1 if earlier.size else 0
        first = int(slow[0])
    index = np.arange(num_steps)
    return Row(index, stages, ends, index >= start, index < first)


def row_at(rows: Row, index) -> Row:
    """Row ``index`` of a :func:`schedule` (``index`` may be traced; clipped to the last)."""
    index = jnp.minimum(index, len(rows.index) - 1)
    return Row(*(jnp.asarray(column)[index] for column in rows))


RATE_SMOOTHING = 0.9
"""Weight of the past in each chain's running rate (about ten transitions)."""


POOLINGS = ("harmonic", "median")
"""The pooled statistics :func:`pooled_rate` offers."""

STEP_POOLINGS = (*POOLINGS, "harmonic_then_median")
"""The poolings of :func:`step_size_adaptation`: ``"harmonic_then_median"`` is the harmonic
rule in the initial fast window (:class:`Row`'s ``initial``) and the median after it."""


def pooled_rate(rates, smoothed, pooling: str = "harmonic"):
    """``(rate, smoothed)``: the rate dual averaging reads from a batch of chains, and their
    updated running rates. The rate is the chains' mean rate times a ratio of two summaries
    of their running rates, near 1 for chains that accept alike (the step then meets the
    target). A non-finite rate counts as 0.

    ``pooling="harmonic"``: the ratio of the harmonic to the arithmetic mean, near 0 while one
    chain stays stuck: the step is lowered until it moves. (The harmonic mean of the
    per-transition rates would also free a stuck chain, but per-transition rates are noisy and
    it ends well above the target.) Right where a chain is stuck only because the step is too
    large for its start; wrong where a chain sits in a region no step of the others' size can
    move in (a degenerate mode of a mixture, the neck of a funnel): there one chain sets the
    step of all of them.

    ``pooling="median"``: the ratio of the median to the arithmetic mean, so that dual
    averaging drives the median running rate to the target. A minority of chains (fewer than
    half) cannot move the median, however low or high their rates, so the step is the one the
    majority needs; the chains left behind are named by :func:`odd_chains`. The mean rate
    still carries each transition's fluctuation, so dual averaging sees the same noise as with
    one chain; a batch of one or two chains gets ``mean(rates)``. (The median of the
    per-transition rates themselves would be robust too, but it is biased: a transition's
    rate is mostly near 0 or 1, and the median of a few such values is not their mean.)"""
    if pooling not in POOLINGS:
        raise ValueError(f"pooling must be one of {POOLINGS}, got {pooling!r}")
    own = jnp.where(jnp.isfinite(rates), rates, 0.0)
    smoothed = RATE_SMOOTHING * smoothed + (1.0 - RATE_SMOOTHING) * own
    if pooling == "harmonic":
        level = 1.0 / jnp.mean(1.0 / jnp.maximum(smoothed, 1e-30))
    else:
        level = jnp.median(smoothed)
    arithmetic = jnp.mean(smoothed)
    ratio = jnp.where(arithmetic > 0, level / jnp.maximum(arithmetic, 1e-30), 1.0)
    return jnp.mean(own) * ratio, smoothed


ODD_RATE_FRACTION = 0.25
"""A chain whose running rate ends below this fraction of the others' median is odd."""


def odd_chains(smoothed, fraction: float = ODD_RATE_FRACTION) -> list[tuple[int, float, float]]:
    """Chains adapted together whose running rate (``smoothed``, one per chain, as
    :func:`pooled_rate` keeps it) is below ``fraction`` of the median of the other chains' (or
    not finite): ``(chain, its rate, the others' median)`` for each. A robust pooled step
    (``pooling="median"``) is the majority's; a chain that cannot move at it sits where the
    others are not (a degenerate mode, a funnel's neck) or is stuck, and its draws are
    suspect. With fewer than three chains none can be told apart from the majority: ``[]``.
    On the host (numpy), after the warm-up."""
    rates = np.asarray(smoothed, dtype=float).ravel()
    if len(rates) < 3:
        return []
    out = []
    for chain, rate in enumerate(rates):
        others = np.delete(rates, chain)
        others = others[np.isfinite(others)]
        median = float(np.median(others)) if others.size else float("nan")
        if np.isfinite(median) and median > 0 and not rate >= fraction * median:
            out.append((chain, float(rate), median))
    return out


class StepSizeState(NamedTuple):
    """Dual averaging's state (``blackjax``'s), the step the next transition uses (the given
    one at first, then ``exp`` of dual averaging's iterate) and each chain's running rate."""

    da: object
    step_size: jax.Array
    smoothed: jax.Array


def step_size_adaptation(target: float, rate_field: str = "acceptance_rate",
                         max_step_size: float | jax.Array = math.inf,
                         pooling: str = "harmonic") -> Adaptation:  # fmt: skip
    """Dual averaging of one step size shared by the chains towards ``target`` of their
    :func:`pooled_rate` of ``info.<rate_field>`` (Hoffman & Gelman 2014, as
    ``blackjax.window_adaptation``; ``blackjax.adaptation.step_size.dual_averaging_adaptation``);
    steps above ``max_step_size`` are not used nor returned. ``init`` reads
    ``parameters["step_size"]``; ``final`` gives ``{"step_size": …}``, dual averaging's
    average. Also the step-size piece of the window adaptations (:meth:`restart` at a window's
    end).

    ``pooling`` (:data:`STEP_POOLINGS`): ``"harmonic"`` (the orbit samplers' warm-up: a chain
    stuck at its start is freed), ``"median"`` (a minority cannot move the step), or
    ``"harmonic_then_median"`` (the window adaptation's: the harmonic rule frees chains stuck
    at their starts in the initial fast window, while every chain is still far from where it
    will sample; after it the median keeps the step of the majority, so that a chain falling
    later into a region no step of the others' size moves in, a degenerate mode or a funnel's
    neck, cannot stop the others; ``update`` then needs the row)."""
    if pooling not in STEP_POOLINGS:
        raise ValueError(f"pooling must be one of {STEP_POOLINGS}, got {pooling!r}")
    da_init, da_update, da_final = dual_averaging_adaptation(target)

    def init(states, parameters):
        step = jnp.asarray(parameters["step_size"])
        num_chains = jax.tree.leaves(states)[0].shape[0]
        return StepSizeState(da_init(step), step, jnp.full(num_chains, target, step.dtype))

    def current(state, row=None):
        return {"step_size": jnp.minimum(state.step_size, max_step_size)}

    def update(state, row, parameters, before, after, infos):
        rates = getattr(infos, rate_field)
        if pooling != "harmonic_then_median":
            rate, smoothed = pooled_rate(rates, state.smoothed, pooling)
        else:
            rate, smoothed = pooled_rate(rates, state.smoothed, "median")
            early, _ = pooled_rate(rates, state.smoothed, "harmonic")
            rate = jnp.where(row.initial, early, rate)
        da = da_update(state.da, rate)
        return StepSizeState(da, jnp.exp(da.log_step_size), smoothed)

    def final(state):
        # before any update dual averaging's average is not yet defined: the current step
        averaged = jnp.where(state.da.step > 1, da_final(state.da), state.step_size)
        return {"step_size": jnp.minimum(averaged, max_step_size)}

    return Adaptation(init, current, update, final)


def restart_step_size(state: StepSizeState, target: float, step_size=None) -> StepSizeState:
    """Dual averaging restarted (at a window's end) from ``step_size``, by default its own
    average."""
    da_init, _, da_final = dual_averaging_adaptation(target)
    start = da_final(state.da) if step_size is None else step_size
    da = da_init(start)
    return state._replace(da=da, step_size=jnp.exp(da.log_step_size))


def fixed(parameters: dict) -> Adaptation:
    """The adaptation that learns nothing: ``parameters`` throughout (a rule computed from the
    starts, e.g. the unadjusted orbit sampler's bias model)."""
    return Adaptation(lambda states, start: None, lambda state, row=None: dict(parameters), None,
                      lambda state: dict(parameters))  # fmt: skip


class _Carry(NamedTuple):
    chain: Any  # this chain's sampler state
    adaptation: Any  # the adaptation state, the same in every chain
    index: jax.Array  # type: ignore[assignment]  # the transition's index (shadows tuple.index)


def _adaptive(adaptation: Adaptation, sampler_at, rows: Row, reference: Sampler):
    """The warm-up as a sampler on :class:`_Carry` (chains vmapped with axis ``"chains"``): the
    sampler at the current parameters, then ``update`` with every chain's states and infos.
    Its info is ``(parameters, info)`` of this chain."""

    def move(advance, carry):
        row = row_at(rows, carry.index)
        parameters = adaptation.current(carry.adaptation, row)
        chain, info = advance(sampler_at(**parameters), carry.chain)
        gather = lambda tree: jax.lax.all_gather(tree, CHAINS)
        update = cast(Callable, adaptation.update)  # an adaptation that learns has one
        state = update(
            carry.adaptation, row, parameters, gather(carry.chain), gather(chain), gather(info)
        )
        return _Carry(chain, state, carry.index + 1), (parameters, info)

    return carried_sampler(reference, move)


def carried_sampler(reference: Sampler, move: Callable) -> Sampler:
    """A sampler on a carry whose ``chain`` is a state of ``reference``: each transition is
    ``move(advance, carry)``, where ``advance(sampler, chain) -> (chain, info)`` steps any
    sampler built like ``reference`` with this transition's key or noise row (the noise blocks
    of ``reference``, drawn for the carry's chain, when it declares them)."""
    blocks = declared_noise_blocks(reference)
    noise_blocks = None
    if blocks is not None:
        noise_blocks = NoiseBlocks(
            blocks.size,
            lambda key, carry: blocks.draw(key, carry.chain),
            lambda row, carry: move(lambda s, chain: s.noise_blocks.step(row, chain), carry),
        )
    return Sampler(
        lambda position, rng_key=None: reference.init(position, rng_key),
        lambda key, carry: move(lambda s, chain: s.step(key, chain), carry),
        noise_blocks=noise_blocks,
    )


def run_adaptation(adaptation: Adaptation, sampler_at: Callable, chain_keys, states,
                   parameters: dict, num_steps: int, record: Callable | None = None):  # fmt: skip
    """Run ``adaptation`` for ``num_steps`` transitions of every chain (module docstring).

    ``sampler_at(**parameters) -> Sampler`` (its arguments may be traced); ``chain_keys``
    ``(chains,)`` and ``states`` (chains first) as for sampling; ``parameters`` the starting
    ones (for ``init``). ``record(parameters, state, info)``, if given, is kept per chain and
    transition (leading axes: chains, transitions). Returns ``(states, tuned parameters,
    records)`` (``records`` ``None`` without ``record``). Traceable: wrap it in
    :func:`liesample.jit`.
    """
    if adaptation.update is None:
        raise ValueError("this adaptation learns nothing from transitions: use its final(init(…))")
    rows = schedule(num_steps)
    start = adaptation.init(states, parameters)
    first = adaptation.current(start, row_at(rows, 0))
    reference = sampler_at(**first)
    warmup = _adaptive(adaptation, sampler_at, rows, reference)
    buffers = None
    if record is not None:
        one = jax.tree.map(lambda leaf: leaf[0], states)
        shapes = jax.eval_shape(
            lambda key, s: record(first, *reference.step(key, s)), chain_keys[0], one
        )
        buffers = jax.tree.map(lambda x: jnp.zeros((num_steps, *x.shape), x.dtype), shapes)

    def keep(step, carry, info, kept):
        if record is None:
            return kept
        values = record(info[0], carry.chain, info[1])
        return jax.tree.map(lambda buffer, value: buffer.at[step].set(value), kept, values)

    def chain(key, state):
        carry = _Carry(state, start, jnp.asarray(0))
        return run_steps(warmup, key, carry, 0, num_steps, keep, buffers)

    end, records = jax.vmap(chain, axis_name=CHAINS)(chain_keys, states)
    tuned = adaptation.final(jax.tree.map(lambda leaf: leaf[0], end.adaptation))
    return end.chain, tuned, records
