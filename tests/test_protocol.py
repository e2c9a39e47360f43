"""The one adaptation protocol (``liesample.tuning.protocol``): its instances' ``init``,
``current``, ``update`` and ``final``, and the driver ``run_adaptation`` on a small sampler."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from liesample.foundation.compile import jit
from liesample.samplers.contract import BasicInfo, Sampler
from liesample.tuning.protocol import (
    fixed,
    row_at,
    run_adaptation,
    schedule,
    step_size_adaptation,
)

jax.config.update("jax_enable_x64", True)


def test_step_size_adaptation_starts_at_the_given_step_and_follows_the_rate():
    adaptation = step_size_adaptation(0.8)
    states = jnp.zeros((3, 2))
    state = adaptation.init(states, {"step_size": jnp.asarray(0.3)})
    row = row_at(schedule(50), 0)
    # before any transition both the current and the final step are the given one, exactly
    assert float(adaptation.current(state, row)["step_size"]) == 0.3
    assert float(adaptation.final(state)["step_size"]) == 0.3
    accepting = BasicInfo(jnp.zeros(3, bool), jnp.ones(3), jnp.zeros(3))
    grown = adaptation.update(state, row, {}, states, states, accepting)
    assert float(adaptation.current(grown, row)["step_size"]) > 0.3
    # one stuck chain: the pooled rate is far below the target, the step shrinks
    stuck = accepting._replace(acceptance_rate=jnp.array([1.0, 1.0, 0.0]))
    for _ in range(5):
        state = adaptation.update(state, row, {}, states, states, stuck)
    assert float(adaptation.current(state, row)["step_size"]) < 0.3


def test_fixed_learns_nothing_and_the_driver_refuses_it():
    adaptation = fixed({"step_size": 0.1})
    assert adaptation.update is None
    assert adaptation.final(adaptation.init(None, {})) == {"step_size": 0.1}
    with pytest.raises(ValueError, match="learns nothing"):
        run_adaptation(adaptation, None, None, None, {}, 20)


def _random_walk(step_size):
    """Random-walk Metropolis on N(0, 1) with proposal sd ``step_size``."""

    def step(key, x):
        move, accept = jax.random.split(key)
        proposal = x + step_size * jax.random.normal(move, x.shape, x.dtype)
        rate = jnp.minimum(1.0, jnp.exp(0.5 * (x**2 - proposal**2)))
        taken = jax.random.uniform(accept, (), x.dtype) < rate
        new = jnp.where(taken, proposal, x)
        return new, BasicInfo(jnp.asarray(False), rate, 0.5 * new**2)

    return Sampler(lambda x, key=None: x, step)


def test_run_adaptation_tunes_shared_step_to_the_target_rate():
    """Four chains share one step; over the second half of 400 transitions their mean
    acceptance is within 0.1 of the target (its Monte-Carlo sd here is about 0.02)."""
    adaptation = step_size_adaptation(0.5)
    keys = jax.random.split(jax.random.key(0), 4)
    starts = jnp.array([-1.0, 0.0, 0.5, 2.0])

    @jit
    def run(keys, starts):
        return run_adaptation(adaptation, _random_walk, keys, starts,
                              {"step_size": jnp.asarray(0.1)}, 400,
                              lambda parameters, state, info: info.acceptance_rate)  # fmt: skip

    states, tuned, rates = run(keys, starts)
    assert rates.shape == (4, 400) and states.shape == (4,)
    assert abs(float(np.mean(np.asarray(rates)[:, 200:])) - 0.5) < 0.1
    # RWM on N(0, 1) accepts (2/π) arctan(2/s) on average: one half at s = 2
    assert 1.0 < float(tuned["step_size"]) < 4.0
