"""Hard cases stay numerically stable, on the orbit, and Gibbs-exact — or are refused.

The stability bound (``liesample.integrators.stability``)
----------------------------------------------
The stiff part of the Poisson–Langevin SDE is the derived dissipation. Along noise direction
``i`` it relaxes at the rate ``θ h''_i``, ``h''_i`` the curvature of ``h`` along the noise flow,
so a step is characterised by the dimensionless number

    κ = step_size · θ · max_i |h''_i|      (max over the orbit),     θ = βσ²/2.

For the rigid body ``max_i |h''_i| = r² (1/I_min − 1/I_max)``. Explicit Euler and Heun on
``y' = −λy`` are stable iff ``λ dt ≤ 2``; measured here (``test_dissipative_flow_bound``):
``splitting``, ``rkmk_heun`` and ``lie_euler`` all converge to the energy minimum at
``κ = 1.95`` and all settle on a spurious 2-cycle at ``κ = 2.05``, for ``I = (1, 2, 4)`` and for
the stiff ``I = (0.01, 1, 100)`` (ratio 1:10⁴), with or without the Hamiltonian drift. So the
bound is **κ ≤ 2** for every orbit-preserving integrator; the sampler estimates κ on the orbit
of the initial state and refuses (default, ``stability="raise"``) or warns (``"warn"``) beyond it.
On the compact rigid-body orbit an unstable step stays finite but samples a wrong law; on the heavy
top's non-compact orbit ``Π`` overflows and the sampler flags every such step ``is_divergent``,
keeps the previous state, and the runner reports it (``test_overflow_is_flagged_and_reported``).
For the heavy top the estimate (curvature at orbit points with ``|Π| ≲ 2|Γ|``) is conservative
at low temperature: measured at β = 10, mgl = 1, ``Π`` stays thermal up to ~3× the estimated
step and grows without bound from ~4×.

The hard cases
--------------
Each runs stationary chains (started at exact i.i.d. draws from ``liesample.targets``), at
``κ = 0.5`` (a quarter of the bound), and checks: every state finite, the orbit kept, and the
Gibbs moments within 5 Monte-Carlo standard errors (MCSE from the spread of the independent
chains' means) of the exact values:

- low temperature β = 10³ (σ = 1, θ = 500: stiff dissipation);
- stiff inertia ``I = (0.01, 1, 100)`` (1:10⁴);
- large noise σ = 10;
- heavy top with large ``mgl = 30``;

in float64 and float32. Orbit tolerance: relative Casimir drift ``≤ 1e-12`` in float64 and
``≤ 10 √n ε₃₂`` after ``n`` steps in float32 (``ε₃₂ = 2⁻²³``): the round-off of each step's
rotation is a random walk; measured ``~7e-5`` after 10⁵ steps (tolerance 1.9e-4), and the
float32 drift is asserted over 10⁵ steps below. No retraction is needed at that level; a run of
10⁹ float32 steps would drift ~1e-3.

A miscompile found by this suite: XLA:CPU's ``small-while-loop-hoisting`` pass (jaxlib 0.12, and
0.11 with a raised threshold) made ``jit(vmap(loop))`` of the samplers' steps give each chain a
different result from the single-chain step (4e-3 after one rigid-body step at β = 30; 0.09 after
20 heavy-top steps), and stationary chains missed the Gibbs law (E[μ₁²] +22 % at β = 10³).
liesample compiles every loop with that pass disabled (``liesample.jit``,
``tests/test_compile.py``); ``test_batched_step_equals_one_chain`` guards every integrator and
system through that path.

The 10⁷-step runs (``lax.fori_loop``, nothing stored, moments accumulated on the fly) are
``@pytest.mark.slow`` (``make test-slow``).
"""

import functools
import math
import warnings

import cases
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample.dynamics import PoissonLangevin, Scene
from liesample.integrators import DEFAULT_INTEGRATOR, INTEGRATORS
from liesample.integrators.stability import STABILITY_LIMITS, stiffness
from liesample.run.runner import NonFiniteStateError
from liesample.targets import HeavyTopGibbs, RestrictedGaussian

