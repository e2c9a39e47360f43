"""Symplectic diffusions (paper, ``sec:stoch-ham``): the stochastic midpoint rule is symplectic for
every path, converges at its known strong order, and a non-symplectic baseline fails the check.

``Dφᵀ Ω Dφ − Ω`` is computed from ``jax.jacfwd`` of the one-step map (through the fixed-point
iteration). The midpoint rule solves to ``1e-14`` relative, so its defect is round-off
(~1e-15 on O(1) entries); ``1e-11`` leaves a wide margin and is still six orders below the
Heun baseline's largest defect (``≳ 1e-5`` at these step sizes, ``O(Δ²)`` per step).
"""

import importlib.util
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample.dynamics.symplectic import (
    brownian_increments,
    coarsen_increments,
    stochastic_heun_step,
    stochastic_midpoint_step,
    symplectic_diffusion,
    symplectic_path,
    symplecticity_defect,
)

SYMPLECTIC_ATOL = 1e-11
ROOT = pathlib.Path(__file__).resolve().parents[1]


def coupled_pendula(sigma=0.7):
    """``n = 2``: coupled pendula with non-separable, coupled noise Hamiltonians."""

    def hamiltonians(z):
        q, p = z[:2], z[2:]
        return jnp.stack(
            [
                0.5 * p @ p - jnp.sum(jnp.cos(q)) - 0.4 * jnp.cos(q[0] - q[1]),
                sigma * (jnp.cos(q[0] - q[1]) + 0.3 * q[0] * p[1]),
                sigma * p[0] * p[1],
                sigma * jnp.sin(q[1]) * p[0],
            ]
        )

    return symplectic_diffusion(hamiltonians, 2)


def rotation_invariant(sigma=0.6):
    """``n = 2`` with every ``H_i`` invariant under rotations of the plane: stochastic Noether
    says ``L = q₁p₂ − q₂p₁`` is conserved pathwise, and the midpoint rule keeps quadratic
    invariants exactly."""

    def hamiltonians(z):
        q, p = z[:2], z[2:]
        return jnp.stack(
            [0.5 * p @ p + 0.25 * (q @ q) ** 2, sigma * q @ q, sigma * 0.5 * p @ p, sigma * q @ p]
        )

    return symplectic_diffusion(hamiltonians, 2)


SYSTEMS = {
    "pendulum": liesample.systems.stochastic_pendulum(1.0, 0.8),
    "pendulum p²": liesample.systems.stochastic_pendulum(1.0, 0.8, quadratic_momentum_noise=True),
    "coupled n=2": coupled_pendula(),
}


def random_steps(system, count=5, seed=3, step_size=0.1):
    rng = np.random.default_rng(seed)
    states = rng.normal(size=(count, 2 * system.dimension))
    noise = np.sqrt(step_size) * rng.normal(size=(count, system.num_drivers - 1))
    increments = np.concatenate([np.full((count, 1), step_size), noise], axis=1)
    return jnp.asarray(states), jnp.asarray(increments)


@pytest.mark.parametrize(
    "name",
    [
        # slow: the one-degree-of-freedom pendula repeat the pathwise check; the default suite
        # checks this with the [coupled n=2] case of
        # test_symplectic.py::test_midpoint_step_is_symplectic_pathwise_and_heun_is_not
        pytest.param("pendulum", marks=pytest.mark.slow),
        pytest.param("pendulum p²", marks=pytest.mark.slow),
        "coupled n=2",
    ],
)
def test_midpoint_step_is_symplectic_pathwise_and_heun_is_not(name):
    system = SYSTEMS[name]

    @liesample.jit
    @jax.vmap
    def defects(z, increments):
        midpoint = symplecticity_defect(
            lambda y: stochastic_midpoint_step(system, y, increments)[0], z, system.dimension
        )
        heun = symplecticity_defect(
            lambda y: stochastic_heun_step(system, y, increments), z, system.dimension
        )
        converged = stochastic_midpoint_step(system, z, increments)[1]
        return midpoint, heun, converged

    midpoint, heun, converged = defects(*random_steps(system))
    assert np.all(converged)
    assert np.all(midpoint < SYMPLECTIC_ATOL), midpoint
    # The same check rejects the explicit Heun scheme (its defect is O(Δ²), state-dependent).
    assert np.all(heun > SYMPLECTIC_ATOL) and np.max(heun) > 1e-5, heun


def test_midpoint_keeps_the_noether_momentum_of_a_symmetric_diffusion():
    system = rotation_invariant()
    increments = brownian_increments(jax.random.key(4), 0.02, 500, 3)
    path = liesample.jit(lambda z, inc: symplectic_path(system, z, inc))(
        jnp.array([1.0, -0.3, 0.2, 0.8]), increments
    )
    q, p = np.asarray(path.states[:, :2]), np.asarray(path.states[:, 2:])
    momentum = q[:, 0] * p[:, 1] - q[:, 1] * p[:, 0]
    assert bool(path.converged)
    np.testing.assert_allclose(momentum, momentum[0], atol=1e-12)
    assert np.ptp(np.sum(q**2, axis=1)) > 0.1  # the path does move


