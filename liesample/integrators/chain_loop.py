"""Run a sampler over a range of steps, drawing its noise in blocks where the sampler allows it.

**The key scheme.** Step ``s`` of a chain with key ``k`` uses ``step(fold_in(k, s), state)``:
one key derivation and one small draw per step. A sampler that declares
:class:`NoiseBlocks` (its ``noise_blocks`` attribute, :class:`DeclaresNoiseBlocks`: the orbit
samplers) instead gets its noise in
blocks of ``B`` steps: block ``b = s // B`` is drawn at once from ``fold_in(k, b)`` and step ``s``
uses its row ``s % B``. The block structure is fixed by the step index, not by the range being
run, so a run split into any ranges (warm-up, chunks, a resumed run) draws the same noise as the
run in one piece. Only the block size changes the draws; the law of the chain is the same
(each row has the law of one step's draw). One draw per block replaces a key derivation and a
draw per step, which on the rigid body is most of the cost of a step.

:func:`run_steps` is the loop every chain runner uses
(:func:`liesample.integrators.accuracy.ergodic_averages`, the warm-up of
:mod:`liesample.tuning.protocol`, the runner): ``num_steps`` steps from ``first_step``, with
an optional ``update`` of the caller's accumulators after each step; :func:`run_draws` keeps
every ``thinning``-th state and the info reduced over each thinning window (what
:func:`liesample.sample` stores). For the blocked scheme it
is a loop over blocks with an inner loop over the rows of each block (the range's ends may
cut the first and last blocks); both loops' bounds are the same for every chain, so under
``vmap`` they stay loops rather than becoming masked computations.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

__all__ = [
    "DEFAULT_NOISE_BLOCK_SIZE",
    "DeclaresNoiseBlocks",
    "NoiseBlocks",
    "check_block_size",
    "declared_noise_blocks",
    "run_draws",
    "run_steps",
]

DEFAULT_NOISE_BLOCK_SIZE = 32
"""Steps per noise block of the orbit samplers (``noise_block_size``)."""


class NoiseBlocks(NamedTuple):
    """How a sampler's step consumes pre-drawn noise.

    size : steps per block ``B``.
    draw : ``(key, state) -> block``: the noise of ``B`` steps, a pytree whose leaves have
        leading axis ``B`` (``state`` gives the dtype).
    step : ``(row, state) -> (state, info)``: one step from row ``j`` of a block (the block's
        leaves indexed at ``j``); ``sampler.step(key, state)`` is this step with a one-row block
        drawn from ``key``.
    """

    size: int
    draw: Callable
    step: Callable


class DeclaresNoiseBlocks:
    """What a sampler declares to this loop: ``noise_blocks``, a :class:`NoiseBlocks` or
    ``None`` (default: one key per step). :class:`liesample.samplers.contract.Sampler` has it;
    any other algorithm (a plain BlackJAX ``SamplingAlgorithm``) is stepped with per-step keys.
    """

    noise_blocks: NoiseBlocks | None = None


def declared_noise_blocks(algorithm) -> NoiseBlocks | None:
    """The :class:`NoiseBlocks` that ``algorithm`` declares (``None`` for one key per step)."""
    return algorithm.noise_blocks if isinstance(algorithm, DeclaresNoiseBlocks) else None


def check_block_size(value) -> int:
    """``value`` as a block size (an integer ≥ 1), or ``ValueError``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"noise_block_size must be an integer >= 1, got {value!r}")
    return value