GEOMETRIC = ("splitting", "rkmk_heun", "lie_euler")
EPS32 = float(np.finfo(np.float32).eps)


def float32_orbit_tolerance(num_steps):
    """Relative Casimir drift allowed after ``num_steps`` float32 steps: ``10 √n ε₃₂``."""
    return 10.0 * math.sqrt(num_steps) * EPS32


# --------------------------------------------------------------------------- the bound


def _rigid_stiffness(inertia, radius):
    return radius**2 * (1.0 / min(inertia) - 1.0 / max(inertia))


@pytest.mark.parametrize("inertia", [(1.0, 2.0, 4.0), (0.01, 1.0, 100.0)])
@pytest.mark.parametrize("integrator", GEOMETRIC)
def test_dissipative_flow_bound(integrator, inertia):
    """The noise-free dissipative flow from near the minimum converges for κ = 1.95 and does not
    for κ = 2.05 (linear stability of Euler/Heun: ``λ dt ≤ 2``)."""
    system = liesample.systems.rigid_body(inertia)
    step = INTEGRATORS[integrator]
    # Small enough that the Hamiltonian precession about the stable axis,
    # ω = r √((1/I₁ − 1/I₃)(1/I₂ − 1/I₃)) (10 for the stiff inertia), is resolved: ω dt ≤ 0.1.
    dt = 0.01
    start = jnp.array([0.05, 0.05, 1.0]) / jnp.linalg.norm(jnp.array([0.05, 0.05, 1.0]))

    @liesample.jit
    def distance_from_minimum(kappa, hamiltonian_flag):
        theta = kappa / (dt * _rigid_stiffness(inertia, 1.0))

        def run(scene):
            dynamics = PoissonLangevin(system, sigma=0.0, theta=theta, scene=scene)
            return jax.lax.fori_loop(0, 3000, lambda _, m: step(dynamics, m, dt, None), start)

        with_h = run(Scene(hamiltonian=True, dissipation=True, noise=False))
        without_h = run(Scene(hamiltonian=False, dissipation=True, noise=False))
        mu = jnp.where(hamiltonian_flag, with_h, without_h)
        return jnp.abs(jnp.abs(mu[2]) - 1.0), jnp.abs(jnp.sum(mu * mu) - 1.0)

    for flag in (True, False):
        stable, drift = distance_from_minimum(1.95, flag)
        assert stable < 1e-10 and drift < 1e-12
        unstable, drift = distance_from_minimum(2.05, flag)
        assert unstable > 1e-3 and drift < 1e-12
    assert STABILITY_LIMITS[integrator] == 2.0


@pytest.mark.parametrize(
    ("inertia", "radius"),
    [((1.0, 2.0, 4.0), 1.0), ((1.0, 2.0, 4.0), 1.5), ((0.01, 1.0, 100.0), 1.0)],
)
def test_estimated_stiffness_matches_the_rigid_body_closed_form(inertia, radius):
    """The sampler's estimate of ``max_i |h''_i|`` on the orbit is within 3 % below the exact
    ``r²(1/I_min − 1/I_max)``; isotropic inertia has none."""
    system = liesample.systems.rigid_body(inertia)
    position = radius * np.array([0.3, 0.4, math.sqrt(0.75)])
    exact = _rigid_stiffness(inertia, radius)
    estimate = stiffness(system, 1.0, position)
    assert 0.97 * exact <= estimate <= exact * (1 + 1e-9)
    assert stiffness(liesample.systems.rigid_body((2.0, 2.0, 2.0)), 1.0, position) < 1e-12


