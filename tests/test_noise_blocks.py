"""Noise drawn in blocks (liesample.integrators.chain_loop): reproducible, independent of how a run
is split into ranges, the same kernel as the per-step draws, and the exact law.

Block ``b`` of a chain with key ``k`` is ``normal(fold_in(k, b), (B, …))`` and step ``s`` uses
its row ``s % B``; only the block size changes the draws.
"""

from __future__ import annotations

import functools
import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample import accuracy
from liesample.foundation.compile import jit
from liesample.integrators.chain_loop import run_steps
from liesample.samplers.orbit import adjusted_lie_poisson as adjusted_module
from liesample.samplers.orbit import lie_poisson_langevin as unadjusted_module
from liesample.systems import heavy_top, rigid_body
from liesample.targets import RestrictedGaussian
from liesample.tuning.warmup import warm_up

RIGID = rigid_body((1.0, 2.0, 4.0))
START = jnp.array([0.3, -1.2, 0.84])
BETA = 3.0


def _samplers(block_size=8):
    return {
        "adjusted": liesample.adjusted_lie_poisson(
            RIGID, beta=BETA, step_size=0.8, noise_block_size=block_size
        ),
        "unadjusted": liesample.lie_poisson_langevin(
            RIGID, beta=BETA, step_size=0.1, noise_block_size=block_size
        ),
    }


@functools.cache
def _ranges_runner(name, block_size):
    """``run(key, position, bounds) -> position`` after the steps ``bounds[0] … bounds[-1] − 1``
    run as consecutive ranges (one compilation; the bounds are traced)."""
    algorithm = _samplers(block_size)[name]

    @jit
    def run(key, position, bounds):
        state = algorithm.init(position)
        for first, last in itertools.pairwise(bounds):
            state, _ = run_steps(algorithm, key, state, first, last - first)
        return state.position

    return run


@pytest.mark.parametrize("name", ["adjusted", "unadjusted"])
def test_draws_do_not_depend_on_how_the_run_is_split(name):
    key = jax.random.key(11)
    run = _ranges_runner(name, 8)
    runs = [
        np.asarray(run(key, START, jnp.array(bounds)))
        for bounds in ([0, 0, 0, 45], [0, 3, 17, 45], [0, 8, 16, 45], [0, 1, 44, 45])
    ]
    for other in runs[1:]:
        np.testing.assert_array_equal(other, runs[0])
    # Another key: another chain (the block size changing the draws: the next test).
    other_key = run(jax.random.key(12), START, jnp.array([0, 0, 0, 45]))
    assert not np.allclose(np.asarray(other_key), runs[0])