def run_steps(algorithm, key, state, first_step, num_steps, update=None, extra=None):
    """Steps ``first_step … first_step + num_steps − 1`` of one chain; returns
    ``(state, extra)``.

    ``algorithm`` has ``step(key, state) -> (state, info)`` and, if it is a
    :class:`DeclaresNoiseBlocks`, ``noise_blocks`` (module docstring for the key scheme).
    ``update(step, state, info, extra) -> extra``, if given, is called after every step with
    the step's index, the new state and its info (what ``update`` does not use is not
    computed: XLA drops it).
    ``first_step`` and ``num_steps`` may be traced (one compilation for every range).
    """

    def advance(step, carry, move):
        state, extra = carry
        state, info = move(state)
        if update is not None:
            extra = update(step, state, info, extra)
        return state, extra

    end = first_step + num_steps
    blocks = declared_noise_blocks(algorithm)
    if blocks is None:

        def one(step, carry):
            return advance(step, carry, lambda s: algorithm.step(jax.random.fold_in(key, step), s))

        return jax.lax.fori_loop(first_step, end, one, (state, extra))

    size = blocks.size

    def one_block(block, carry):
        noise = blocks.draw(jax.random.fold_in(key, block), carry[0])
        start = block * size

        def one(row, carry):
            noise_row = jax.tree.map(lambda leaf: leaf[row], noise)
            return advance(start + row, carry, lambda s: blocks.step(noise_row, s))

        low = jnp.clip(first_step - start, 0, size)
        high = jnp.clip(end - start, 0, size)
        return jax.lax.fori_loop(low, high, one, carry)

    num_blocks_end = (end + size - 1) // size
    return jax.lax.fori_loop(first_step // size, num_blocks_end, one_block, (state, extra))


def run_draws(
    algorithm, key, state, first_step, num_draws: int, thinning: int, reduce, record=None,
    num_steps=None,
):  # fmt: skip
    """``num_draws`` draws ``thinning`` steps apart, from step ``first_step``; returns
    ``(state, (positions, info))``.

    ``positions`` stacks the state's ``position`` (a pytree) after steps ``first_step +
    thinning·(d + 1) − 1``, leading axis ``num_draws``; ``info[name]`` stacks
    ``reduce(name)(window)`` over the ``thinning`` values of the info field in each draw's
    window (leading axis: the steps). The steps are those of :func:`run_steps`, so the draws do
    not depend on how a run is split into calls. ``num_draws`` and ``thinning`` are static.

    ``record``, if given, is a function of the position: ``positions`` then stacks
    ``record(state.position)`` (a pytree), evaluated once per draw, at the last step of its
    window, instead of the position (the runner's ``observables``). The steps do not change.

    ``num_steps`` (may be traced; default ``num_draws · thinning``) is how many steps are run:
    fewer keep the first ``num_steps // thinning`` draws (the rest of the arrays is
    meaningless), more run on past the last draw, keeping nothing of those steps. So one
    compiled program runs a shorter last chunk and a warm-up as well as a chunk.
    """
    _, example = jax.eval_shape(algorithm.step, jax.random.key(0), state)
    fields = example._asdict()
    window = {n: jnp.zeros((thinning, *v.shape), v.dtype) for n, v in fields.items()}
    reduced = jax.eval_shape(lambda w: {n: reduce(n)(w[n]) for n in w}, window)
    infos = {n: jnp.zeros((num_draws, *v.shape), v.dtype) for n, v in reduced.items()}
    recorded = state.position if record is None else jax.eval_shape(record, state.position)
    positions = jax.tree.map(lambda leaf: jnp.zeros((num_draws, *leaf.shape), leaf.dtype), recorded)

    def update(step, state, info, carry):
        window, positions, infos = carry
        offset = step - first_step
        draw, slot = offset // thinning, offset % thinning
        window = {n: window[n].at[slot].set(v) for n, v in info._asdict().items()}
        if record is None:
            # Written at every step of the window; the last step's write is the one kept.
            positions = jax.tree.map(
                lambda out, leaf: out.at[draw].set(leaf, mode="drop"), positions, state.position
            )
        else:  # evaluated at the window's last step of a kept draw only (an unbatched cond)
            positions = jax.lax.cond(
                (slot == thinning - 1) & (draw < num_draws),
                lambda: jax.tree.map(
                    lambda out, leaf: out.at[draw].set(leaf, mode="drop"),
                    positions,
                    record(state.position),
                ),
                lambda: positions,
            )
        if thinning == 1:
            values = {n: reduce(n)(window[n]) for n in window}
        else:  # reduce once per window (the step index is the same for every chain)
            values = jax.lax.cond(
                slot == thinning - 1,
                lambda: {n: reduce(n)(window[n]) for n in window},
                lambda: {n: infos[n][draw] for n in infos},
            )
        infos = {n: infos[n].at[draw].set(values[n], mode="drop") for n in infos}
        return window, positions, infos

    steps = num_draws * thinning if num_steps is None else num_steps
    state, (_, positions, infos) = run_steps(
        algorithm, key, state, first_step, steps, update, (window, positions, infos)
    )
    return state, (positions, infos)