def test_heavy_top_stiffness_covers_the_translation_noise():
    """The Γ-translations shift Π by ``φ Γ×e_j``: ``h'' = (Γ×e_j)·I⁻¹(Γ×e_j)``, whose largest
    value on the orbit is ``|Γ|²/I_min``; the estimate is at least that."""
    system = liesample.systems.heavy_top((1.0, 2.0, 4.0), mgl=1.0)
    position = np.array([0.1, 0.2, -0.1, 0.0, 0.6, -0.8])
    assert stiffness(system, 1.0, position) >= 1.0 / 1.0


def test_sampler_refuses_or_warns_beyond_the_bound():
    system = liesample.systems.rigid_body((1.0, 2.0, 4.0))
    position = np.array([0.0, 0.0, 1.0])
    beta = 1e3  # θ = 500, so the bound is step_size ≲ 2/(500·0.75) = 5.3e-3
    exact_bound = 2.0 / (0.5 * beta * _rigid_stiffness((1.0, 2.0, 4.0), 1.0))
    refusing = liesample.lie_poisson_langevin(system, beta=beta, step_size=0.01, stability="raise")
    with pytest.raises(ValueError, match=r"stable bound.*κ = .* > 2.*step_size must be <=") as e:
        refusing.init(position)
    named = float(str(e.value).split("step_size must be <= ")[1].split(";")[0])
    assert 0.999 * exact_bound <= named <= 1.03 * exact_bound
    # The runner passes the refusal on, naming the chain.
    with pytest.raises(ValueError, match=r"initial_positions\[0\].*stable bound"):
        liesample.sample_chains(refusing, jax.random.key(0), position[None], 2, progress_bar=False)
    # Refusing is the default; warning is an explicit choice.
    with pytest.raises(ValueError, match="stable bound"):
        liesample.lie_poisson_langevin(system, beta=beta, step_size=0.01).init(position)
    with pytest.warns(UserWarning, match="stable bound"):
        liesample.lie_poisson_langevin(system, beta=beta, step_size=0.01, stability="warn").init(
            position
        )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        liesample.lie_poisson_langevin(system, beta=beta, step_size=0.01, stability="off").init(
            position
        )
        # Well below the bound: silent, in every mode (at half the bound, κ = 1, the step is
        # stable but the linear model's sd error, 18 %, warns:
        # liesample.integrators.accuracy.linear_sd_bias).
        liesample.lie_poisson_langevin(
            system, beta=beta, step_size=0.25 * exact_bound, stability="raise"
        ).init(position)
    with pytest.raises(ValueError, match="stability must be one of"):
        liesample.lie_poisson_langevin(system, beta=1.0, step_size=0.1, stability="ignore")


def test_overflow_is_flagged_and_reported():
    """Far beyond the bound on the heavy top's non-compact orbit, ``Π`` overflows: each such
    step is flagged ``is_divergent`` and rejected (the state stays finite), and the runner warns or
    raises. Never a silent NaN chain."""
    system = liesample.systems.heavy_top(mgl=1.0)
    algorithm = liesample.lie_poisson_langevin(
        system, beta=10.0, step_size=5.0, stability="off", integrator="lie_euler"
    )
    starts = np.tile(system.default_position, (2, 1))
    with pytest.warns(RuntimeWarning, match="non-finite state"):
        result = liesample.sample_chains(algorithm, jax.random.key(1), starts, 30, thinning=10)
    assert np.all(np.isfinite(result.positions))
    # A chain overflows (which and when, along these chaotic paths, depends on the last bit of
    # round-off, hence on the CPU and the compiler).
    assert np.any(result.info["is_divergent"])
    with pytest.raises(NonFiniteStateError, match="Reduce step_size"):
        liesample.sample_chains(
            algorithm, jax.random.key(1), starts, 30, thinning=10, on_nonfinite="raise"
        )


# --------------------------------------------------------------------------- hard cases


# One rigid body per inertia for the float64 runs: the cases on it (low temperature, large
# sigma) then share its stiffness cache and, through the sampler's structure, one compiled run.
_shared_rigid_body = functools.cache(liesample.systems.rigid_body)


