"""Dual averaging of one step size shared by all chains, to a target acceptance rate.

The warm-up of a sampler that declares ``tuning.method == "dual_averaging"``
(:class:`liesample.samplers.contract.StepSizeTuning`; :func:`liesample.adjusted_lie_poisson`): every
warm-up step moves each chain with the current step size ``exp(x_t)``, and the chains' mean
acceptance rate, weighted down when one chain's running acceptance falls far below the others'
(:func:`liesample.tuning.adaptation.pooled_rate`: a stuck chain lowers the step until it moves, e.g.
one started at the rigid body's maximum-energy axis), updates ``x_t`` by the dual-averaging scheme
of Hoffman & Gelman (2014), as ``blackjax.window_adaptation`` does
(``blackjax.adaptation.step_size.dual_averaging_adaptation``). The tuned step is the scheme's
average ``exp(x̄)``.

The steps are those of :func:`liesample.integrators.chain_loop.run_steps` (chain ``c`` with key
``key_c``, the sampler's noise blocks), vmapped over the chains; the mean over the chains is a
collective over the vmapped axis, so every chain carries the same dual-averaging state.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from blackjax.adaptation.step_size import dual_averaging_adaptation

from liesample.foundation.compile import jit
from liesample.integrators.chain_loop import NoiseBlocks, declared_noise_blocks, run_steps
from liesample.samplers.contract import Sampler
from liesample.tuning.adaptation import pooled_rate

__all__ = ["DualAveragingResult", "dual_averaging"]

_CHAINS = "chains"


class DualAveragingResult(NamedTuple):
    """What :func:`dual_averaging` returns.

    states : the chains' states after the warm-up.
    step_size : the tuned step (the dual-averaging average).
    mean_acceptance : the chains' pooled acceptance rate
        (:func:`liesample.tuning.adaptation.pooled_rate`), averaged over the second half of
        the steps.
    """

    states: object
    step_size: jax.Array
    mean_acceptance: jax.Array


class _WarmupState(NamedTuple):
    chain: object  # the sampler's state
    adaptation: object  # blackjax's DualAveragingAdaptationState, the same in every chain
    smoothed: jax.Array  # this chain's running acceptance (adaptation.pooled_rate)


def _adaptive(sampler_at, update, max_step_size):
    """The warm-up as a sampler on ``_WarmupState``: one step of the sampler at the current
    step size (at most ``max_step_size``), then the dual-averaging update with the chains'
    pooled acceptance (:func:`liesample.tuning.adaptation.pooled_rate`; the step's info is
    that rate)."""

    def move(advance, state):
        sampler = sampler_at(jnp.minimum(jnp.exp(state.adaptation.log_step_size), max_step_size))
        chain, info = advance(sampler, state.chain)
        rates = jax.lax.all_gather(info.acceptance_rate, _CHAINS)
        rate, smoothed = pooled_rate(rates, jax.lax.all_gather(state.smoothed, _CHAINS))
        smoothed = smoothed[jax.lax.axis_index(_CHAINS)]
        return _WarmupState(chain, update(state.adaptation, rate), smoothed), rate

    reference = sampler_at(jnp.ones(()))
    blocks = declared_noise_blocks(reference)
    noise_blocks = None
    if blocks is not None:
        noise_blocks = NoiseBlocks(
            blocks.size,
            lambda key, state: blocks.draw(key, state.chain),
            lambda row, state: move(lambda s, chain: s.noise_blocks.step(row, chain), state),
        )
    return Sampler(
        lambda position, rng_key=None: reference.init(position, rng_key),
        lambda key, state: move(lambda s, chain: s.step(key, chain), state),
        noise_blocks=noise_blocks,
    )


def dual_averaging(
    sampler_at,
    chain_keys,
    states,
    initial_step_size,
    num_steps: int,
    target_acceptance_rate,
    parameters=None,
    max_step_size=None,
) -> DualAveragingResult:
    """Tune the step size shared by the chains over ``num_steps`` warm-up steps.

    Parameters
    ----------
    sampler_at : callable
        ``(step_size, **parameters) -> Sampler`` (``StepSizeTuning.at``); its arguments are
        traced.
    chain_keys : key array ``(chains,)``
        Chain ``c``'s steps use ``chain_keys[c]`` (the key scheme of
        :mod:`liesample.integrators.chain_loop`), as in the sampling that follows.
    states : the chains' initial states (leading axis: chains).
    initial_step_size : float
        Where the scheme starts.
    num_steps : int
        Warm-up steps (static).
    target_acceptance_rate : float
        The (pooled) acceptance rate aimed at.
    parameters : dict, optional
        The sampler's other parameters (``StepSizeTuning.parameters``), passed to
        ``sampler_at`` as arrays of the positions' dtype.
    max_step_size : float, optional
        The largest step used and returned (``StepSizeTuning.max_step_size``).
    """
    init, update, final = dual_averaging_adaptation(target_acceptance_rate)
    first_kept = num_steps // 2
    cap = math.inf if max_step_size is None else float(max_step_size)

    def accumulate(step, state, rate, total):
        del state
        return total + jnp.where(step >= first_kept, rate, 0.0)

    def chain(key, state, adaptation, parameters):
        warmup = _adaptive(lambda step_size: sampler_at(step_size, **parameters), update, cap)
        zero = jnp.zeros((), adaptation.log_step_size.dtype)
        start = _WarmupState(state, adaptation, zero + target_acceptance_rate)
        end, total = run_steps(warmup, key, start, 0, num_steps, accumulate, zero)
        return end.chain, jnp.minimum(final(end.adaptation), cap), total / (num_steps - first_kept)

    @jit
    def run(chain_keys, states, initial, parameters):
        adaptation = init(initial)
        return jax.vmap(chain, in_axes=(0, 0, None, None), axis_name=_CHAINS)(
            chain_keys, states, adaptation, parameters
        )

    dtype = jax.tree.leaves(states.position)[0].dtype
    parameters = {name: jnp.asarray(value, dtype) for name, value in (parameters or {}).items()}
    states, step_sizes, rates = run(
        chain_keys, states, jnp.asarray(initial_step_size, dtype), parameters
    )
    return DualAveragingResult(states, step_sizes[0], rates[0])
