"""Divergences watched at every step of an HMC trajectory, as NUTS does: a trajectory whose
energy error exceeds the threshold mid-way and comes back is flagged; the Metropolis test stays
the end point's; a trajectory through a non-finite energy is rejected; watching evaluates no
extra gradient; a healthy Gaussian shows none.

The overshooting trajectory is the leapfrog on the standard normal at ``ε = 1.9``, from
``x = 0`` with ``p = 20``: the map rotates the phase by ``θ = arccos(1 − ε²/2) ≈ π − 0.635``
per step on an ellipse squeezed by ``1 − ε²/4``, so ``H`` rises about tenfold near the turning
point (steps 2 and 3) and is nearly back at step 5. The energies of every step are computed
here independently (NumPy leapfrog) and the test first checks that premise.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample import spaces as S
from liesample.samplers.cotangent import _core

LEAPFROG = (("B", 0.5), ("A", 1.0), ("B", 0.5))
STEP, STEPS, P0, THRESHOLD = 1.9, 5, 20.0, 1000.0


def gaussian(x):
    return -0.5 * jnp.sum(x**2)


def numpy_energy_errors(grad, x, p, step, steps):
    """``H(z_k) − H(z_0)`` for ``k = 1..steps`` of the leapfrog on ``H = x²/2 + p²/2``."""
    start, errors = 0.5 * (x * x + p * p), []
    for _ in range(steps):
        p = p + 0.5 * step * grad(x)
        x = x + step * p
        p = p + 0.5 * step * grad(x)
        errors.append(0.5 * (x * x + p * p) - start)
    return np.array(errors), x


def transition(logdensity, position, momentum, step, steps):
    space = S.Euclidean((1,))
    move = _core.make_move(logdensity, space, step, None, None, LEAPFROG)
    state = _core.init(jnp.array([position]), logdensity, space)
    run = jax.jit(
        lambda s: _core.hamiltonian_transition(
            jax.random.key(0), s, jnp.array([momentum]), move, steps, THRESHOLD
        )
    )
    return state, run(state)


def test_a_trajectory_that_overshoots_and_comes_back_is_flagged():
    errors, _ = numpy_energy_errors(lambda x: -x, 0.0, P0, STEP, STEPS)
    assert errors.max() > THRESHOLD > abs(errors[-1])  # the premise: overshoot, then back
    _, (_, outcome) = transition(gaussian, 0.0, P0, STEP, STEPS)
    _, rate, is_divergent, start, final = outcome
    assert bool(is_divergent)
    # the test is still the end point's: rate min(1, e^{-ΔH}) of the last step
    np.testing.assert_allclose(float(final - start), errors[-1], rtol=1e-10)
    np.testing.assert_allclose(float(rate), min(1.0, np.exp(-errors[-1])), rtol=1e-10)


def test_watching_evaluates_no_extra_gradient():
    calls = []

    def counted(x):
        jax.debug.callback(lambda: calls.append(1))
        return gaussian(x)

    space = S.Euclidean((1,))
    state = _core.init(jnp.zeros(1), counted, space)
    move = _core.make_move(counted, space, STEP, None, None, LEAPFROG)
    calls.clear()
    run = jax.jit(
        lambda s: _core.hamiltonian_transition(
            jax.random.key(0), s, jnp.array([P0]), move, STEPS, THRESHOLD
        )
    )
    jax.block_until_ready(run(state))
    assert len(calls) == STEPS == int(_core.trajectory_cost(move, STEPS))


def test_a_trajectory_through_a_non_finite_energy_is_rejected():
    """A band ``1 < x < 1.8`` where ``log π = −∞`` (its gradient, through ``where``, is 0): the
    trajectory from ``x = 0``, ``p = 3`` (step 0.25) lands in it and leaves it, ending finite."""

    def banded(x):
        inside = (x[0] > 1.0) & (x[0] < 1.8)
        return jnp.where(inside, -jnp.inf, gaussian(x))

    def grad(x):
        return 0.0 if 1.0 < x < 1.8 else -x

    steps, x = 12, 0.0
    path = [x]
    p = 3.0
    for _ in range(steps):
        p = p + 0.125 * grad(x)
        x = x + 0.25 * p
        p = p + 0.125 * grad(x)
        path.append(x)
    assert any(1.0 < y < 1.8 for y in path) and not 1.0 < path[-1] < 1.8  # the premise
    state, (new, outcome) = transition(banded, 0.0, 3.0, 0.25, steps)
    is_accepted, rate, is_divergent, _, final = outcome
    assert np.isfinite(float(final)) and bool(is_divergent)
    assert not bool(is_accepted) and float(rate) == 0.0
    np.testing.assert_array_equal(new.position, state.position)


@pytest.mark.parametrize("name", ["geometric_hmc", "magnetic_hmc"])
def test_the_samplers_flag_it(name):
    """Each sampler's own transition: a momentum carried at ``α = 0.9999`` (partial refresh)
    makes the drawn one ``≈ 20``, the overshooting trajectory above."""
    options = {"divergence_threshold": THRESHOLD, "momentum_persistence": 0.9999}
    if name == "geometric_hmc":
        sampler = liesample.geometric_hmc(gaussian, S.Euclidean((1,)), STEP, STEPS, **options)
    else:
        sampler = liesample.magnetic_hmc(
            gaussian, STEP, jnp.ones(1), STEPS, jnp.zeros((1, 1)), **options
        )
    state = sampler.init(jnp.zeros(1))._replace(momentum=jnp.array([P0]))
    _, info = jax.jit(sampler.step)(jax.random.key(1), state)
    assert bool(info.is_divergent) and float(info.acceptance_rate) > 0.1


def test_a_healthy_gaussian_shows_none():
    sampler = liesample.geometric_hmc(gaussian, S.Euclidean((5,)), 0.3, 10, jitter=True)

    def body(state, key):
        state, info = sampler.step(key, state)
        return state, (info.is_divergent, info.acceptance_rate)

    run = jax.jit(
        lambda key: jax.lax.scan(body, sampler.init(jnp.zeros(5)), jax.random.split(key, 2000))
    )
    _, (divergent, rate) = run(jax.random.key(2))
    assert not np.any(np.asarray(divergent))
    assert np.mean(np.asarray(rate)) > 0.9