def _squares(mu):
    return mu * mu


def _top_observables(mu):
    return jnp.concatenate([mu[5:6], mu[:3] * mu[:3]])


def _rigid(inertia, beta, sigma, radius, shared=True):
    system = (_shared_rigid_body if shared else liesample.systems.rigid_body)(inertia)
    target = RestrictedGaussian(inertia=inertia, beta=beta, radius=radius)
    exact = np.diag(np.asarray(target.second_moments()))
    return system, target, exact, _squares, beta, sigma


def _heavy_top(mgl, beta, sigma, shared=True):
    del shared  # one case on this system: nothing to share
    system = liesample.systems.heavy_top((1.0, 2.0, 4.0), mgl=mgl)
    position = system.default_position
    target = HeavyTopGibbs(
        inertia=(1.0, 2.0, 4.0), mgl=mgl, chi=(0.0, 0.0, 1.0), beta=beta, radius=1.0, c=0.0
    )
    exact = np.concatenate([[target.mean_gamma_chi()], target.pi_second_moments()])
    del position
    return system, target, exact, _top_observables, beta, sigma


CASES = {
    "low temperature beta=1e3": lambda **k: _rigid((1.0, 2.0, 4.0), 1e3, 1.0, 1.0, **k),
    "stiff inertia 1:1e4": lambda **k: _rigid((0.01, 1.0, 100.0), 2.0, 1.0, 1.0, **k),
    "large sigma=10": lambda **k: _rigid((1.0, 2.0, 4.0), 1.0, 10.0, 1.5, **k),
    "heavy top mgl=30": lambda **k: _heavy_top(30.0, 1.0, 1.0, **k),
}
KAPPA = 0.1
NUM_CHAINS = 96
NUM_STEPS = 2000


def stationary_run(algorithm, starts, num_steps, observables, key, num_batches=1):
    """Per-chain means of ``observables`` over ``num_steps`` steps (nothing stored; with
    ``num_batches > 1``, means over consecutive batches, shape ``(chains, batches, k)``), the
    largest Casimir drift, whether any step was non-finite, and the final states.

    Compiled as the runner compiles a sampler: its structure's ``build`` static, its values
    (β, σ, step) traced, so samplers on one system share the program."""
    states = jax.vmap(algorithm.init)(starts)
    keys = jax.random.split(key, starts.shape[0])
    build, values = algorithm.structure
    values = {name: jnp.asarray(value, starts.dtype) for name, value in values.items()}
    return _stationary_run(
        states,
        keys,
        values,
        build=build,
        observables=observables,
        num_steps=num_steps,
        num_batches=num_batches,
    )


@functools.partial(
    liesample.jit, static_argnames=("build", "observables", "num_steps", "num_batches")
)
def _stationary_run(states, keys, values, *, build, observables, num_steps, num_batches):
    algorithm = build(**values)
    batch_steps = num_steps // num_batches

    def chain(state, chain_key):
        def body(step, carry):
            state, total, drift, bad = carry
            state, info = algorithm.step(jax.random.fold_in(chain_key, step), state)
            return (
                state,
                total + observables(state.position),
                jnp.maximum(drift, info.casimir_error),
                bad | info.is_divergent,
            )

        def batch(carry, index):
            state, drift, bad = carry
            zero = jnp.zeros_like(observables(state.position))
            first = index * batch_steps
            state, total, drift, bad = jax.lax.fori_loop(
                first, first + batch_steps, body, (state, zero, drift, bad)
            )
            return (state, drift, bad), total / batch_steps

        init = (state, jnp.zeros((), state.position.dtype), jnp.zeros((), bool))
        (state, drift, bad), means = jax.lax.scan(batch, init, jnp.arange(num_batches))
        return (means[0] if num_batches == 1 else means), drift, bad, state.position

    return jax.vmap(chain)(states, keys)


