"""float32 (``jax_enable_x64`` off): the systems accept the starts float32 can hold, refuse the
ones that are off, naming how to run in float64, and a run that leaves its orbits says so.

The suite runs in float64 (``tests/conftest.py``); each float32 case runs inside
``jax.enable_x64(False)``, which restores the setting on exit, and builds its systems there
(functions traced in float64 are not reused in float32). The start checks' rule is
``liesample.foundation.precision``; the run's Casimir check is ``liesample.run.checks``.
"""

import re
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample import systems
from liesample.foundation.precision import X64_SWITCH, roundoff_tolerance
from liesample.geometry.algebras import so3
from liesample.run.checks import casimir_drift_bound
from liesample.run.runner import sample_chains
from liesample.samplers.orbit._starts import check_orbit_starts, distinct_orbits, orbit_groups

EPS32 = float(np.finfo(np.float32).eps)
X64 = re.escape(X64_SWITCH)


def float32_unit_vectors(shape, seed=0):
    """Unit vectors normalised in float32 (each off by float32 round-off); NumPy, so that
    nothing is compiled for them."""
    x = np.random.default_rng(seed).normal(size=shape).astype(np.float32)
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


# ---------------------------------------------------------------------------- Zeitlin


@pytest.fixture(autouse=True)
def _zeitlin_programs_of_this_mode():
    """A process picks its precision once, at start-up (README); the suite switches it. The
    Zeitlin harmonics and their jitted transform are cached per size, and a program JAX traced
    under x64 is not retraced cleanly without it: these tests start and end with none cached."""
    from liesample.systems import zeitlin

    caches = (zeitlin.quantised_harmonics, zeitlin._compiled_from_coefficients)
    for cache in caches:
        cache.cache_clear()
    yield
    for cache in caches:
        cache.cache_clear()


@pytest.mark.parametrize(
    "size", [3] + [pytest.param(n, marks=pytest.mark.slow) for n in range(4, 13)]
)
def test_zeitlin_euler_accepts_its_own_float32_default_position(size):
    """Was refused for every N from 3 to 12 ("trace 1.49e-08"): the trace check allows the
    round-off of N float32 terms. (N = 3 by default: each size's check compiles its own
    eigenvalue programs; the rest in make test-slow.)"""
    with jax.enable_x64(False):
        system = systems.zeitlin_euler(size, noise_degree=2)
        start = jnp.asarray(system.default_position, jnp.float32)
        system.check_position(start)
    trace = abs(float(np.trace(np.asarray(start, float))))
    assert trace <= roundoff_tolerance(np.float32, terms=size) * np.linalg.norm(start)


def test_zeitlin_float32_start_with_a_trace_names_float64():
    with jax.enable_x64(False):
        system = systems.zeitlin_euler(3, noise_degree=2)
        start = jnp.asarray(system.default_position, jnp.float32) + 0.01 * jnp.eye(3)
        with pytest.raises(ValueError, match=f"trace-free.*{X64}"):
            system.check_position(start)
        with pytest.raises(ValueError, match=f"trace-free.*{X64}"):
            systems.zeitlin_euler(3, position=start)


# ---------------------------------------------------------------------------- vortices, spins


def test_point_vortex_starts_normalised_in_float32_are_accepted():
    """Were refused ("1e-09 relative"); a start 1e-3 off the sphere is still refused, naming
    jax_enable_x64."""
    with jax.enable_x64(False):
        system = systems.point_vortices([1.0, -2.0, 0.5])
        starts = np.stack([float32_unit_vectors((3, 3), seed) for seed in range(2)])
        assert starts.dtype == np.float32
        check_orbit_starts(system, starts)  # the start check of every orbit sampler's run
        system.check_position(starts[0])
        off = starts[1] * np.array([[1.0], [1.001], [1.0]], np.float32)
        with pytest.raises(ValueError, match=f"on the sphere of radius 1.*vortex 1.*{X64}"):
            system.check_position(off)


def test_spins_normalised_in_float32_are_accepted():
    with jax.enable_x64(False):
        system = systems.heisenberg((4,))
        spins = float32_unit_vectors((4, 3))
        check_orbit_starts(system, np.stack([spins, spins]))
        with pytest.raises(ValueError, match=f"unit spins.*site \\(2,\\).*{X64}"):
            system.check_position(spins * np.array([[1.0], [1.0], [1.001], [1.0]], np.float32))


def test_other_orbit_systems_accept_float32_starts():
    """Rigid body, heavy top and a custom ``lie_poisson_system``: their checks (a non-degenerate
    orbit) hold in float32 as they are; the starts are checked as every run checks them."""
    with jax.enable_x64(False):
        custom = systems.lie_poisson_system(
            so3, lambda m: jnp.sum(m**2 * jnp.array([1.0, 2.0, 3.0])), lambda m: m,
            jnp.array([0.3, 0.4, 0.5], jnp.float32),
        )  # fmt: skip
        rigid = systems.rigid_body([1.0, 2.0, 3.0])
        heavy = systems.heavy_top([1.0, 2.0, 3.0], 1.0)
        for system in (rigid, heavy, custom):
            start = np.asarray(system.default_position, np.float32)
            check_orbit_starts(system, np.stack([start, 0.5 * start]))


