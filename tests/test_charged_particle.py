"""The canonical/magnetic structure on T*Rⁿ and the charged Brownian particle (MATH.md §1, §3).

Closed forms used as references, written out independently of the library:

- derived dissipation ``−θ Σ {h, ĥ_i} X_{ĥ_i} = (0, −θ p/m)`` for ``ĥ_i = −q_i``;
- Gibbs law ``∝ exp(−βV − β|p|²/2m)``: for ``V = ½ qᵀKq``, ``Cov q = K⁻¹/β``,
  ``Cov p = (m/β) I``, whatever ``G``;
- cyclotron motion in a constant ``B`` (``V = 0``): ``p`` rotates about ``B`` at
  ``ω = e|B|/m``, the guiding centre ``q + p×B/(e|B|²)`` moves with ``p_∥/m``, and the Larmor
  radius is ``|p_⊥|/(|e||B|)``;
- the magnetic bottle ``A = ½(−q₂ g, q₁ g, 0)``, ``g = 1 + q₃²/2``:
  ``B = curl A = (−q₁q₃/2, −q₂q₃/2, g)``.

Deterministic comparisons are of a few float64 operations on O(1) numbers, so ``1e-12`` is
~10⁴ ulp and far below any sign or factor slip.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import liesample
from liesample import PoissonLangevin, Scene
from liesample.dynamics.sde import PoissonLangevinSDE
from liesample.geometry.cotangent import kinetic_magnetic_flow, make_metric
from liesample.geometry.poisson import (
    LiePoissonStructure,
    field_from_vector_potential,
    magnetic_structure,
)
from liesample.systems.charged_particle import (
    MagneticScene,
    charged_particle,
    charged_particle_dynamics,
    charged_particle_path,
)

ATOL = 1e-12
STIFFNESS = np.array([[2.0, 0.6], [0.6, 1.0]])


def quadratic_potential(q):
    return 0.5 * q @ jnp.asarray(STIFFNESS) @ q


def bottle_potential(q):
    g = 1.0 + 0.5 * q[2] ** 2
    return 0.5 * jnp.array([-q[1] * g, q[0] * g, 0.0])


def bottle_field(q):
    return np.array([-q[0] * q[2] / 2, -q[1] * q[2] / 2, 1.0 + q[2] ** 2 / 2])


def random_states(n, count=6, seed=5):
    return np.random.default_rng(seed).normal(size=(count, 2 * n))


# ---------------------------------------------------------------------------------------------
# The structure and the derived dissipation
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "field",
    [
        {"magnetic_field": None},
        {"magnetic_field": [0.3, -0.4, 1.2]},
        {"vector_potential": bottle_potential},
    ],
    ids=["canonical", "constant", "bottle"],
)
def test_derived_dissipation_is_the_friction(field):
    mass, charge, beta, sigma = 1.7, -0.8, 2.5, 0.9
    theta = 0.5 * beta * sigma**2
    system = charged_particle(
        lambda q: jnp.sum(jnp.cos(q)) + 0.5 * jnp.sum(q**2),
        mass=mass,
        charge=charge,
        dimension=3,
        **field,
    )
    dynamics = charged_particle_dynamics(system, beta=beta, sigma=sigma)
    sde = dynamics.sde
    states = random_states(3)
    derived = liesample.jit(
        jax.vmap(
            lambda z: (
                sde.dissipation(z),
                sde.brackets_with_noise(z),
                sde.drift(z),
                sde.noise_fields(z),
            )
        )
    )(jnp.asarray(states))
    for z, dissipation, brackets, drift, noise_fields in zip(states, *derived, strict=True):
        q, p = z[:3], z[3:]
        np.testing.assert_allclose(
            dissipation, np.concatenate([np.zeros(3), -theta * p / mass]), atol=ATOL
        )
        np.testing.assert_allclose(brackets, p / mass, atol=ATOL)
        magnetic = np.zeros((3, 3))
        if "magnetic_field" in field and field["magnetic_field"] is not None:
            b1, b2, b3 = field["magnetic_field"]
            magnetic = charge * np.array([[0, b3, -b2], [-b3, 0, b1], [b2, -b1, 0]])
        elif "vector_potential" in field:
            b1, b2, b3 = bottle_field(q)
            magnetic = charge * np.array([[0, b3, -b2], [-b3, 0, b1], [b2, -b1, 0]])
        force = np.sin(q) - q + magnetic @ p / mass  # −∇V + G p/m
        np.testing.assert_allclose(
            drift, np.concatenate([p / mass, force - theta * p / mass]), atol=ATOL
        )
        np.testing.assert_allclose(
            noise_fields, sigma * np.vstack([np.zeros((3, 3)), np.eye(3)]), atol=ATOL
        )
    assert dynamics.friction_rate == pytest.approx(theta / mass, rel=1e-12)


def test_lorentz_force_convention():
    """``G p/m = e (p/m) × B``: a positive charge moving along x in B = ẑ is pushed to −y."""
    structure = magnetic_structure(magnetic_field=[0.0, 0.0, 1.0], charge=2.0)
    force = structure.hamiltonian_vector_field(
        lambda z: 0.5 * jnp.sum(z[3:] ** 2), jnp.array([0.0, 0, 0, 1.0, 0, 0])
    )
    np.testing.assert_allclose(force, [1.0, 0, 0, 0, -2.0, 0], atol=ATOL)


def test_generic_sde_reproduces_the_lie_poisson_engine():
    """The structure-agnostic assembly with ``J(μ)ζ = ad*_ζ μ`` is ``PoissonLangevin``."""
    system = liesample.systems.rigid_body((1.0, 2.0, 4.0))
    engine = PoissonLangevin(system, sigma=0.7, theta=0.4, scene=Scene())
    generic = PoissonLangevinSDE(
        LiePoissonStructure(system.algebra),
        system.hamiltonian,
        system.noise_hamiltonians,
        0.7,
        0.4,
        Scene(),
    )
    rng = np.random.default_rng(2)
    for _ in range(4):
        mu, dW = jnp.asarray(rng.normal(size=3)), jnp.asarray(0.1 * rng.normal(size=3))
        np.testing.assert_allclose(
            generic.covector(mu, 0.01, dW), engine.generator(mu, 0.01, dW), atol=ATOL
        )
        np.testing.assert_allclose(
            generic.increment(mu, 0.01, dW), engine.vector_field(mu, 0.01, dW), atol=ATOL
        )


def test_bracket_matches_the_poisson_tensor_and_is_antisymmetric():
    structure = magnetic_structure(vector_potential=bottle_potential, charge=1.3, dimension=3)
    f = lambda z: jnp.sin(z[0]) * z[4] + z[2] ** 2
    g = lambda z: z[1] * z[3] - jnp.cos(z[5])

    @liesample.jit
    def pieces(z):
        tensor = structure.poisson_tensor(z)
        expected = jax.grad(f)(z) @ tensor @ jax.grad(g)(z)
        return tensor, expected, structure.bracket(f, g, z), structure.bracket(g, f, z)

    for z in map(jnp.asarray, random_states(3)):
        tensor, expected, forward, backward = pieces(z)
        np.testing.assert_allclose(tensor, -tensor.T, atol=ATOL)
        assert float(forward) == pytest.approx(float(expected), abs=ATOL)
        assert float(forward) == pytest.approx(-float(backward), abs=ATOL)


def test_vector_potential_field_is_the_curl_and_divergence_free():
    field = field_from_vector_potential(bottle_potential)
    positions = np.random.default_rng(4).normal(size=(6, 3))
    fields, divergences = liesample.jit(
        jax.vmap(lambda q: (field(q), jnp.trace(jax.jacfwd(field)(q))))
    )(jnp.asarray(positions))
    np.testing.assert_allclose(fields, np.stack([bottle_field(q) for q in positions]), atol=ATOL)
    np.testing.assert_allclose(divergences, 0.0, atol=ATOL)


def test_jacobi_identity_holds_for_a_field_from_a_vector_potential():
    """``{f,{g,k}} + cyclic = 0`` for linear ``f, g, k`` (it is ``dF = 0``, i.e. ``div B = 0``)."""
    structure = magnetic_structure(vector_potential=bottle_potential, dimension=3)
    rng = np.random.default_rng(9)
    a, b, c = (jnp.asarray(v) for v in rng.normal(size=(3, 6)))

    def linear(v):
        return lambda z: v @ z

    def nested(u, v, w):
        return lambda z: structure.bracket(
            linear(u), lambda y: structure.bracket(linear(v), linear(w), y), z
        )

    # A field with div B ≠ 0 (B = q) breaks it: the test can fail.
    broken = liesample.geometry.poisson.CanonicalStructure(
        3, lambda q: jnp.array([[0, q[2], -q[1]], [-q[2], 0, q[0]], [q[1], -q[0], 0]])
    )

    @liesample.jit
    def cyclic_sums(z):
        def broken_nested(u, v, w):
            return broken.bracket(linear(u), lambda y: broken.bracket(linear(v), linear(w), y), z)

        return (
            nested(a, b, c)(z) + nested(b, c, a)(z) + nested(c, a, b)(z),
            broken_nested(a, b, c) + broken_nested(b, c, a) + broken_nested(c, a, b),
        )

    for z in map(jnp.asarray, random_states(3)):
        cyclic, broken_cyclic = cyclic_sums(z)
        assert abs(float(cyclic)) < ATOL
        assert abs(float(broken_cyclic)) > 1e-3


def magnetic_flow(field, mass, step_size):
    """``(e^{εG/m}, (1/m) ∫₀^ε e^{sG/m} ds)``: the kinetic–magnetic flow the BAOAB drift uses."""
    flow = kinetic_magnetic_flow(field, make_metric(jnp.full(len(field), 1.0 / mass)), step_size)
    return flow.propagator, flow.displacement / mass


def test_exact_magnetic_flow_is_orthogonal_including_singular_g():
    """``e^{εG/m}`` is orthogonal to round-off for ``G = 0``, a singular ``G`` (rank 2, a strong
    field in R³ embedded in R⁴) and a generic one (one compiled shape, three matrices)."""
    singular = np.zeros((4, 4))
    singular[:3, :3] = magnetic_structure(magnetic_field=[0.0, 0.0, 40.0]).magnetic_term
    generic = [[0, 3.0, 1, 0], [-3, 0, 2, 5], [-1, -2, 0, 1], [0, -5, -1, 0]]
    flow = liesample.jit(magnetic_flow)
    for matrix in (
        np.zeros((4, 4)),
        singular,
        magnetic_structure(magnetic_field=generic).magnetic_term,
    ):
        rotation, displacement = flow(matrix, 1.3, 0.7)
        np.testing.assert_allclose(rotation.T @ rotation, np.eye(4), atol=ATOL)
        # displacement = (1/m) ∫₀^ε e^{sG/m} ds: G·displacement = rotation − I, and it commutes
        # with G; on ker G it is ε/m.
        np.testing.assert_allclose(matrix @ displacement, rotation - np.eye(4), atol=ATOL)
        np.testing.assert_allclose(matrix @ displacement, displacement @ matrix, atol=ATOL)
    _, displacement = flow(np.zeros((4, 4)), 1.3, 0.7)
    np.testing.assert_allclose(displacement, 0.7 / 1.3 * np.eye(4), atol=ATOL)
    _, displacement = flow(singular, 1.3, 0.7)
    assert displacement[3, 3] == pytest.approx(0.7 / 1.3, rel=1e-14)
    np.testing.assert_allclose(displacement[2, 2], 0.7 / 1.3, rtol=1e-14)  # B ∥ e₃: free along B


# ---------------------------------------------------------------------------------------------
# Simulations
# ---------------------------------------------------------------------------------------------


def cyclotron_reference(q0, p0, field, charge, mass, times):
    """Closed-form orbit in a constant field with ``V = 0`` (module docstring)."""
    field = np.asarray(field)
    strength = np.linalg.norm(field)
    axis = field / strength
    parallel = (p0 @ axis) * axis
    perpendicular = p0 - parallel
    angle = -charge * strength / mass * times[:, None]  # ṗ = −(e/m) B × p: rotation by −ω t
    p = parallel + np.cos(angle) * perpendicular + np.sin(angle) * np.cross(axis, perpendicular)
    centre = q0 + np.cross(p0, field) / (charge * strength**2) + parallel * times[:, None] / mass
    q = centre - np.cross(p, field) / (charge * strength**2)
    return q, p


def test_cyclotron_orbit_with_the_exact_flow():
    field, charge, mass, step = np.array([0.3, -0.4, 1.2]), -0.7, 1.3, 0.1
    system = charged_particle(lambda q: 0.0 * q[0], magnetic_field=field, mass=mass, charge=charge)
    q0, p0 = np.array([0.5, -1.0, 0.2]), np.array([1.0, 0.4, -0.3])
    path = charged_particle_path(
        system,
        jax.random.key(0),
        np.concatenate([q0, p0]),
        step_size=step,
        num_steps=300,
        sigma=0.0,
    )
    q, p = np.asarray(path.states[:, :3]), np.asarray(path.states[:, 3:])
    q_exact, p_exact = cyclotron_reference(q0, p0, field, charge, mass, step * np.arange(301))
    np.testing.assert_allclose(p, p_exact, atol=1e-11)
    np.testing.assert_allclose(q, q_exact, atol=1e-11)
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), np.linalg.norm(p0), rtol=1e-13)
    # Larmor radius |p_⊥|/(|e||B|) about the guiding centre, in the plane normal to B.
    axis = field / np.linalg.norm(field)
    centre = q + np.cross(p, field) / (charge * field @ field)
    offset = q - centre
    offset -= (offset @ axis)[:, None] * axis
    p_perp = p0 - (p0 @ axis) * axis
    np.testing.assert_allclose(
        np.linalg.norm(offset, axis=1),
        np.linalg.norm(p_perp) / (abs(charge) * np.linalg.norm(field)),
        rtol=1e-12,
    )


def test_cyclotron_with_implicit_midpoint_keeps_radius_and_has_cayley_frequency():
    """A constant field given by ``A = ½ B × q``: the implicit midpoint conserves ``|p|`` and the
    guiding centre (a linear invariant), so the radius is exact; its phase per half step is the
    Cayley angle ``2 atan(ω ε/4)`` instead of ``ω ε/2``."""
    field, charge, mass, step = np.array([0.0, 0.0, 2.0]), 1.5, 1.2, 0.05
    system = charged_particle(
        lambda q: 0.0 * q[0],
        vector_potential=lambda q: 0.5 * jnp.cross(jnp.asarray(field), q),
        mass=mass,
        charge=charge,
        dimension=3,
    )
    constant = magnetic_structure(magnetic_field=field, charge=charge).magnetic_term
    np.testing.assert_allclose(system.structure.magnetic_matrix(jnp.ones(3)), constant, atol=ATOL)
    p0 = np.array([0.8, -0.2, 0.1])
    path = charged_particle_path(
        system,
        jax.random.key(0),
        np.concatenate([np.zeros(3), p0]),
        step_size=step,
        num_steps=400,
        sigma=0.0,
    )
    assert bool(path.converged)
    p = np.asarray(path.states[:, 3:])
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), np.linalg.norm(p0), rtol=1e-12)
    omega = charge * 2.0 / mass
    angles = np.unwrap(np.arctan2(p[:, 1], p[:, 0]))
    per_step = 2 * 2 * np.arctan(omega * step / 4)
    np.testing.assert_allclose(angles - angles[0], -per_step * np.arange(401), atol=1e-9)
    assert abs(per_step - omega * step) > 1e-6  # the Cayley phase error is visible, not zero


def test_magnetic_bottle_conserves_kinetic_energy_without_noise():
    system = charged_particle(
        lambda q: 0.0 * q[0], vector_potential=bottle_potential, charge=3.0, dimension=3
    )
    z0 = np.array([0.4, 0.0, 0.0, 0.0, 0.6, 0.5])
    path = charged_particle_path(
        system, jax.random.key(0), z0, step_size=0.02, num_steps=3000, sigma=0.0
    )
    assert bool(path.converged) and not bool(path.nonfinite)
    kinetic = np.sum(np.asarray(path.states[:, 3:]) ** 2, axis=1)
    np.testing.assert_allclose(kinetic, kinetic[0], rtol=1e-11)
    # The orbit is not trivial: the particle is reflected by the bottle (p₃ changes sign).
    assert np.min(path.states[:, 5]) < -0.3


def test_heun_and_baoab_agree_on_a_dissipative_flow():
    system = charged_particle(
        lambda q: jnp.sum(q**2) + 0.1 * q[0] ** 4, vector_potential=bottle_potential, dimension=3
    )
    z0 = np.array([0.4, -0.2, 0.3, 0.1, 0.6, 0.5])
    ends = [
        charged_particle_path(
            system,
            jax.random.key(0),
            z0,
            step_size=1e-3,
            num_steps=1000,
            sigma=0.0,
            theta=0.3,
            integrator=name,
        ).states[-1]
        for name in ("baoab", "heun")
    ]
    np.testing.assert_allclose(ends[0], ends[1], atol=1e-5)
    assert np.max(np.abs(ends[0] - z0)) > 0.1


def test_pure_friction_decreases_the_energy():
    system = charged_particle(quadratic_potential, magnetic_field=[[0.0, 4.0], [-4.0, 0.0]])
    path = charged_particle_path(
        system,
        jax.random.key(0),
        np.array([1.0, -1.0, 0.5, 0.5]),
        step_size=0.02,
        num_steps=2000,
        sigma=0.0,
        theta=1.0,
    )
    energy = np.asarray(liesample.jit(jax.vmap(system.hamiltonian_fn()))(path.states))
    assert np.all(np.diff(energy) < 1e-12) and energy[-1] < 0.01 * energy[0]


def stationary_moments(system, beta, sigma, key, num_chains=256, num_steps=4000, step_size=0.05):
    """Per-chain time averages of ``q qᵀ`` (3 entries) and ``p_i²`` from exact stationary starts."""
    mass = system.mass
    dynamics = charged_particle_dynamics(system, beta=beta, sigma=sigma)
    key_q, key_p, key_run = jax.random.split(key, 3)
    cov_q = np.linalg.inv(STIFFNESS) / beta
    q0 = jax.random.multivariate_normal(key_q, jnp.zeros(2), jnp.asarray(cov_q), (num_chains,))
    p0 = jnp.sqrt(mass / beta) * jax.random.normal(key_p, (num_chains, 2))
    run = liesample.jit(
        jax.vmap(lambda k, z: dynamics.path(k, z, step_size, num_steps, 4).states[1:])
    )
    states = run(jax.random.split(key_run, num_chains), jnp.concatenate([q0, p0], axis=1))
    q, p = states[..., :2], states[..., 2:]
    per_chain = jnp.stack(
        [
            jnp.mean(q[..., 0] ** 2, 1),
            jnp.mean(q[..., 0] * q[..., 1], 1),
            jnp.mean(q[..., 1] ** 2, 1),
            jnp.mean(p[..., 0] ** 2, 1),
            jnp.mean(p[..., 1] ** 2, 1),
            jnp.mean(q[..., 0] * p[..., 1], 1),
        ],
        axis=1,
    )
    cov_p = mass / beta
    exact = np.array([cov_q[0, 0], cov_q[0, 1], cov_q[1, 1], cov_p, cov_p, 0.0])
    return np.asarray(per_chain), exact


@pytest.mark.parametrize(
    "strong_field",
    [
        # slow: the same Gibbs law without a field; the default suite checks this with
        # test_charged_particle.py::test_stationary_law_is_gibbs_whatever_the_field[strong G]
        pytest.param(False, marks=pytest.mark.slow),
        True,
    ],
    ids=["G=0", "strong G"],
)
def test_stationary_law_is_gibbs_whatever_the_field(strong_field):
    """Moments of ``exp(−βV − β|p|²/2m)`` within 4.5 MCSE (independent chains' spread).

    ``m = 1.5``, ``β = 2``, ``σ = 1.2`` (``θ/m ≈ 0.96``). The strong field has ``|G|/m = 4``,
    above both the friction and the potential's frequencies; it is given through a log-density
    (``V = −log π/β``, so ``q ~ N(0, K⁻¹/β)`` again). BAOAB's bias at ``ε = 0.05`` is
    ``O(ε²) ≈ 10⁻³`` relative, well below the ~2–5 % MCSE.
    """
    beta, mass = 2.0, 1.5
    if strong_field:
        system = charged_particle(
            logdensity_fn=lambda q: -beta * quadratic_potential(q),
            magnetic_field=[[0.0, 6.0], [-6.0, 0.0]],
            mass=mass,
        )
    else:
        system = charged_particle(quadratic_potential, mass=mass, dimension=2)
    per_chain, exact = stationary_moments(system, beta, 1.2, jax.random.key(17 + strong_field))
    estimate = per_chain.mean(0)
    mcse = per_chain.std(0, ddof=1) / np.sqrt(len(per_chain))
    z_scores = (estimate - exact) / mcse
    assert np.all(np.abs(z_scores) < 4.5), (estimate, exact, z_scores)
    assert np.all(mcse < 0.05 * np.max(np.abs(exact)))  # the test has power


@pytest.mark.slow  # Gibbs law in a uniform field runs by default
def test_stationary_law_is_gibbs_in_a_position_dependent_field():
    """The magnetic bottle (implicit-midpoint ``A`` steps) with ``V = ½ Σ k_i q_i²``, ``β = 1``,
    ``m = 1``: ``E q_i² = 1/k_i`` and ``E p_i² = 1`` within 4.5 MCSE of 128 independent chains
    started from the exact law."""
    stiffness = jnp.array([1.0, 2.0, 0.5])
    system = charged_particle(
        lambda q: 0.5 * jnp.sum(stiffness * q * q),
        vector_potential=bottle_potential,
        charge=3.0,
        dimension=3,
    )
    dynamics = charged_particle_dynamics(system, beta=1.0, sigma=1.0)
    num_chains = 128
    key_q, key_p, key_run = jax.random.split(jax.random.key(23), 3)
    q0 = jax.random.normal(key_q, (num_chains, 3)) / jnp.sqrt(stiffness)
    p0 = jax.random.normal(key_p, (num_chains, 3))
    run = liesample.jit(jax.vmap(lambda k, z: dynamics.path(k, z, 0.05, 3000, 4)))
    path = run(jax.random.split(key_run, num_chains), jnp.concatenate([q0, p0], axis=1))
    assert bool(jnp.all(path.converged)) and not bool(jnp.any(path.nonfinite))
    per_chain = np.asarray(jnp.mean(path.states[:, 1:] ** 2, axis=1))
    exact = np.concatenate([1.0 / np.asarray(stiffness), np.ones(3)])
    mcse = per_chain.std(0, ddof=1) / np.sqrt(num_chains)
    z_scores = (per_chain.mean(0) - exact) / mcse
    assert np.all(np.abs(z_scores) < 4.5), (per_chain.mean(0), z_scores)
    assert np.all(mcse < 0.05 * exact)


# ---------------------------------------------------------------------------------------------
# Scenes are structural
# ---------------------------------------------------------------------------------------------


def step_jaxpr(dynamics, z):
    return str(jax.make_jaxpr(dynamics.make_step(0.1))(jax.random.key(0), z))


def test_no_random_bits_without_noise():
    system = charged_particle(quadratic_potential, magnetic_field=[[0.0, 2.0], [-2.0, 0.0]])
    z = jnp.ones(4)
    quiet = charged_particle_dynamics(system, sigma=0.0, theta=0.5)
    noisy = charged_particle_dynamics(system, beta=1.0, sigma=1.0)
    assert quiet.scene.noise is False and "random_bits" not in step_jaxpr(quiet, z)
    assert "random_bits" in step_jaxpr(noisy, z)
    for integrator in ("baoab", "heun"):
        dynamics = charged_particle_dynamics(system, sigma=0.0, theta=0.5, integrator=integrator)
        assert "random_bits" not in step_jaxpr(dynamics, z)


def test_disabled_effects_are_never_traced():
    calls = {"potential": 0, "vector_potential": 0}

    def potential(q):
        calls["potential"] += 1
        return jnp.sum(q**2)

    def vector_potential(q):
        calls["vector_potential"] += 1
        return bottle_potential(q)

    system = charged_particle(potential, vector_potential=vector_potential, dimension=3)
    z = jnp.ones(6)

    def traced_calls(**kwargs):
        dynamics = charged_particle_dynamics(system, beta=1.0, **kwargs)
        calls.update(potential=0, vector_potential=0)
        step_jaxpr(dynamics, z)
        return dict(calls)

    for integrator in ("baoab", "heun"):
        without_field = traced_calls(magnetic=False, integrator=integrator)
        assert without_field["vector_potential"] == 0 and without_field["potential"] > 0
        assert traced_calls(integrator=integrator)["vector_potential"] > 0
    # BAOAB's O step integrates the derived dissipation in closed form (its rate is read off
    # the generic formula at build time): without the Hamiltonian, h and the field are not traced.
    assert traced_calls(hamiltonian=False) == {"potential": 0, "vector_potential": 0}
    assert charged_particle_dynamics(system, beta=1.0, magnetic=False).scene.effects == (
        "hamiltonian",
        "dissipation",
        "noise",
    )


def test_magnetic_scene_validates():
    with pytest.raises(TypeError, match="magnetic"):
        MagneticScene(magnetic=1)
    with pytest.raises(ValueError, match="no effect"):
        MagneticScene(hamiltonian=False, dissipation=False, noise=False)


# ---------------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"magnetic_field": [[0.0, 1.0], [2.0, 0.0]]}, ValueError, "antisymmetric"),
        ({"magnetic_field": [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]}, ValueError, "square"),
        ({"magnetic_field": [1.0, 2.0]}, ValueError, "3-vector"),
        ({"magnetic_field": [0.0, np.nan, 1.0]}, ValueError, "3-vector"),
        ({"magnetic_field": [[0.0, np.inf], [-np.inf, 0.0]]}, ValueError, "finite"),
        ({"magnetic_field": lambda q: q}, TypeError, "vector_potential"),
        ({"magnetic_field": [0, 0, 1.0], "dimension": 2}, ValueError, "dimension=3"),
        ({"magnetic_field": [[0.0, 1.0], [-1.0, 0.0]], "dimension": 3}, ValueError, "dimension=3"),
        ({"vector_potential": bottle_potential}, ValueError, "dimension is required"),
        ({"vector_potential": lambda q: q[:2], "dimension": 3}, ValueError, "vector_potential"),
        ({"vector_potential": [1.0, 2.0, 3.0], "dimension": 3}, TypeError, "vector_potential"),
        (
            {"magnetic_field": [0, 0, 1.0], "vector_potential": bottle_potential},
            ValueError,
            "at most one",
        ),
        ({}, ValueError, "dimension is required"),
        ({"dimension": 0}, ValueError, "dimension"),
        ({"dimension": 2.0}, TypeError, "dimension"),
        ({"dimension": 3, "mass": 0.0}, ValueError, "mass"),
        ({"dimension": 3, "mass": -1.0}, ValueError, "mass"),
        ({"dimension": 3, "mass": np.nan}, ValueError, "mass"),
        ({"dimension": 3, "charge": np.inf}, ValueError, "charge"),
    ],
)
def test_bad_system_parameters(kwargs, error, match):
    with pytest.raises(error, match=match):
        charged_particle(lambda q: jnp.sum(q**2), **kwargs)


def test_exactly_one_of_potential_and_logdensity():
    with pytest.raises(ValueError, match="exactly one"):
        charged_particle(dimension=2)
    with pytest.raises(ValueError, match="exactly one"):
        charged_particle(lambda q: q @ q, lambda q: -(q @ q), dimension=2)
    with pytest.raises(TypeError, match="logdensity_fn"):
        charged_particle(logdensity_fn=3.0, dimension=2)
    with pytest.raises(ValueError, match="scalar"):
        charged_particle(lambda q: q, dimension=2)
    system = charged_particle(logdensity_fn=lambda q: -(q @ q), dimension=2)
    assert float(system.potential(jnp.array([1.0, 1.0]), beta=4.0)) == pytest.approx(0.5)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"sigma": 1.0}, ValueError, "beta is required"),
        ({"beta": 1.0, "sigma": 1.0, "theta": 0.5}, ValueError, "theta is derived"),
        ({"beta": 1.0, "sigma": 0.0}, ValueError, "beta needs noise"),
        ({"beta": -1.0, "sigma": 1.0}, ValueError, "beta must be > 0"),
        ({"beta": 1.0, "sigma": -1.0}, ValueError, "sigma"),
        ({"beta": 1.0, "integrator": "leapfrog"}, ValueError, "integrator"),
        ({"beta": 1.0, "magnetic": "yes"}, TypeError, "magnetic"),
        ({"beta": 1.0, "step_size": 0.0}, ValueError, "step_size"),
        ({"beta": 1.0, "num_steps": 0}, ValueError, "num_steps"),
        ({"beta": 1.0, "num_steps": 10, "thinning": 3}, ValueError, "multiple of thinning"),
        ({"beta": 1.0, "initial_state": np.ones(3)}, ValueError, r"shape \(4,\)"),
        ({"beta": 1.0, "initial_state": np.array([0.0, np.nan, 0.0, 0.0])}, ValueError, "finite"),
    ],
)
def test_bad_simulation_parameters(kwargs, error, match):
    system = charged_particle(quadratic_potential, magnetic_field=[[0.0, 1.0], [-1.0, 0.0]])
    arguments = {"step_size": 0.1, "num_steps": 10, "initial_state": np.zeros(4)} | kwargs
    initial_state = arguments.pop("initial_state")
    with pytest.raises(error, match=match):
        charged_particle_path(system, jax.random.key(0), initial_state, **arguments)


def test_non_finite_path_is_flagged():
    system = charged_particle(lambda q: -jnp.sum(q**4), dimension=1)  # unbounded below: blows up
    with pytest.warns(RuntimeWarning, match="non-finite"):
        path = charged_particle_path(
            system, jax.random.key(0), np.array([3.0, 0.0]), step_size=0.5, num_steps=50, sigma=0.0
        )
    assert bool(path.nonfinite)
