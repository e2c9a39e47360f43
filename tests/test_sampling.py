"""Statistical tests of the rigid-body sampler against the exact restricted Gaussian on S².

Every test compares with an exact reference (MATH.md §2, §4) using Monte-Carlo standard errors
computed from independent chains (so the SE is honest), with fixed keys.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample.analysis.diagnostics import expectation_table
from liesample.run.runner import sample_chains
from liesample.systems import rigid_body
from liesample.targets import isotropic_autocorrelation

INERTIA = (1.0, 2.0, 4.0)
RADIUS = 1.5


def start_points(num_chains, seed=123):
    x = np.random.default_rng(seed).normal(size=(num_chains, 3))
    return RADIUS * x / np.linalg.norm(x, axis=1, keepdims=True)


BODY = rigid_body(INERTIA)  # one system: samplers on it share compiled programs (structure)
# Keys per chain drawn by the shared program (at least): 10 + 200 time units at dt = 0.1. With
# JAX's partitionable threefry, ``split(key, n)[i]`` does not depend on ``n``, so each run uses
# the same keys as ``split(key, num_warmup + num_steps)`` would give it.
KEYS_PER_CHAIN = 2100


@functools.partial(liesample.jit, static_argnames=("build", "num_keys"))
def _time_averages(keys, positions, values, num_warmup, num_steps, *, build, num_keys):
    """Per-chain time averages of μ² after ``num_warmup`` steps (both traced): one compiled
    program per sampler structure (the integrator), for every step size and run length."""
    algorithm = build(**values)

    def chain(key, position):
        step_keys = jax.random.split(key, num_keys)

        def step(k, carry):
            state, total = carry
            state, _ = algorithm.step(step_keys[k], state)
            return state, total + state.position**2

        state = algorithm.init(position)
        state, _ = jax.lax.fori_loop(0, num_warmup, step, (state, jnp.zeros(3)))
        _, total = jax.lax.fori_loop(
            num_warmup, num_warmup + num_steps, step, (state, jnp.zeros(3))
        )
        return total / num_steps

    return jax.vmap(chain)(keys, positions)


def ergodic_second_moments(integrator, beta, step_size, num_chains, total_time, seed):
    """Per-chain time averages of μ_i² (after 10 time units of warm-up), accumulated on the fly.

    Returns an array (chains, 3); the chains are independent, so the spread across them gives an
    honest standard error of the mean. Chain ``c`` uses ``split(key(seed), chains)[c]``, step
    ``s`` (warm-up included) ``split(key_c, num_warmup + num_steps)[s]``.
    """
    algorithm = liesample.lie_poisson_langevin(
        BODY, beta=beta, sigma=1.0, step_size=step_size, integrator=integrator
    )
    num_warmup = round(10.0 / step_size)
    num_steps = round(total_time / step_size)
    build, values = algorithm.structure
    keys = jax.random.split(jax.random.key(seed), num_chains)
    return np.asarray(
        _time_averages(
            keys,
            jnp.asarray(start_points(num_chains)),
            {name: jnp.asarray(value) for name, value in values.items()},
            num_warmup,
            num_steps,
            build=build,
            num_keys=max(KEYS_PER_CHAIN, num_warmup + num_steps),
        )
    )


def exact_second_moments(beta):
    return np.diag(np.asarray(rigid_body(INERTIA).reference(beta, [RADIUS, 0, 0]).second_moments()))


# Long statistical runs: make test-slow. The default suite checks the rigid body's exact law on
# the default path by tests/test_negative_temperature.py::test_unadjusted_rigid_body_at_negative_
# beta_by_the_default_path and tests/stability/test_stability.py's hard cases.
@pytest.mark.slow
@pytest.mark.parametrize("beta", [3.0, -2.0])
def test_second_moments_match_exact_law(beta):
    """E[μ_iμ_j] from several chains matches the exact moments (anisotropic body, β of both
    signs). At dt = 0.05 the splitting's bias (~5e-4, benchmarks/RESULTS.md) is far below the
    MCSE (~4e-3), so a z-test at |z| < 3.5 (Bonferroni over 6 moments, p ≈ 0.003) applies."""
    algorithm = liesample.lie_poisson_langevin(
        rigid_body(INERTIA), beta=beta, sigma=1.0, step_size=0.05
    )
    result = sample_chains(
        algorithm,
        jax.random.key(7),
        start_points(8),
        num_draws=3000,
        num_warmup=200,
        thinning=10,
        progress_bar=False,
    )
    mu = result.positions
    exact = rigid_body(INERTIA).reference(beta, [RADIUS, 0, 0]).second_moments()
    draws, exact_values = {}, {}
    for i in range(3):
        for j in range(i, 3):
            draws[f"{i}{j}"] = mu[..., i] * mu[..., j]
            exact_values[f"{i}{j}"] = float(exact[i, j])
    table = expectation_table(draws, exact_values)
    assert np.all(np.abs(table["z"]) < 3.5), table
    assert np.all(table["r_hat"] < 1.01), table
    # The test has power: the uniform law's moments (r²/3 each) are rejected.
    assert np.any(np.abs((table["estimate"] - RADIUS**2 / 3) / table["mcse"]) > 10)


@pytest.mark.slow  # three long ensembles; default sibling: test_lie_euler_bias_is_first_order
def test_second_order_integrator_beats_first_order_ones():
    """At dt = 0.2 the Lie–Euler and joint-Heun biases are resolved (≫ SE) and several times
    the splitting's, whose bias at this step is ~5e-3 (benchmarks/RESULTS.md)."""
    exact = exact_second_moments(3.0)
    worst = {}
    for integrator in ("splitting", "lie_euler", "rkmk_heun"):
        m = ergodic_second_moments(integrator, 3.0, 0.2, num_chains=256, total_time=200.0, seed=1)
        bias = m.mean(0) - exact
        se = m.std(0, ddof=1) / np.sqrt(len(m))
        worst[integrator] = (np.max(np.abs(bias)), se[np.argmax(np.abs(bias))])
    assert worst["lie_euler"][0] > 10 * worst["lie_euler"][1]
    assert worst["lie_euler"][0] > 4 * worst["splitting"][0]
    assert worst["rkmk_heun"][0] > worst["splitting"][0]