def test_float32_starts_on_one_orbit_sample_one_law():
    """Chains started at different float32 points of one orbit form one law group (their
    Casimirs differ by round-off), so their R-hat is computed; another orbit is another law."""
    with jax.enable_x64(False):
        system = systems.heisenberg((4,))
        spins = [float32_unit_vectors((4, 3), seed) for seed in range(3)]
        starts = np.stack([*spins, 0.5 * spins[0]])
        groups = orbit_groups(system)(starts)
    assert groups.tolist()[:3] == [groups[0]] * 3 and groups[3] != groups[0]
    casimirs = np.array([[2.25], [2.2500002], [1.0]], np.float32)  # |μ|² of three starts
    assert distinct_orbits(casimirs).tolist() == [0, 2]


def test_float64_checks_keep_their_floors():
    """x64 on: a float64 start is held to the float64 floors (1e-9 for the sphere) and told
    nothing about float64; a float32 start is held to float32 round-off, and told to pass a
    float64 array when it is off."""
    system = systems.point_vortices([1.0, -2.0, 0.5])
    start = np.asarray(system.default_position)
    with pytest.raises(ValueError, match=r"to 1e-09 relative.*off the sphere in all\)\.$"):
        system.check_position(start * np.array([[1.0], [1.0 + 1e-8], [1.0]]))
    start32 = np.asarray(float32_unit_vectors((3, 3)))
    system.check_position(start32)  # float32 round-off: fine, even with x64 on
    with pytest.raises(ValueError, match=r"held in float32.*float64 array"):
        system.check_position(start32 * np.array([[1.0], [1.001], [1.0]], np.float32))


# ---------------------------------------------------------------------------- Casimir drift


def test_casimir_drift_bound_follows_the_dtype():
    assert casimir_drift_bound(np.float32) == pytest.approx(1000 * EPS32)
    assert casimir_drift_bound(np.float64) == 1e-9  # the floor: 1000 ε₆₄ is below it


RIGID_START = [0.9, 1.2, 0.0]


def _run(run, integrator, num_draws, **options):
    """A rigid-body run (``liesample.sample`` or ``sample_chains``) from two starts on the orbit
    |μ| = 1.5: its Casimir warnings and its result."""
    system = systems.rigid_body((1.0, 2.0, 4.0))
    algorithm = liesample.lie_poisson_langevin(
        system, beta=3.0, step_size=0.05, integrator=integrator, stability="off"
    )
    starts = jnp.tile(jnp.asarray(RIGID_START), (2, 1))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = run(
            algorithm, jax.random.key(3), starts, num_draws, num_warmup=0, progress_bar=False,
            **options,
        )  # fmt: skip
    left = [str(w.message) for w in caught if "left their orbits" in str(w.message)]
    return left, result


def test_float32_run_off_its_orbits_warns_naming_float64():
    """A float32 run whose chains leave their orbits (the ambient Euler–Heun scheme: its step
    error, far above any round-off) records its drift and warns, naming jax_enable_x64;
    ``test_float32_round_off_over_a_million_steps_warns`` is the round-off alone."""
    with jax.enable_x64(False):
        left, tree = _run(liesample.sample, "euler_heun", 20, exact_starts=True)
    drift = tree.attrs["casimir_drift"]
    assert drift == pytest.approx(float(tree.sample_stats["casimir_error"].max()))
    assert drift > casimir_drift_bound(np.float32)
    assert len(left) == 1 and X64_SWITCH in left[0] and "euler_heun" in left[0]


def test_float64_run_records_its_drift_quietly():
    """float64 and the orbit-preserving default: quiet; the low-level loop records the drift in
    the run's settings, which ``liesample.sample`` writes to the tree's attributes."""
    left, result = _run(sample_chains, "splitting", 10)
    assert left == []
    assert 0.0 <= result.settings["casimir_drift"] <= casimir_drift_bound(np.float64)


@pytest.mark.slow
def test_float32_round_off_over_a_million_steps_warns():
    """The case measured by users (10⁶ float32 steps drifted 1.7e-4 with no warning): the
    orbit-preserving splitting at a large step, 10⁶ steps, drifts by round-off alone above the
    bound, and the run says so."""
    with jax.enable_x64(False):
        system = systems.rigid_body((1.0, 2.0, 4.0))
        algorithm = liesample.lie_poisson_langevin(system, beta=3.0, step_size=0.2)
        starts = jnp.tile(jnp.asarray(RIGID_START, jnp.float32), (2, 1))
        with pytest.warns(RuntimeWarning, match=f"left their orbits.*{X64}"):
            tree = liesample.sample(
                algorithm, jax.random.key(3), starts, 1000, thinning=1000, num_warmup=0,
                exact_starts=True, progress_bar=False,
            )  # fmt: skip
    assert tree.attrs["casimir_drift"] > casimir_drift_bound(np.float32)
