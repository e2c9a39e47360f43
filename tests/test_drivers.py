"""Semimartingale drivers (paper ``def:driving_semimartingale``), pathwise Casimirs, and the Itô
form as a cross-check of the Stratonovich integrators.

Exact reference: in the noise-only scene on so(3)* with ``ĥ_i = μ_i`` the SDE is linear,
``dμ = σ Σ_i L_i μ ∘ dS^i`` with ``L_i μ = ad*_{e_i} μ``. For the drivers here the Itô form is
``dμ = B μ dt + σ Σ_i L_i μ dM^i`` with ``B = σ Σ_i a_i L_i + ½ σ² q Σ_i L_i²`` (``a``: drift,
``q = d[S]/dt``), so ``E μ(T) = e^{B T} μ₀`` and ``vec E[μμᵀ](T) = e^{𝓛 T} vec(μ₀μ₀ᵀ)`` with
``𝓛 = B⊗I + I⊗B + σ² q Σ_i L_i⊗L_i``. A time change ``τ`` replaces ``T`` by ``τ(T)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import liesample
from liesample.dynamics import PoissonLangevin, Scene
from liesample.geometry.algebras import so3
from liesample.integrators.drivers import (
    BrownianMotion,
    DriftedBrownianMotion,
    TimeChangedBrownianMotion,
    simulate,
)
from liesample.systems import heavy_top, rigid_body

MU0 = np.array([0.3, -0.5, 1.2])
SIGMA = 0.9
T_END = 1.0
STEP = 0.004
NUM_PATHS = 2000

DRIVERS = {
    "brownian": (BrownianMotion(scale=0.8), np.zeros(3), 0.64, T_END),
    "drifted": (
        DriftedBrownianMotion(drift=(0.7, -0.4, 0.2), scale=0.8),
        (0.7, -0.4, 0.2),
        0.64,
        T_END,
    ),
    "time-changed": (
        TimeChangedBrownianMotion(lambda t: t**2 + 0.5 * t),
        np.zeros(3),
        1.0,
        T_END**2 + 0.5 * T_END,
    ),
}


def generators():
    return np.stack([np.asarray(so3.ad_star(jnp.eye(3)[i], jnp.eye(3))).T for i in range(3)])


def test_generators_are_the_noise_fields():
    L = generators()
    mu = np.array([0.4, 1.1, -0.7])
    for i in range(3):
        np.testing.assert_allclose(L[i] @ mu, so3.ad_star(jnp.eye(3)[i], mu), atol=1e-15)
    np.testing.assert_allclose(sum(l @ l for l in L), -2 * np.eye(3), atol=1e-14)


def exact_moments(drift, q, clock_end):
    """``E μ(T)`` and ``E[μμᵀ](T)`` of the linear SDE (module docstring); ``clock_end`` is
    ``τ(T)`` (``T`` without a time change; drift only appears without one)."""
    L = generators()
    B = SIGMA * sum(a * l for a, l in zip(drift, L)) + 0.5 * SIGMA**2 * q * sum(l @ l for l in L)
    eye = np.eye(3)
    big = np.kron(B, eye) + np.kron(eye, B) + SIGMA**2 * q * sum(np.kron(l, l) for l in L)
    mean = scipy.linalg.expm(B * clock_end) @ MU0
    second = (scipy.linalg.expm(big * clock_end) @ np.outer(MU0, MU0).ravel()).reshape(3, 3)
    return mean, second


def final_states(driver, form, integrator="splitting", hamiltonian=False, system=None):
    system = rigid_body() if system is None else system
    num_steps = round(T_END / STEP)

    def one(key):
        path = simulate(
            system,
            key,
            MU0 if system.event_shape == (3,) else None,
            step_size=STEP,
            num_steps=num_steps,
            sigma=SIGMA,
            driver=driver,
            hamiltonian=hamiltonian,
            integrator=integrator,
            form=form,
            save_every=num_steps,
        )
        return path.positions[-1], path.nonfinite

    keys = jax.random.split(jax.random.key(2024), NUM_PATHS)
    final, nonfinite = liesample.jit(jax.vmap(one))(keys)
    assert not np.any(np.asarray(nonfinite))
    return np.asarray(final)


def assert_matches(samples, exact_mean, exact_second, z_max=4.5):
    features = np.concatenate(
        [samples, (samples[:, :, None] * samples[:, None, :]).reshape(len(samples), 9)], axis=1
    )
    exact = np.concatenate([exact_mean, exact_second.ravel()])
    se = features.std(0) / np.sqrt(len(features))
    z = (features.mean(0) - exact) / se
    assert np.all(np.abs(z) < z_max), np.round(z, 2)
    return z


def _law_cases():
    """Every driver in the Stratonovich form and Brownian motion in the Itô form by default."""
    for form in ("stratonovich", "ito"):
        for name in sorted(DRIVERS):
            quick = form == "stratonovich" or name == "brownian"
            # slow: the Itô form under another driver; the default suite checks this with the
            # [stratonovich-<driver>] and [ito-brownian] cases of
            # test_drivers.py::test_law_at_time_t_matches_exact
            marks = () if quick else pytest.mark.slow
            yield pytest.param(name, form, id=f"{form}-{name}", marks=marks)


@pytest.mark.parametrize(("name", "form"), list(_law_cases()))
def test_law_at_time_t_matches_exact(name, form):
    """Stratonovich (orbit-preserving splitting) and Itô (ambient Euler–Maruyama with the
    correction) both reproduce the exact first and second moments at time T."""
    driver, drift, q, clock_end = DRIVERS[name]
    mean, second = exact_moments(drift, q, clock_end)
    samples = final_states(driver, form)
    assert_matches(samples, mean, second)
    moved = np.abs(mean - MU0).max()
    assert moved > 0.2  # the reference is not trivially the start


def test_ito_without_its_correction_is_wrong():
    """Reading the Stratonovich noise as Itô (no ``½σ²Σ DX·X`` drift) misses the decay of E μ."""
    driver, drift, q, clock_end = DRIVERS["brownian"]
    mean, _ = exact_moments(drift, q, clock_end)
    system = rigid_body()
    dynamics = PoissonLangevin(system, sigma=SIGMA, theta=0.0, scene=Scene(False, False, True))
    num_steps = round(T_END / STEP)

    def one(key):
        def step(mu, k):
            dS = driver.increments(jax.random.fold_in(key, k), k * STEP, STEP, 3, mu.dtype)
            return mu + dynamics.vector_field(mu, STEP, dS), None

        return jax.lax.scan(step, jnp.asarray(MU0), jnp.arange(num_steps))[0]

    samples = np.asarray(
        liesample.jit(jax.vmap(one))(jax.random.split(jax.random.key(7), NUM_PATHS))
    )
    se = samples.std(0) / np.sqrt(NUM_PATHS)
    assert np.max(np.abs(samples.mean(0) - mean) / se) > 10


def _driver_cases():
    """Every driver with the default integrator and every integrator under Brownian motion in the
    default suite; the other pairs in ``make test-slow``."""
    for integrator in ("splitting", "rkmk_heun", "lie_euler"):
        for name in sorted(DRIVERS):
            quick = integrator == "splitting" or name == "brownian"
            yield pytest.param(
                name, integrator, id=f"{integrator}-{name}", marks=() if quick else pytest.mark.slow
            )


@pytest.mark.parametrize(("name", "integrator"), list(_driver_cases()))
def test_casimirs_kept_pathwise_under_every_driver(name, integrator):
    """Hamiltonian + semimartingale noise: |μ|² (rigid body) and |Γ|², Π·Γ (heavy top) stay at
    their initial values to round-off along every path, whatever the driver."""
    driver = DRIVERS[name][0]
    if name == "drifted":  # one drift for any number of directions (the heavy top has 6)
        driver = DriftedBrownianMotion(drift=0.7, scale=0.8)
    cases = ((rigid_body(), MU0), (heavy_top(), np.array([0.5, -0.2, 0.9, 0.3, -0.8, 0.4])))
    for system, start in cases:

        def one(key, system=system, start=start):
            return simulate(
                system,
                key,
                start,
                step_size=0.05,
                num_steps=400,
                sigma=1.5,
                driver=driver,
                integrator=integrator,
                save_every=10,
            ).positions

        paths = liesample.jit(jax.vmap(one))(jax.random.split(jax.random.key(3), 8))
        reference = system.casimirs(start)
        errors = jax.vmap(jax.vmap(lambda m, s=system, c=reference: s.casimir_error(m, c)))(paths)
        assert float(jnp.max(errors)) < 1e-12
        assert float(jnp.max(jnp.abs(paths[:, -1] - start))) > 0.1  # the paths moved


def test_ito_euler_leaves_the_orbit():
    """The ambient Itô scheme is a cross-check, not a sampler: it drifts off |μ| = const."""
    samples = final_states(DRIVERS["brownian"][0], "ito", hamiltonian=True)
    assert np.max(np.abs(np.sum(samples**2, 1) - MU0 @ MU0)) > 1e-3


def test_dissipation_only_with_standard_brownian_driver():
    system = rigid_body()
    with pytest.raises(ValueError, match="balances standard Brownian noise"):
        simulate(
            system,
            jax.random.key(0),
            step_size=0.1,
            num_steps=1,
            beta=1.0,
            driver=DriftedBrownianMotion(drift=1.0),
        )
    path = simulate(system, jax.random.key(0), step_size=0.1, num_steps=5, beta=2.0)
    assert path.positions.shape == (6, 3)


@pytest.mark.parametrize(
    ("factory", "match"),
    [
        (lambda: DriftedBrownianMotion(scale=0.0), "scale must be > 0"),
        (lambda: DriftedBrownianMotion(drift=np.nan), "drift must be a finite"),
        (lambda: DriftedBrownianMotion(drift=[[1.0]]), "drift must be a finite"),
        (lambda: BrownianMotion(scale=-1.0), "scale must be > 0"),
        (lambda: TimeChangedBrownianMotion(3.0), "clock must be a callable"),
    ],
)
def test_bad_drivers(factory, match):
    with pytest.raises((ValueError, TypeError), match=match):
        factory()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"driver": TimeChangedBrownianMotion(lambda t: 1.0 + t)}, "τ\\(0\\) = 0"),
        ({"driver": TimeChangedBrownianMotion(lambda t: jnp.sin(5 * t))}, "strictly increasing"),
        ({"driver": DriftedBrownianMotion(drift=(1.0, 2.0))}, "one per direction"),
        ({"driver": "brownian"}, "driver must be"),
        ({"form": "weird"}, "form must be"),
        ({"num_steps": 10, "save_every": 3}, "multiple of save_every"),
        ({"num_steps": 0}, "num_steps must be"),
        ({"step_size": -0.1}, "step_size must be > 0"),
        ({"sigma": -1.0}, "sigma must be >= 0"),
    ],
)
def test_bad_simulation_arguments(kwargs, match):
    arguments = {"step_size": 0.1, "num_steps": 10} | kwargs
    with pytest.raises((ValueError, TypeError), match=match):
        simulate(rigid_body(), jax.random.key(0), **arguments)


def test_bad_start_is_refused():
    with pytest.raises(ValueError, match="shape"):
        simulate(rigid_body(), jax.random.key(0), np.ones(4), step_size=0.1, num_steps=1)