# slow: the low-temperature and stiff-inertia float32 runs repeat their hard case; the default
# suite checks this with test_hard_case_is_stable_and_gibbs_exact[<case>-float64] (float32:
# test_float32_orbit_drift_over_1e5_steps)
SLOW_HARD_CASES = {
    ("large sigma=10", "float32"),
    ("heavy top mgl=30", "float32"),
    ("low temperature beta=1e3", "float32"),
    ("stiff inertia 1:1e4", "float32"),
}
HARD_CASES = [
    pytest.param(case, dtype, marks=pytest.mark.slow)
    if (case, dtype) in SLOW_HARD_CASES
    else pytest.param(case, dtype)
    for case in CASES
    for dtype in ("float64", "float32")
]


@pytest.mark.parametrize(("case", "dtype"), HARD_CASES)
def test_hard_case_is_stable_and_gibbs_exact(case, dtype):
    system, target, exact, observables, beta, sigma = CASES[case]()
    theta = 0.5 * beta * sigma**2
    starts64 = np.asarray(target.sample(jax.random.key(7), NUM_CHAINS), dtype=float)
    step_size = KAPPA / stiffness(system, theta, starts64[0])
    # A fresh system for a float32 run: functions JAX traced in float64 (the stiffness above)
    # are not reused inside the float32 context. A float64 run reuses the system.
    run_system = system if dtype == "float64" else CASES[case](shared=False)[0]
    with jax.enable_x64(dtype == "float64"):
        algorithm = liesample.lie_poisson_langevin(
            run_system, beta=beta, sigma=sigma, step_size=step_size, stability="raise"
        )
        starts = jnp.asarray(starts64, dtype=dtype)
        means, drift, bad, final = stationary_run(
            algorithm, starts, NUM_STEPS, observables, jax.random.key(11)
        )
        assert means.dtype == np.dtype(dtype)
    means, drift, final = (np.asarray(x, dtype=float) for x in (means, drift, final))
    assert not np.any(bad) and np.all(np.isfinite(final))
    tolerance = 1e-12 if dtype == "float64" else float32_orbit_tolerance(NUM_STEPS)
    assert np.max(drift) <= tolerance
    estimate = means.mean(axis=0)
    mcse = means.std(axis=0, ddof=1) / math.sqrt(NUM_CHAINS)
    z = np.abs(estimate - exact) / mcse
    assert np.all(z < 5.0), f"{case} {dtype}: estimate {estimate}, exact {exact}, z {z}"


# Costly to compile, and checked by default through their own vmapped statistical tests.
_SLOW_BATCHED_SYSTEMS = ("zeitlin_euler", "point_vortices")


def _batched_cases():
    """By default the default integrator on every system but the two in
    ``_SLOW_BATCHED_SYSTEMS``, and every integrator on the heavy top (the configuration that
    once miscompiled, module notes); the rest in ``make test-slow``. ``tests/test_registry.py``
    guards the runner's compile path for every sampler."""
    for integrator in sorted(INTEGRATORS):
        for system_name in cases.SYSTEM_NAMES:
            default = integrator == DEFAULT_INTEGRATOR and system_name not in _SLOW_BATCHED_SYSTEMS
            quick = default or system_name == "heavy_top"
            yield pytest.param(
                integrator,
                system_name,
                id=f"{integrator}-{system_name}",
                marks=() if quick else pytest.mark.slow,
            )


