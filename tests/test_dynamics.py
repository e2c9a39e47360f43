"""The Poisson–Langevin dynamics: scenes, the derived dissipation (MATH.md §1–2), and that scenes
are structural (a disabled effect is never traced and draws no random numbers).

For the rigid body ``h = ½ μ·I⁻¹μ``, ``ĥ_i = e_i·μ`` the closed form of MATH.md §2 is

    dμ = μ×Ω dt + θ μ×(μ×Ω) dt + σ Σ_i μ×e_i ∘ dW_i,    Ω = I⁻¹μ,

and the dissipation changes ``h`` at the rate ``−θ Σ_i {h, ĥ_i}² ≤ 0`` with the (−) bracket
``{f, g}(μ) = −⟨μ, ∇f × ∇g⟩``. Comparisons with these closed forms are of a few float64
operations on O(1) numbers: ``1e-13`` absolute is ~100 ulp and far below any sign/factor slip.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample import PoissonLangevin, Scene
from liesample.integrators import INTEGRATORS
from liesample.samplers.orbit.lie_poisson_langevin import make_dynamics

INERTIA = np.array([1.0, 2.0, 4.0])
SYSTEM = liesample.systems.rigid_body(tuple(INERTIA))
ATOL = 1e-13
KEY = jax.random.key(3)


def random_states(n=8, seed=11):
    return np.random.default_rng(seed).normal(size=(n, 3)) * 1.5


def hamiltonian_grad(mu):
    return mu / INERTIA


def lie_poisson_bracket(mu, grad_f, grad_g):
    """The (−) Lie–Poisson bracket of MATH.md §2, written out independently."""
    return -np.dot(mu, np.cross(grad_f, grad_g))


# ---------------------------------------------------------------------------------------------
# Scene
# ---------------------------------------------------------------------------------------------


def test_scene_without_effects_raises():
    with pytest.raises(ValueError, match="no effect"):
        Scene(hamiltonian=False, dissipation=False, noise=False)


@pytest.mark.parametrize("name", ["hamiltonian", "dissipation", "noise"])
@pytest.mark.parametrize("value", [1, 0, None, "yes", np.bool_(True)])
def test_scene_flags_must_be_bool(name, value):
    with pytest.raises(TypeError, match=name):
        Scene(**{name: value})


def test_scene_effects():
    assert Scene().effects == ("hamiltonian", "dissipation", "noise")
    assert Scene(dissipation=False).effects == ("hamiltonian", "noise")
    assert Scene(hamiltonian=False, noise=False).effects == ("dissipation",)
    assert Scene(hamiltonian=True, dissipation=False, noise=False).effects == ("hamiltonian",)


def test_make_dynamics_builds_scenes_from_coefficients():
    assert make_dynamics(SYSTEM, sigma=0.0)[2] == Scene(True, False, False)
    assert make_dynamics(SYSTEM, sigma=0.0, theta=0.5)[2] == Scene(True, True, False)
    assert make_dynamics(SYSTEM, sigma=1.0, beta=0.0)[2] == Scene(True, False, True)
    sigma, theta, scene = make_dynamics(SYSTEM, sigma=2.0, beta=3.0, hamiltonian=False)
    assert (sigma, theta, scene) == (2.0, 0.5 * 3.0 * 2.0**2, Scene(False, True, True))
    with pytest.raises(ValueError, match="no effect"):
        make_dynamics(SYSTEM, sigma=0.0, hamiltonian=False)


# ---------------------------------------------------------------------------------------------
# The generator against the closed form of MATH.md §2
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("theta", [0.0, 0.5, 2.0])
def test_deterministic_vector_field_is_the_double_bracket(theta):
    """Ambient field with dt = 1, no noise: μ×Ω + θ μ×(μ×Ω) (energy-decreasing sign)."""
    dynamics = PoissonLangevin(
        SYSTEM, sigma=0.0, theta=theta, scene=Scene(hamiltonian=True, dissipation=True, noise=False)
    )
    field = liesample.jit(lambda m: dynamics.vector_field(m, 1.0))
    generator = liesample.jit(lambda m: dynamics.generator(m, 1.0))
    for mu in random_states():
        omega = hamiltonian_grad(mu)
        expected = np.cross(mu, omega) + theta * np.cross(mu, np.cross(mu, omega))
        np.testing.assert_allclose(field(mu), expected, rtol=0, atol=ATOL * 10)
        # The generator itself: ∇h dt − θ Σ {h, ĥ_i} ∇ĥ_i dt = Ω + θ μ×Ω.
        np.testing.assert_allclose(generator(mu), omega + theta * np.cross(mu, omega), atol=ATOL)


def test_dissipation_decreases_energy_at_the_bracket_rate():
    theta = 0.7
    dissipation = PoissonLangevin(
        SYSTEM,
        sigma=0.0,
        theta=theta,
        scene=Scene(hamiltonian=False, dissipation=True, noise=False),
    )
    hamiltonian = PoissonLangevin(
        SYSTEM,
        sigma=0.0,
        theta=theta,
        scene=Scene(hamiltonian=True, dissipation=False, noise=False),
    )
    noise_grads = np.eye(3)  # ∇ĥ_i = e_i
    for mu in random_states(seed=5):
        omega = hamiltonian_grad(mu)
        brackets = np.array([lie_poisson_bracket(mu, omega, g) for g in noise_grads])
        library_brackets = dissipation.brackets_with_noise(mu, jnp.asarray(omega))
        np.testing.assert_allclose(library_brackets, brackets, atol=ATOL)
        rate = float(np.dot(omega, dissipation.vector_field(mu, 1.0)))
        assert rate == pytest.approx(-theta * np.sum(brackets**2), rel=1e-12, abs=ATOL)
        assert rate <= 0.0
        # Strictly negative off the principal axes (not a vacuous ≤ 0).
        assert rate < -1e-6
        # The Hamiltonian drift conserves h.
        assert abs(float(np.dot(omega, hamiltonian.vector_field(mu, 1.0)))) < ATOL


def test_dissipation_vanishes_at_the_principal_axes():
    dynamics = PoissonLangevin(
        SYSTEM, sigma=0.0, theta=1.0, scene=Scene(hamiltonian=False, dissipation=True, noise=False)
    )
    for axis in np.eye(3):
        np.testing.assert_allclose(dynamics.vector_field(2.0 * axis, 1.0), 0.0, atol=ATOL)


def test_noise_part_is_sigma_mu_cross_dW():
    sigma, dt = 0.8, 0.3
    dynamics = PoissonLangevin(
        SYSTEM,
        sigma=sigma,
        theta=0.0,
        scene=Scene(hamiltonian=False, dissipation=False, noise=True),
    )
    rng = np.random.default_rng(2)
    for mu in random_states(seed=9):
        dW = rng.normal(size=3) * np.sqrt(dt)
        expected = sigma * sum(np.cross(mu, e) * w for e, w in zip(np.eye(3), dW))
        np.testing.assert_allclose(dynamics.vector_field(mu, dt, dW), expected, atol=ATOL)
        np.testing.assert_allclose(dynamics.generator(mu, dt, dW), sigma * dW, atol=ATOL)


def test_full_generator_is_the_sum_of_its_parts():
    sigma, theta, dt = 0.6, 0.9, 0.05
    dW = np.array([0.1, -0.3, 0.2])
    full = PoissonLangevin(SYSTEM, sigma, theta, Scene())
    mu = random_states(1)[0]
    omega = hamiltonian_grad(mu)
    expected = omega * dt + theta * dt * np.cross(mu, omega) + sigma * dW
    np.testing.assert_allclose(full.generator(mu, dt, dW), expected, atol=ATOL)


def test_dW_must_match_the_scene():
    mu = random_states(1)[0]
    with pytest.raises(ValueError, match="dW"):
        PoissonLangevin(SYSTEM, 1.0, 0.5, Scene()).generator(mu, 0.1)
    with pytest.raises(ValueError, match="dW"):
        PoissonLangevin(SYSTEM, 0.0, 0.5, Scene(noise=False)).generator(mu, 0.1, np.zeros(3))
    with pytest.raises(ValueError, match="dW"):
        PoissonLangevin(SYSTEM, 1.0, 0.5, Scene()).group_generator(mu, 0, 0.1)


@pytest.mark.parametrize(
    "scene",
    [
        Scene(hamiltonian=False),
        Scene(hamiltonian=False, noise=False),
        Scene(hamiltonian=False, dissipation=False),
    ],
    ids=["dissipation+noise", "dissipation", "noise"],
)
def test_group_generators_sum_to_the_generator(scene):
    dynamics = PoissonLangevin(SYSTEM, sigma=0.7, theta=1.3, scene=scene)
    dt = 0.02
    rng = np.random.default_rng(4)
    for mu in random_states(seed=21):
        dW = rng.normal(size=3) * np.sqrt(dt) if scene.noise else None
        total = sum(dynamics.group_generator(mu, g, dt, dW) for g in range(SYSTEM.num_noise_groups))
        expected = dynamics.generator(mu, dt, dW)
        np.testing.assert_allclose(total, expected, atol=ATOL)
        assert np.linalg.norm(expected) > 1e-4  # not comparing zeros


def test_brownian_increments_only_with_noise():
    assert (
        PoissonLangevin(SYSTEM, 0.0, 1.0, Scene(noise=False)).brownian_increments(
            KEY, 0.1, jnp.float64
        )
        is None
    )
    dW = PoissonLangevin(SYSTEM, 1.0, 1.0, Scene()).brownian_increments(KEY, 0.1, jnp.float64)
    assert dW.shape == (3,) and dW.dtype == jnp.float64


# ---------------------------------------------------------------------------------------------
# Scenes are structural: inspect the jaxpr of one sampler step
# ---------------------------------------------------------------------------------------------

RANDOM_PRIMITIVES = ("random_bits", "threefry")


def _sub_jaxprs(value):
    if hasattr(value, "eqns"):  # an open jaxpr
        yield value
    elif hasattr(value, "jaxpr") and hasattr(value.jaxpr, "eqns"):  # a closed jaxpr
        yield value.jaxpr
    elif isinstance(value, (tuple, list)):
        for v in value:
            yield from _sub_jaxprs(v)


def count_eqns(jaxpr) -> int:
    """Equations of ``jaxpr``, recursively through every sub-jaxpr (jit, scan, cond, …)."""
    jaxpr = getattr(jaxpr, "jaxpr", jaxpr)
    total = 0
    for eqn in jaxpr.eqns:
        total += 1
        for param in eqn.params.values():
            for sub in _sub_jaxprs(param):
                total += count_eqns(sub)
    return total


def primitive_names(jaxpr) -> set:
    jaxpr = getattr(jaxpr, "jaxpr", jaxpr)
    names = set()
    for eqn in jaxpr.eqns:
        names.add(eqn.primitive.name)
        for param in eqn.params.values():
            for sub in _sub_jaxprs(param):
                names |= primitive_names(sub)
    return names


def step_jaxpr(system=SYSTEM, **kwargs):
    algorithm = liesample.lie_poisson_langevin(system, step_size=0.01, **kwargs)
    state = algorithm.init(system.default_position)
    return jax.make_jaxpr(algorithm.step)(jax.random.key(0), state)


def uses_randomness(jaxpr) -> bool:
    text = str(jaxpr)
    names = primitive_names(jaxpr)
    return any(p in text for p in RANDOM_PRIMITIVES) or any(
        p in name for name in names for p in RANDOM_PRIMITIVES
    )


@pytest.mark.parametrize("integrator", sorted(INTEGRATORS))
@pytest.mark.parametrize(
    "kwargs",
    [
        {"sigma": 0.0},
        {"sigma": 0.0, "theta": 0.5},
        {"sigma": 0.0, "theta": 0.5, "hamiltonian": False},
    ],
    ids=["hamiltonian", "hamiltonian+dissipation", "dissipation"],
)
def test_noise_off_draws_no_random_numbers(integrator, kwargs):
    assert not uses_randomness(step_jaxpr(integrator=integrator, **kwargs))


@pytest.mark.parametrize("integrator", sorted(INTEGRATORS))
@pytest.mark.parametrize(
    "kwargs",
    [{"sigma": 1.0, "beta": 2.0}, {"sigma": 1.0, "beta": 0.0, "hamiltonian": False}],
    ids=["full", "noise-only"],
)
def test_noise_on_draws_random_numbers(integrator, kwargs):
    assert uses_randomness(step_jaxpr(integrator=integrator, **kwargs))


@pytest.mark.parametrize("integrator", sorted(INTEGRATORS))
def test_hamiltonian_only_scene_is_a_smaller_program(integrator):
    hamiltonian_only = count_eqns(step_jaxpr(integrator=integrator, sigma=0.0))
    with_dissipation = count_eqns(step_jaxpr(integrator=integrator, sigma=0.0, theta=0.5))
    full = count_eqns(step_jaxpr(integrator=integrator, sigma=1.0, beta=2.0))
    no_dissipation = count_eqns(step_jaxpr(integrator=integrator, sigma=1.0, beta=0.0))
    assert hamiltonian_only < with_dissipation < full
    assert no_dissipation < full
    # A zero coefficient is a different program from a disabled effect: θ = 0 with noise on
    # (β = 0) drops the dissipation, so it is not the full program with a zero multiplier.


def counting_system(counter):
    """The rigid body whose noise Hamiltonians bump ``counter`` each time they are traced."""

    def noise_hamiltonians(mu):
        counter["noise"] += 1  # Python side effect: runs at trace time only
        return SYSTEM.noise_hamiltonians(mu)

    def hamiltonian(mu):
        counter["hamiltonian"] += 1
        return SYSTEM.hamiltonian(mu)

    return dataclasses.replace(
        SYSTEM, noise_hamiltonians=noise_hamiltonians, hamiltonian=hamiltonian
    )


@pytest.mark.parametrize("integrator", sorted(INTEGRATORS))
def test_disabled_dissipation_is_never_traced(integrator):
    counter = {"noise": 0, "hamiltonian": 0}
    system = counting_system(counter)
    step_jaxpr(system, integrator=integrator, sigma=0.0)  # σ = 0, θ = 0: Hamiltonian only
    assert counter["noise"] == 0
    assert counter["hamiltonian"] > 0
    # The counter works: with dissipation on, the noise Hamiltonians are traced.
    step_jaxpr(system, integrator=integrator, sigma=0.0, theta=0.5)
    assert counter["noise"] > 0


def test_disabled_hamiltonian_is_never_traced_by_the_generator():
    counter = {"noise": 0, "hamiltonian": 0}
    system = counting_system(counter)
    noise_only = PoissonLangevin(system, 1.0, 0.0, Scene(hamiltonian=False, dissipation=False))
    jax.make_jaxpr(lambda m, w: noise_only.generator(m, 0.1, w))(jnp.ones(3), jnp.ones(3))
    assert counter == {"noise": 1, "hamiltonian": 0}
    full = PoissonLangevin(system, 1.0, 0.5, Scene())
    jax.make_jaxpr(lambda m, w: full.generator(m, 0.1, w))(jnp.ones(3), jnp.ones(3))
    assert counter["hamiltonian"] == 1