def test_lie_euler_bias_is_first_order():
    """Halving dt halves Lie–Euler's bias in E[μ₁²] (ratio in [1.5, 2.6]: order 1 ± MC error)."""
    exact = exact_second_moments(3.0)
    biases = []
    for dt in (0.2, 0.1):
        m = ergodic_second_moments("lie_euler", 3.0, dt, num_chains=256, total_time=200.0, seed=2)
        biases.append(m.mean(0)[0] - exact[0])
    assert 1.5 < biases[0] / biases[1] < 2.6, biases


@pytest.mark.slow
def test_splitting_bias_is_second_order():
    """Halving dt from 0.1 to 0.05 divides the splitting's bias by ≈4, not 2.

    Observable f = μ₃² − μ₁² (its bias is the largest). With b₁ = bias(0.1), b₂ = bias(0.05) and
    s the combined SE: b₂ is consistent with b₁/4 (|b₂ − b₁/4| < 3s) and inconsistent with
    b₁/2 (|b₂ − b₁/2| > 3s); the run length makes s ≈ b₁/25 so the test has power (about 12
    minutes on 2 cores).
    """
    moments = exact_second_moments(3.0)
    exact = moments[2] - moments[0]
    estimates = []
    for dt in (0.1, 0.05):
        m = ergodic_second_moments(
            "splitting", 3.0, dt, num_chains=16384, total_time=1400.0, seed=3
        )
        f = m[:, 2] - m[:, 0]
        estimates.append((f.mean() - exact, f.std(ddof=1) / np.sqrt(len(f))))
    (b1, s1), (b2, s2) = estimates
    assert abs(b1) > 6 * s1, estimates
    s = np.hypot(s2, s1 / 4)
    assert abs(b2 - b1 / 4) < 3 * s, estimates
    assert abs(b2 - b1 / 2) > 3 * np.hypot(s2, s1 / 2), estimates


@pytest.mark.slow  # a long statistical run; the dynamics' path by the default tests of
# tests/test_zeitlin.py::test_su2_is_the_isotropic_rigid_body_pathwise
def test_isotropic_autocorrelation_matches_exact():
    """Isotropic inertia: Brownian motion on the sphere, E[μ(t)·μ(0)] = r² e^{−σ²t} (MATH.md §2).

    Stationary start (uniform law = the Gibbs law here); the per-lag SE comes from independent
    chains; |z| < 4 at every tested lag (5 lags)."""
    sigma, dt = 0.8, 0.05
    algorithm = liesample.lie_poisson_langevin(
        rigid_body((2.0, 2.0, 2.0)), beta=3.0, sigma=sigma, step_size=dt
    )
    lags = np.array([5, 10, 20, 40, 60])  # t = 0.25 … 3

    def chain(key, position):
        state = algorithm.init(position)

        def step(state, k):
            state, _ = algorithm.step(k, state)
            return state, state.position

        _, path = jax.lax.scan(step, state, jax.random.split(key, lags[-1]))
        return jnp.stack([jnp.dot(path[lag - 1], position) for lag in lags])

    num_chains = 20000
    keys = jax.random.split(jax.random.key(11), num_chains)
    products = np.asarray(
        liesample.jit(jax.vmap(chain))(keys, jnp.asarray(start_points(num_chains)))
    )
    estimate = products.mean(0)
    se = products.std(0, ddof=1) / np.sqrt(num_chains)
    exact = np.asarray(isotropic_autocorrelation(lags * dt, RADIUS, sigma))
    z = (estimate - exact) / se
    assert np.all(np.abs(z) < 4), (estimate, exact, z)
    # Power: a 20 % error in the decay rate would be detected at the middle lag.
    wrong = RADIUS**2 * np.exp(-1.2 * sigma**2 * lags[2] * dt)
    assert abs(estimate[2] - wrong) > 4 * se[2]