def strong_errors(system, scheme, num_paths=128, horizon=1.0, fine=2048, coarse=(8, 16, 32, 64)):
    """RMS end-point error against the midpoint rule on the same path at ``Δt = horizon/fine``."""
    z0 = jnp.array([1.0, 0.5])

    @liesample.jit
    @jax.vmap
    def errors(key):
        increments = brownian_increments(key, horizon / fine, fine, system.num_drivers - 1)
        reference = symplectic_path(system, z0, increments)
        ends = [
            symplectic_path(
                system, z0, coarsen_increments(increments, fine // c), scheme=scheme
            ).states[-1]
            for c in coarse
        ]
        return jnp.stack(ends) - reference.states[-1], reference.converged

    error, converged = errors(jax.random.split(jax.random.key(1), num_paths))
    assert np.all(converged)
    rms = np.sqrt(np.mean(np.sum(np.asarray(error) ** 2, axis=-1), axis=0))
    slope = np.polyfit(np.log(horizon / np.array(coarse)), np.log(rms), 1)[0]
    return rms, slope


@pytest.mark.parametrize(
    ("noise_momentum", "order"),
    [(0.0, 1.0), (1.0, 0.5)],
    ids=["commutative (order 1)", "non-commutative (order 1/2)"],
)
def test_midpoint_strong_order(noise_momentum, order):
    """Mean-square order 1 with commuting noise fields (``σ₂ = 0``: only ``H_1 = σ₁ cos q``) and
    1/2 without (``{H_1, H_2} ≠ 0`` and no Lévy areas). The fitted slope over ``Δt = 1/8 … 1/64``
    (128 paths, fixed key) is within ±0.15 of the order; the two cases differ by 0.5, so the
    bounds separate them."""
    rms, slope = strong_errors(
        liesample.systems.stochastic_pendulum(1.0, noise_momentum), "midpoint"
    )
    assert abs(slope - order) < 0.15, (rms, slope)
    assert rms[-1] < 0.05


def test_symplectic_path_rejects_bad_input():
    system = liesample.systems.stochastic_pendulum()
    with pytest.raises(ValueError, match="scheme"):
        symplectic_path(system, jnp.zeros(2), jnp.zeros((3, 3)), scheme="euler")
    with pytest.raises(ValueError, match=r"initial_state must have shape \(2,\)"):
        symplectic_path(system, jnp.zeros(3), jnp.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"increments must have shape \(num_steps, 3\)"):
        symplectic_path(system, jnp.zeros(2), jnp.zeros((3, 2)))
    with pytest.raises(ValueError, match="multiple of factor"):
        coarsen_increments(jnp.zeros((10, 3)), 3)
    with pytest.raises(ValueError, match="dimension"):
        symplectic_diffusion(lambda z: z, 0)
    with pytest.raises(ValueError, match=r"shape \(m \+ 1,\)"):
        symplectic_diffusion(lambda z: jnp.sum(z), 1)
    with pytest.raises(TypeError, match="hamiltonians"):
        symplectic_diffusion(3.0, 1)
    with pytest.raises(TypeError, match="noise_position"):
        liesample.systems.stochastic_pendulum(noise_position="big")


def test_non_convergence_is_flagged():
    """``H_2 = σ p²/2`` with a huge increment: the fixed-point map expands, the flag says so."""
    system = liesample.systems.stochastic_pendulum(1.0, 1.0, quadratic_momentum_noise=True)
    _, converged = liesample.jit(lambda z, inc: stochastic_midpoint_step(system, z, inc))(
        jnp.array([0.3, 1.0]), jnp.array([0.1, 10.0, 10.0])
    )
    assert not bool(converged)


def test_truncated_increments_are_bounded():
    increments = brownian_increments(jax.random.key(0), 0.01, 10_000, 2, truncate=True)
    assert np.all(increments[:, 0] == 0.01)
    assert np.max(np.abs(increments[:, 1:])) <= np.sqrt(4 * 0.01 * abs(np.log(0.01))) + 1e-15


def test_stochastic_pendulum_example_writes_a_phase_portrait(tmp_path):
    spec = importlib.util.spec_from_file_location(
        "stochastic_pendulum_example", ROOT / "examples" / "stochastic_pendulum.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    output = tmp_path / "pendulum.png"
    summary = module.main(output, num_paths=2, num_steps=100)
    assert output.stat().st_size > 10_000
    assert summary["converged"] and summary["max_symplecticity_defect"] < SYMPLECTIC_ATOL