@pytest.mark.parametrize(("integrator", "system_name"), list(_batched_cases()))
def test_batched_step_equals_one_chain(integrator, system_name):
    """Twenty steps vmapped over 8 chains give each chain exactly the single-chain steps
    (round-off), for every integrator and every system of ``tests/cases.py``: the runner and
    every statistical test rely on it. This caught a miscompile of XLA:CPU (module notes; the
    heavy-top row is the configuration it hit); it runs through ``liesample.jit``, the compile
    path of the runner, the accuracy knob and ``simulate``. ``tests/test_registry.py`` guards
    every sampler the same way."""
    case = next(case for case in cases.SYSTEMS if case.name == system_name)
    algorithm = cases.system_sampler(case, integrator)
    starts = jnp.asarray(case.starts())
    positions = starts[np.arange(8) % cases.NUM_CHAINS]  # chain c starts at starts[c % 2]
    keys = jax.random.split(jax.random.key(0), 8)

    def twenty_steps(key, state):
        def one(state, k):
            return algorithm.step(jax.random.fold_in(key, k), state)[0], None

        return jax.lax.scan(one, state, jnp.arange(20))[0].position

    states = jax.vmap(algorithm.init)(positions)
    batched = liesample.jit(jax.vmap(twenty_steps))(keys, states)
    # jit alone compiles correctly (checked against eager).
    single_chain = liesample.jit(twenty_steps)
    for chain in (0, 5):
        single = single_chain(keys[chain], algorithm.init(positions[chain]))
        np.testing.assert_allclose(batched[chain], single, rtol=0, atol=1e-12)


def test_float32_orbit_drift_over_1e5_steps():
    """float32: the relative drift of |μ|² stays below ``10 √n ε₃₂`` over 10⁵ steps."""
    num_steps = 100_000
    system = liesample.systems.rigid_body((1.0, 2.0, 4.0))
    with jax.enable_x64(False):
        algorithm = liesample.lie_poisson_langevin(system, beta=3.0, step_size=0.05)
        starts = jnp.tile(jnp.array([0.9, 1.2, 0.0], jnp.float32), (4, 1))
        _, drift, bad, final = stationary_run(
            algorithm, starts, num_steps, lambda mu: mu, jax.random.key(3)
        )
        assert final.dtype == jnp.float32
    assert not np.any(bad)
    radii = np.sum(np.asarray(final, float) ** 2, axis=-1) / 2.25
    assert np.max(np.abs(radii - 1.0)) <= float32_orbit_tolerance(num_steps)
    assert np.max(np.asarray(drift, float)) <= float32_orbit_tolerance(num_steps)


# --------------------------------------------------------------------------- 10⁷ steps (slow)


@pytest.mark.slow
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_ten_million_steps(dtype):
    """10⁷ steps of 16 chains (rigid body, β = 3, |μ| = 1.5, dt = 0.01, T = 10⁵ per chain),
    nothing stored: finite, on the orbit (float32: ``10 √n ε₃₂``), and E[μ_i²] within 5 MCSE
    of the exact law; the MCSE comes from 16 × 50 batch means of 2·10⁵ steps (2000 time units,
    far beyond the autocorrelation time ~1), and the splitting's O(dt²) bias at dt = 0.01 is
    below it."""
    inertia, beta, radius = (1.0, 2.0, 4.0), 3.0, 1.5
    target = RestrictedGaussian(inertia=inertia, beta=beta, radius=radius)
    exact = np.diag(np.asarray(target.second_moments()))
    starts64 = np.asarray(target.sample(jax.random.key(1), 16))
    num_steps = 10_000_000
    system = liesample.systems.rigid_body(inertia)
    with jax.enable_x64(dtype == "float64"):
        algorithm = liesample.lie_poisson_langevin(system, beta=beta, step_size=0.01)
        means, drift, bad, final = stationary_run(
            algorithm,
            jnp.asarray(starts64, dtype),
            num_steps,
            lambda m: m * m,
            jax.random.key(2),
            num_batches=50,
        )
    assert not np.any(bad) and np.all(np.isfinite(np.asarray(final)))
    tolerance = 1e-10 if dtype == "float64" else float32_orbit_tolerance(num_steps)
    assert np.max(np.asarray(drift, float)) <= tolerance
    batches = np.asarray(means, float).reshape(-1, 3)
    mcse = batches.std(axis=0, ddof=1) / math.sqrt(batches.shape[0])
    z = np.abs(batches.mean(axis=0) - exact) / mcse
    assert np.all(z < 5.0), f"estimate {batches.mean(axis=0)}, exact {exact}, z {z}"