@pytest.mark.parametrize("name", ["adjusted", "unadjusted"])
def test_step_s_uses_row_s_mod_b_of_block_s_div_b(name):
    """The blocked run is the sampler's noise kernel fed with the rows of
    ``normal(fold_in(key, b), (B, …))``, in order: the per-step kernel with other draws."""
    block_size, num_steps = 4, 11
    algorithm = _samplers(block_size)[name]
    if name == "adjusted":
        kernel = adjusted_module.build_noise_kernel(RIGID)
        width, params = RIGID.num_noises + 1, (0.8, 1.0, BETA)
    else:
        kernel = unadjusted_module.build_noise_kernel(RIGID)
        width, params = RIGID.num_noises, (0.1, 1.0, 0.5 * BETA)

    @jit
    def both(key):
        state = algorithm.init(START)
        blocked, _ = run_steps(algorithm, key, state, 0, num_steps)

        def one(step, state):
            block_key = jax.random.fold_in(key, step // block_size)
            rows = jax.random.normal(block_key, (block_size, width), START.dtype)
            return kernel(rows[step % block_size], state, *params)[0]

        return blocked.position, jax.lax.fori_loop(0, num_steps, one, state).position

    blocked, manual = both(jax.random.key(5))
    np.testing.assert_allclose(np.asarray(blocked), np.asarray(manual), rtol=0, atol=1e-13)
    # Another block size: other draws (same key, same law). The block-8 runner of the split
    # test above: the range bounds are traced, so its one compilation serves here too.
    moved = _ranges_runner(name, 2 * block_size)(
        jax.random.key(5), START, jnp.array([0, 0, 0, num_steps])
    )
    assert not np.allclose(np.asarray(moved), np.asarray(blocked))


def test_step_with_a_key_draws_one_row():
    """``step(key, state)`` is the noise kernel with ``normal(key, (m + 1,))`` (adjusted) or
    ``normal(key, (m,))`` (unadjusted): BlackJAX's drivers keep working, with their own keys."""
    key = jax.random.key(3)
    for name, width, kernel, params in (
        ("adjusted", 4, adjusted_module.build_noise_kernel(RIGID), (0.8, 1.0, BETA)),
        ("unadjusted", 3, unadjusted_module.build_noise_kernel(RIGID), (0.1, 1.0, 0.5 * BETA)),
    ):
        algorithm = _samplers()[name]
        state = algorithm.init(START)
        stepped, _ = algorithm.step(key, state)
        fed, _ = kernel(jax.random.normal(key, (width,), START.dtype), state, *params)
        np.testing.assert_array_equal(np.asarray(stepped.position), np.asarray(fed.position))


def test_the_cached_energy_is_h_at_the_state():
    for name, algorithm in _samplers().items():
        step = jit(algorithm.step)
        state = algorithm.init(START)
        for index in range(6):
            state, info = step(jax.random.key(index), state)
            expected = float(RIGID.hamiltonian(state.position))
            assert float(info.energy) == pytest.approx(expected, rel=1e-14), name
            assert float(state.energy) == float(info.energy), name


def test_a_divergent_unadjusted_step_keeps_the_state_and_its_energy():
    kernel = unadjusted_module.build_noise_kernel(RIGID)
    state = unadjusted_module.init(START, RIGID)
    new, info = kernel(jnp.array([jnp.nan, 0.0, 0.0]), state, 0.1, 1.0, 1.5)
    assert bool(info.is_divergent) and float(info.acceptance_rate) == 0.0
    np.testing.assert_array_equal(np.asarray(new.position), np.asarray(START))
    assert float(new.energy) == float(state.energy) == float(info.energy)


def test_noise_free_sampler_has_no_blocks():
    """Without noise nothing is drawn, so there is nothing to block."""
    algorithm = liesample.lie_poisson_langevin(RIGID, sigma=0.0, theta=0.0, step_size=0.1)
    assert algorithm.noise_blocks is None
    state, _ = run_steps(algorithm, jax.random.key(0), algorithm.init(START), 0, 5)
    assert np.all(np.isfinite(np.asarray(state.position)))


@pytest.mark.parametrize("value", [0, -3, 2.5, True, "8", None])
def test_bad_block_size_is_refused(value):
    for make in (liesample.adjusted_lie_poisson, liesample.lie_poisson_langevin):
        with pytest.raises(ValueError, match="noise_block_size must be an integer >= 1"):
            make(RIGID, beta=BETA, step_size=0.1, noise_block_size=value)


def test_block_size_is_recorded_and_kept_by_the_warm_up():
    algorithm = liesample.adjusted_lie_poisson(RIGID, beta=BETA, noise_block_size=5)
    assert algorithm.settings["noise_block_size"] == 5
    starts = jnp.stack([START, -START])
    tuned, states = warm_up(
        algorithm,
        jax.random.key(0),
        jax.random.split(jax.random.key(1), 2),
        jax.vmap(algorithm.init)(starts),
        starts,
        23,
    )
    assert tuned.noise_blocks.size == 5 and tuned.settings["noise_block_size"] == 5
    assert np.all(np.isfinite(np.asarray(states.position)))


# slow: the adjusted rigid body's law again; the default suite checks this with
# test_adjusted.py::test_exact_on_the_rigid_body_where_the_unadjusted_chain_is_biased
@pytest.mark.slow
def test_blocked_adjusted_chains_have_the_exact_moments():
    """The exact law through the blocked driver: E[μ_i²] of the rigid body within 5 MCSE of the
    exact Bingham moments (MCSE from independent chains started at exact draws)."""
    target = RestrictedGaussian(inertia=(1.0, 2.0, 4.0), beta=BETA, radius=1.5)
    starts = target.sample(jax.random.key(20), 128)
    algorithm = liesample.adjusted_lie_poisson(RIGID, beta=BETA, step_size=1.0)
    result = accuracy.ergodic_averages(
        algorithm,
        jax.random.key(21),
        starts,
        lambda mu: mu**2,
        num_steps=1000,
        info_fields=("acceptance_rate",),
    )
    exact = np.diag(np.asarray(target.second_moments()))
    z = (result.estimate - exact) / result.mcse
    assert np.all(np.abs(z) < 5), (result.estimate, exact, z)
    assert 0.3 < float(np.mean(result.info_means["acceptance_rate"])) < 0.95


def test_blocked_heavy_top_runs_and_keeps_its_casimirs():
    """Blocks on a second system with more noise directions (the heavy top's six)."""
    system = heavy_top(inertia=(1.0, 1.5, 2.0), mgl=1.0, chi=(0.0, 0.0, 1.0))
    algorithm = liesample.adjusted_lie_poisson(system, beta=1.0, step_size=0.05, noise_block_size=7)
    start = algorithm.init(jnp.asarray(system.default_position))

    @jit  # the range traced: one compilation for the three ranges
    def steps(state, first_step, num_steps):
        return run_steps(algorithm, jax.random.key(2), state, first_step, num_steps)[0]

    whole = steps(start, 0, 30)
    split = steps(steps(start, 0, 9), 9, 21)
    np.testing.assert_array_equal(np.asarray(whole.position), np.asarray(split.position))
    assert float(system.casimir_error(whole.position, whole.reference_casimirs)) < 1e-12


@pytest.mark.slow  # blocked draws independent of the split run by default
def test_the_runner_draws_the_blocked_chain_whatever_the_chunks():
    """``sample_chains`` with thinning keeps the states of :func:`run_steps` (chain ``c`` with
    key ``split(key)[c]``) at steps ``k(d + 1) − 1``, in any chunking, and reduces the info
    over each window (any / mean)."""
    from liesample.run.runner import sample_chains

    algorithm = _samplers(block_size=8)["adjusted"]
    starts = jnp.stack([START, -START])
    key = jax.random.key(9)
    runs = [
        sample_chains(algorithm, key, starts, 10, thinning=3, chunk_draws=c, progress_bar=False)
        for c in (None, 4)
    ]
    np.testing.assert_array_equal(runs[0].positions, runs[1].positions)
    np.testing.assert_array_equal(runs[0].info["acceptance_rate"], runs[1].info["acceptance_rate"])
    chain_keys = jax.random.split(key, 2)

    @jit
    def direct(keys):
        def chain(k, x):
            def update(step, state, info, carry):
                return carry.at[step].set(info.acceptance_rate)

            state, rates = run_steps(algorithm, k, algorithm.init(x), 0, 30, update, jnp.zeros(30))
            return state.position, rates

        return jax.vmap(chain)(keys, starts)

    final, rates = direct(chain_keys)
    np.testing.assert_allclose(runs[0].positions[:, -1], np.asarray(final), rtol=0, atol=1e-13)
    np.testing.assert_allclose(
        runs[0].info["acceptance_rate"], np.asarray(rates).reshape(2, 10, 3).mean(-1), atol=1e-13
    )
