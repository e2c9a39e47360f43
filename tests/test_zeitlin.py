"""Zeitlin's su(N) model: the algebra u(N), the quantised harmonics, the scenes, and the Gibbs law.

Exact references: algebraic identities (to round-off), the su(2) ≅ so(3) rigid body (pathwise,
with the same Brownian increments), the coherent-state symbols of the basis (positive multiples
of the real spherical harmonics), and the Gibbs law on small orbits by importance sampling over
Haar unitaries (``liesample.targets.zeitlin``). Round-off tolerances: entries are sums of
O(N) products of O(1) numbers, so 1e-12 relative leaves a wide margin and is far below any
sign or index slip.
"""

import functools
import math
from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import liesample
from liesample.dynamics import PoissonLangevin, Scene
from liesample.geometry.algebras import Unitary
from liesample.geometry.spherical_harmonics import real_spherical_harmonics
from liesample.integrators import get_integrator
from liesample.systems import rigid_body
from liesample.systems.zeitlin import (
    isospectral_midpoint,
    quantised_harmonics,
    random_vorticity,
    so3_from_su2,
    su2_from_so3,
    zeitlin_euler,
)

REL = 1e-12


@pytest.fixture
def rng():
    return np.random.default_rng(2718)


# ---------------------------------------------------------------------------------------------
# The algebra u(N)
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("size", [3])
def test_unitary_algebra_identities(rng, size):
    algebra = Unitary(size)
    ops = {
        op: liesample.jit(getattr(algebra, op)) for op in ("bracket", "ad_star", "coadjoint_exp")
    }
    mu, xi, eta = rng.normal(size=(3, size, size))
    scale = np.linalg.norm(mu) * np.linalg.norm(xi) * np.linalg.norm(eta)
    # ⟨ad*_ξ μ, η⟩ = ⟨μ, [ξ, η]⟩, and the real-coordinate sum is −tr(WΞ)
    lhs = float(algebra.pairing(ops["ad_star"](xi, mu), eta))
    rhs = float(algebra.pairing(mu, ops["bracket"](xi, eta)))
    assert abs(lhs - rhs) <= REL * scale
    w, z = algebra.to_matrix(mu), algebra.to_matrix(xi)
    assert abs(float(algebra.pairing(mu, xi)) + float(jnp.real(jnp.trace(w @ z)))) <= REL * scale
    assert float(jnp.max(jnp.abs(jnp.imag(jnp.trace(w @ z))))) <= REL * scale
    # skew-Hermitian, and a bijection
    assert np.allclose(w, -np.conj(w.T), atol=0)
    assert np.allclose(algebra.from_matrix(w), mu, rtol=0, atol=1e-15 * np.abs(mu).max())
    # antisymmetry and Jacobi
    b = ops["bracket"]
    assert np.max(np.abs(b(xi, eta) + b(eta, xi))) <= REL * scale
    jacobi = b(mu, b(xi, eta)) + b(xi, b(eta, mu)) + b(eta, b(mu, xi))
    assert np.max(np.abs(jacobi)) <= REL * scale * 10
    # coadjoint_exp: derivative at 0 is ad*, a one-parameter group, isospectral
    eps = 1e-6
    move = ops["coadjoint_exp"]
    derivative = (move(eps * xi, mu) - move(-eps * xi, mu)) / (2 * eps)
    assert np.max(np.abs(derivative - ops["ad_star"](xi, mu))) <= 1e-8 * scale
    twice = ops["coadjoint_exp"](0.3 * xi, ops["coadjoint_exp"](0.4 * xi, mu))
    assert np.max(np.abs(twice - ops["coadjoint_exp"](0.7 * xi, mu))) <= REL * np.linalg.norm(mu)
    moved = ops["coadjoint_exp"](xi, mu)
    drift = np.max(np.abs(algebra.casimirs(moved) - algebra.casimirs(mu)))
    assert drift <= REL * np.sum(mu**2)
    assert np.max(np.abs(moved - mu)) > 1e-3  # not vacuous


def test_unitary_algebra_broadcasts_over_chains(rng):
    algebra = Unitary(3)
    zeta, mu = rng.normal(size=(2, 5, 3, 3))
    move = liesample.jit(algebra.coadjoint_exp)
    batched = move(zeta, mu)
    single = np.stack([move(z, m) for z, m in zip(zeta, mu)])
    assert np.allclose(batched, single, rtol=0, atol=1e-14)
    assert algebra.casimirs(mu).shape == (5, 4)


def test_unitary_algebra_bad_input():
    with pytest.raises(ValueError, match="int >= 1"):
        Unitary(0)
    with pytest.raises(ValueError, match="shape"):
        Unitary(3).to_matrix(np.zeros((2, 2)))


# ---------------------------------------------------------------------------------------------
# Quantised harmonics
# ---------------------------------------------------------------------------------------------


class Compiled:
    """The quantised harmonics of su(N) with their operators jitted (eager dispatch is slow)."""

    def __init__(self, size):
        self.raw = quantised_harmonics(size)
        for op in (
            "laplacian",
            "inverse_laplacian",
            "coefficients",
            "from_coefficients",
            "energy",
            "energy_spectrum",
        ):
            setattr(self, op, liesample.jit(getattr(self.raw, op)))

    def __getattr__(self, name):
        return getattr(self.raw, name)


def spin_matrices(size):
    basis = quantised_harmonics(size)
    s = 0.5 * (size - 1)
    raising = np.diag(basis.ladder, 1)
    return (
        0.5 * (raising + raising.T),
        (raising - raising.T) / 2j,
        np.diag(s - np.arange(size)),
    )


@pytest.mark.parametrize("size", [2, 9])
def test_laplacian_is_the_su2_casimir_with_spectrum_l_l_plus_1(rng, size):
    basis = Compiled(size)
    algebra = Unitary(size)
    x = rng.normal(size=(size, size))
    w = algebra.to_matrix(x)
    by_commutators = -sum(s @ (s @ w - w @ s) - (s @ w - w @ s) @ s for s in spin_matrices(size))
    assert np.allclose(basis.laplacian(x), algebra.from_matrix(by_commutators), atol=1e-12)
    e = basis.basis(size - 1, 0)
    ell = basis.degrees
    gram = np.einsum("aij,bij->ab", e, e)
    assert np.max(np.abs(gram - np.eye(size * size))) < 1e-12
    assert np.max(np.abs(basis.laplacian(e) + (ell * (ell + 1))[:, None, None] * e)) < 1e-11
    # Δ⁻¹ on su(N): its inverse, trace-free; coefficients round trip; energy formula
    x = x - np.trace(x) / size * np.eye(size)
    p = basis.inverse_laplacian(x)
    assert np.max(np.abs(basis.laplacian(p) - x)) < 1e-12 and abs(np.trace(p)) < 1e-12
    c = basis.coefficients(x)
    assert np.max(np.abs(basis.from_coefficients(c) - x)) < 1e-13
    exact = 0.5 * np.sum(np.where(ell > 0, c**2 / np.maximum(ell * (ell + 1), 1), 0.0))
    assert abs(float(basis.energy(x)) - exact) < 1e-13 * exact
    assert np.allclose(basis.energy_spectrum(x).sum(), exact, rtol=1e-13)


@pytest.mark.parametrize("size", [6])
def test_symbols_of_the_basis_are_positive_multiples_of_the_real_harmonics(rng, size):
    """``⟨n| −iE_ℓm |n⟩ = c_ℓ Y_ℓm(n)`` with ``c_ℓ > 0`` for spin coherent states ``|n⟩``: the
    phases of the quantised harmonics are those of liesample.geometry.spherical_harmonics."""
    basis = quantised_harmonics(size)
    e = np.asarray(Unitary(size).to_matrix(jnp.asarray(basis.basis(size - 1, 0))))
    _, sy, sz = spin_matrices(size)
    symbols, points = [], []
    for _ in range(12):
        theta, phi = math.acos(rng.uniform(-1, 1)), rng.uniform(0, 2 * math.pi)
        state = scipy.linalg.expm(-1j * phi * sz) @ scipy.linalg.expm(-1j * theta * sy)[:, 0]
        symbols.append(np.real(np.einsum("i,kij,j->k", state.conj(), -1j * e, state)))
        points.append(
            [math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)]
        )
    harmonics = np.asarray(real_spherical_harmonics(jnp.asarray(points), size - 1))
    for k in range(size * size):
        ratio = np.array(symbols)[:, k] / harmonics[:, k]
        ok = np.abs(harmonics[:, k]) > 1e-3
        assert np.all(ratio[ok] > 0), (k, ratio)
        assert np.ptp(ratio[ok]) < 1e-10 * np.abs(ratio[ok]).max(), (k, ratio)
    # the factor depends on ℓ only
    ell = basis.degrees
    ratio = np.array(symbols)[0] / harmonics[0]
    for degree in range(size):
        assert np.ptp(ratio[ell == degree]) < 1e-9


def test_grid_is_the_band_limited_vorticity():
    size = 5
    basis = quantised_harmonics(size)
    x = random_vorticity(size, seed=3)
    theta, phi, values = basis.grid(x, num_theta=6, num_phi=8)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    points = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    expected = np.asarray(real_spherical_harmonics(jnp.asarray(points), size - 1)) @ np.asarray(
        basis.coefficients(x)
    )
    assert values.shape == (6, 8)
    assert np.allclose(values, expected, atol=1e-13)


# ---------------------------------------------------------------------------------------------
# The system
# ---------------------------------------------------------------------------------------------


def test_zeitlin_bad_input():
    with pytest.raises(ValueError, match="N must be an int >= 2"):
        zeitlin_euler(1)
    with pytest.raises(ValueError, match="noise_degree must be in 1 … 3"):
        zeitlin_euler(4, noise_degree=4)
    with pytest.raises(TypeError, match="noise_smoothness must be an int"):
        zeitlin_euler(4, noise_smoothness=0.5)
    with pytest.raises(ValueError, match="trace-free"):
        zeitlin_euler(3, position=np.eye(3))
    with pytest.raises(ValueError, match="shape"):
        zeitlin_euler(3, position=np.zeros((2, 2)))
    with pytest.raises(ValueError, match="degenerate orbit"):
        zeitlin_euler(3, position=np.zeros((3, 3)))


def test_noise_hamiltonians_are_the_normalised_streamfunctions():
    system = zeitlin_euler(6, noise_degree=3, noise_smoothness=2)
    basis = system.params["harmonics"]
    x = random_vorticity(6, seed=5)
    c = np.asarray(basis.coefficients(x))[1:16]
    ell = basis.degrees[1:16]
    expected = c / (ell * (ell + 1.0))
    assert np.allclose(system.noise_hamiltonians(jnp.asarray(x)), expected, atol=1e-14)
    assert system.num_noises == 15
    assert float(system.hamiltonian(jnp.asarray(x))) > 0


def test_su2_is_the_isotropic_rigid_body_pathwise():
    """N = 2: ``μ ↦ W = −iΣμ_kσ_k`` carries the rigid body with isotropic inertia 1 and noise
    ``ĥ = Rμ`` (R a rotation: the ℓ = 1 modes, n = 1) onto Zeitlin's su(2) model; the same
    Brownian increments give the same path to round-off."""
    zeitlin = zeitlin_euler(2, noise_degree=1)
    jacobian = jax.jacfwd(lambda mu: zeitlin.noise_hamiltonians(su2_from_so3(mu)))(jnp.zeros(3))
    rotation = np.asarray(jacobian)
    assert np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-14)
    body = rigid_body((1.0, 1.0, 1.0)).with_noise(lambda mu: jnp.asarray(rotation) @ mu)
    mu0 = np.array([0.3, -1.2, 0.5])
    assert abs(float(zeitlin.hamiltonian(su2_from_so3(mu0))) - 0.5 * mu0 @ mu0) < 1e-14
    assert np.allclose(so3_from_su2(su2_from_so3(mu0)), mu0)
    # Hamiltonian drift is a Casimir's: add a non-trivial one to both through the same map.
    extra = lambda mu: 0.7 * mu[0] * mu[1] + 0.2 * mu[2] ** 2
    body = replace(body, hamiltonian=lambda mu, h=body.hamiltonian: h(mu) + extra(mu))
    zeitlin = replace(
        zeitlin, hamiltonian=lambda x, h=zeitlin.hamiltonian: h(x) + extra(so3_from_su2(x))
    )
    integrator = get_integrator("splitting")
    dyn_body = PoissonLangevin(body, sigma=0.8, theta=0.6, scene=Scene())
    dyn_z = PoissonLangevin(zeitlin, sigma=0.8, theta=0.6, scene=Scene())

    def run(mu, x, key):
        def step(carry, k):
            mu, x = carry
            dw = 0.1 * jax.random.normal(k, (3,))
            return (integrator(dyn_body, mu, 0.01, dw), integrator(dyn_z, x, 0.01, dw)), None

        return jax.lax.scan(step, (mu, x), jax.random.split(key, 100))[0]

    mu, x = liesample.jit(run)(jnp.asarray(mu0), su2_from_so3(mu0), jax.random.key(1))
    assert np.max(np.abs(so3_from_su2(x) - mu)) < 1e-12
    assert np.max(np.abs(mu - mu0)) > 0.05  # moved


# ---------------------------------------------------------------------------------------------
# Scenes: pure Euler, relaxation, and the isospectral midpoint
# ---------------------------------------------------------------------------------------------

EULER_N = 4
EULER_START = random_vorticity(EULER_N, seed=7, enstrophy=8.0)
INTEGRATORS = ("splitting", "rkmk_heun", "lie_euler", isospectral_midpoint)


@functools.cache
def _euler_system():
    """Zeitlin's su(4) model of the scene tests (built once: its construction is eager)."""
    return zeitlin_euler(EULER_N, noise_degree=2)


@functools.cache
def _compiled_run(scene, integrators, num_steps):
    """``run(x, key, dt, sigma, theta, snapshot)`` of :func:`_trajectories`, compiled once per
    scene, integrators and number of steps (step size, σ, θ and the snapshot step are traced)."""
    system = _euler_system()
    steps = [get_integrator(i) for i in integrators]

    def run(x, key, dt, sigma, theta, snapshot):
        dynamics = PoissonLangevin(system, sigma=sigma, theta=theta, scene=scene)

        def body(carry, inputs):
            states, saved = carry
            k, n = inputs
            new = []
            for step, state, kk in zip(steps, states, jax.random.split(k, len(steps))):
                dw = dynamics.brownian_increments(jax.random.fold_in(kk, 0), dt, x.dtype)
                new.append(step(dynamics, state, dt, dw))
            saved = tuple(jnp.where(n + 1 == snapshot, a, b) for a, b in zip(new, saved))
            return (tuple(new), saved), jnp.stack([system.hamiltonian(s) for s in new])

        keys = jax.random.split(key, num_steps)
        start = (x,) * len(steps)
        (finals, saved), energies = jax.lax.scan(
            body, (start, start), (keys, jnp.arange(num_steps))
        )
        return finals, saved, energies

    return liesample.jit(run)


def _trajectories(
    scene, integrators, step_size, num_steps, sigma=0.0, theta=0.0, seed=0, snapshot=0
):
    """Final states, states after ``snapshot`` steps and per-step energies of each of
    ``integrators`` (each its own chain, all in one scan of ``num_steps`` steps of
    ``step_size``) from ``EULER_START``. One compilation serves every step size, σ, θ and
    snapshot (they are traced)."""
    run = _compiled_run(scene, tuple(integrators), num_steps)
    return run(jnp.asarray(EULER_START), jax.random.key(seed), step_size, sigma, theta, snapshot)


def test_pure_euler_keeps_casimirs_and_energy_and_integrators_agree():
    system = _euler_system()
    scene = Scene(hamiltonian=True, dissipation=False, noise=False)
    c0 = system.casimirs(jnp.asarray(EULER_START))
    h0 = float(system.hamiltonian(jnp.asarray(EULER_START)))
    # t = 10 at dt = 0.01, and the states at t = 1 (step 100) for the convergence check below
    finals, at_one, energies = _trajectories(scene, INTEGRATORS, 0.01, 1000, snapshot=100)
    # (with noise as well: test_stochastic_runs_keep_the_spectrum_over_1e5_steps, slow)
    for name, final, energy in zip(INTEGRATORS, finals, np.asarray(energies).T):
        name = getattr(name, "name", name)
        assert float(system.casimir_error(final, c0)) < 1e-13, name
        if name != "lie_euler":  # second order: O(dt²) energy error, no secular drift here
            assert np.max(np.abs(energy - h0)) < 1e-4 * h0, (name, np.max(np.abs(energy - h0)))
        assert np.max(np.abs(final - EULER_START)) > 0.1  # the flow moved
    # Short time: the explicit schemes converge to the isospectral-midpoint trajectory at
    # second order (the gap at t = 1 shrinks ~4× when dt halves). The same compiled run at
    # dt = 0.005, its states after 200 steps (t = 1).
    _, at_one_fine, _ = _trajectories(scene, INTEGRATORS, 0.005, 1000, snapshot=200)
    splitting, midpoint = INTEGRATORS.index("splitting"), INTEGRATORS.index(isospectral_midpoint)
    gaps = [
        float(np.max(np.abs(states[splitting] - states[midpoint])))
        for states in (at_one, at_one_fine)
    ]
    assert gaps[1] < 1e-3 and 3.0 < gaps[0] / gaps[1] < 5.0, gaps


def test_isospectral_midpoint_is_modin_viviani():
    """One step against the formulas written out: ``W̃`` solves
    ``W_n = W̃ − h/2 [P̃, W̃] − h²/4 P̃W̃P̃`` and ``W_{n+1} = W̃ + h/2 [P̃, W̃] − h²/4 P̃W̃P̃``,
    ``P̃ = Δ⁻¹W̃``, with Zeitlin's ``Ẇ = [P, W]``; isospectral."""
    system = _euler_system()
    basis = Compiled(EULER_N)
    algebra = system.algebra
    h = 0.05
    w0 = np.asarray(algebra.to_matrix(jnp.asarray(EULER_START)))

    def p_of(w):
        return np.asarray(algebra.to_matrix(basis.inverse_laplacian(algebra.from_matrix(w))))

    w_mid = w0
    for _ in range(200):
        p = p_of(w_mid)
        w_mid = w0 + h / 2 * (p @ w_mid - w_mid @ p) + h * h / 4 * p @ w_mid @ p
    p = p_of(w_mid)
    w1 = w_mid + h / 2 * (p @ w_mid - w_mid @ p) - h * h / 4 * p @ w_mid @ p
    residual = w_mid - h / 2 * (p @ w_mid - w_mid @ p) - h * h / 4 * p @ w_mid @ p - w0
    assert np.max(np.abs(residual)) < 1e-13
    dynamics = PoissonLangevin(system, sigma=0.0, theta=0.0, scene=Scene(True, False, False))
    step = liesample.jit(lambda x: isospectral_midpoint(dynamics, x, h))
    ours = np.asarray(step(jnp.asarray(EULER_START)))
    assert np.max(np.abs(ours - algebra.from_matrix(w1))) < 1e-12
    spectrum = lambda w: np.linalg.eigvalsh(1j * w)
    assert np.max(np.abs(spectrum(w1) - spectrum(w0))) < 1e-12
    # and the step is Zeitlin's flow Ẇ = [P, W] to first order
    p0 = p_of(w0)
    flow = p0 @ w0 - w0 @ p0
    assert np.max(np.abs((w1 - w0) / h - flow)) < 0.1 * np.max(np.abs(flow))


def test_relaxation_decreases_energy_monotonically():
    system = _euler_system()
    scene = Scene(hamiltonian=True, dissipation=True, noise=False)
    c0 = system.casimirs(jnp.asarray(EULER_START))
    h0 = float(system.hamiltonian(jnp.asarray(EULER_START)))
    integrators = ("splitting", isospectral_midpoint)
    finals, _, energies = _trajectories(scene, integrators, 0.01, 400, theta=1.0)
    for name, final, energy in zip(integrators, finals, np.asarray(energies).T):
        name = getattr(name, "name", name)
        assert np.all(np.diff(np.concatenate([[h0], energy])) < 0), name
        assert energy[-1] < 0.9 * h0, (name, energy[-1], h0)
        assert float(system.casimir_error(final, c0)) < 1e-13, name


def _spectrum_drift(num_steps):
    """Largest relative spectral drift of each integrator over a stochastic run (β = 1, σ = 1)."""
    system = _euler_system()
    c0 = system.casimirs(jnp.asarray(EULER_START))
    finals, _, _ = _trajectories(
        Scene(), INTEGRATORS, 0.02, num_steps, sigma=1.0, theta=0.5, seed=3
    )
    return [float(system.casimir_error(final, c0)) for final in finals]


@pytest.mark.slow
def test_stochastic_runs_keep_the_spectrum_over_1e5_steps():
    assert max(_spectrum_drift(100_000)) < 1e-11


# ---------------------------------------------------------------------------------------------
# The Gibbs law on small orbits
# ---------------------------------------------------------------------------------------------


def _observables(x):
    """``(h, x₀₀², x₀₁², x₀₀x₁₁)`` on a stack of states (shape ``(K, 4)``)."""
    return np.stack([x[:, 0, 0] ** 2, x[:, 0, 1] ** 2, x[:, 0, 0] * x[:, 1, 1]], -1)


def _chain_means(system, algorithm, num_chains, num_steps, burn_in, seed):
    """Per-chain ergodic averages of ``(h, observables)``, shape ``(num_chains, 4)``; chains
    start i.i.d. uniform on the orbit."""
    starts = system.reference(1.0, system.default_position).orbit_samples(
        np.random.default_rng(seed), num_chains
    )

    def chain(start, key):
        def body(state, k):
            state, info = algorithm.step(k, state)
            x = state.position
            observed = [info.energy, x[0, 0] ** 2, x[0, 1] ** 2, x[0, 0] * x[1, 1]]
            return state, (jnp.stack(observed), info.casimir_error)

        _, (trace, drift) = jax.lax.scan(
            body, algorithm.init(start), jax.random.split(key, num_steps)
        )
        return jnp.mean(trace[burn_in:], axis=0), jnp.max(drift)

    keys = jax.random.split(jax.random.key(seed), num_chains)
    means, drift = liesample.jit(jax.vmap(chain))(jnp.asarray(starts), keys)
    assert float(jnp.max(drift)) < 1e-12  # the spectrum is kept along every chain
    return np.asarray(means)


def _check_against_orbit_law(system, beta, means, num_samples=100_000):
    law = system.reference(beta, system.default_position)
    exact, exact_error, ess = law.expectations(
        lambda x: np.concatenate(
            [np.asarray(system.hamiltonian(jnp.asarray(x)))[:, None], _observables(x)], -1
        ),
        num_samples=num_samples,
        seed=11,
    )
    assert ess > 0.05 * num_samples
    estimate = means.mean(0)
    mcse = means.std(0, ddof=1) / math.sqrt(len(means))
    z = (estimate - exact) / np.sqrt(mcse**2 + exact_error**2)
    assert np.all(np.abs(z) < 4.5), (estimate, exact, mcse, exact_error, z)
    # Not vacuous: a chain of the uniform orbit law (β = 0) would fail the test on E[h] (its
    # distance from the Gibbs value is over twice the 4.5-standard-error tolerance).
    uniform, uniform_error, _ = law.__class__(law.hamiltonian, law.position, 0.0).expectations(
        lambda x: np.asarray(system.hamiltonian(jnp.asarray(x)))[:, None], num_samples=20_000
    )
    tolerance = 4.5 * math.sqrt(mcse[0] ** 2 + exact_error[0] ** 2 + uniform_error[0] ** 2)
    assert abs(uniform[0] - exact[0]) > 2 * tolerance


GIBBS_START = random_vorticity(3, seed=2, enstrophy=8.0)


@pytest.mark.slow  # the adjusted sampler's N = 3 check runs by default
def test_sampler_matches_the_exact_orbit_law_n3():
    system = zeitlin_euler(3, noise_degree=2, position=GIBBS_START)
    beta = 1.0
    algorithm = liesample.lie_poisson_langevin(system, beta=beta, sigma=1.0, step_size=0.05)
    means = _chain_means(system, algorithm, num_chains=16, num_steps=1000, burn_in=100, seed=1)
    _check_against_orbit_law(system, beta, means)


def test_adjusted_sampler_matches_the_exact_orbit_law_n3_at_a_large_step():
    system = zeitlin_euler(3, noise_degree=2, position=GIBBS_START)
    beta = 1.0
    algorithm = liesample.adjusted_lie_poisson(system, beta=beta, sigma=1.0, step_size=0.3)
    means = _chain_means(system, algorithm, num_chains=16, num_steps=1500, burn_in=100, seed=2)
    _check_against_orbit_law(system, beta, means)


@pytest.mark.slow
@pytest.mark.parametrize("sampler", ["unadjusted", "adjusted"])
def test_samplers_match_the_exact_orbit_law_n4(sampler):
    start = random_vorticity(4, seed=4, enstrophy=12.5)
    system = zeitlin_euler(4, noise_degree=3, position=start)
    beta = 0.7
    if sampler == "unadjusted":
        algorithm = liesample.lie_poisson_langevin(system, beta=beta, sigma=1.0, step_size=0.02)
        means = _chain_means(system, algorithm, 16, 4000, 200, seed=5)
    else:
        algorithm = liesample.adjusted_lie_poisson(system, beta=beta, sigma=1.0, step_size=0.3)
        means = _chain_means(system, algorithm, 16, 3000, 200, seed=6)
    _check_against_orbit_law(system, beta, means, num_samples=400_000)


# ---------------------------------------------------------------------------------------------
# The adjusted step's cost: structured exponential, no per-step eigenproblem, refused noise
# ---------------------------------------------------------------------------------------------


def test_noise_of_rigid_rotations_alone_is_refused():
    """ℓ = 1 noise only rotates the sphere rigidly, which keeps h: refused for N ≥ 3 (N = 2:
    the rotations are all of su(2) and h is a Casimir, so it stays allowed)."""
    for size in (3, 8):
        with pytest.raises(ValueError, match=r"noise_degree=1 cannot mix.*noise_degree >= 2"):
            zeitlin_euler(size, noise_degree=1)
    assert zeitlin_euler(2, noise_degree=1).num_noises == 3


@functools.cache
def _su6_exponential():
    """Zeitlin's u(6) algebra, its ``group_element`` and the forward-mode derivative of it at
    ``Z = 0``, compiled once for every scale below."""
    algebra = zeitlin_euler(6).algebra

    def tangent_at_zero(direction):
        return jax.jvp(algebra.group_element, (jnp.zeros_like(direction),), (direction,))[1]

    return algebra, liesample.jit(algebra.group_element), liesample.jit(tangent_at_zero)


@pytest.mark.parametrize("scale", [0.0, 1e-3, 0.7, 5.0, 300.0])
def test_skew_hermitian_exponential_is_expm_and_unitary(rng, scale):
    """``group_element`` (products only) equals SciPy's ``expm`` to round-off times ‖Z‖, is
    unitary to round-off at any ‖Z‖, and is differentiable in forward mode at Z = 0."""
    size = 6
    algebra, group_element, tangent_at_zero = _su6_exponential()
    zetas = jnp.asarray(rng.standard_normal((3, size, size)) * scale)
    u = np.asarray(group_element(zetas))
    for z, one in zip(np.asarray(algebra.to_matrix(zetas)), u):
        assert np.max(np.abs(one - scipy.linalg.expm(-z))) < 1e-14 * max(1.0, scale * size)
        assert np.max(np.abs(one @ one.conj().T - np.eye(size))) < 1e-14
    direction = jnp.asarray(rng.standard_normal((size, size)))
    tangent = tangent_at_zero(direction)
    np.testing.assert_allclose(tangent, -algebra.to_matrix(direction), atol=1e-15)


@functools.cache
def _su5_system():
    """su(5) with ℓ ≤ 2 noise, shared by the step-cost tests (its construction, noise-span and
    stiffness checks are computed once and cached on the system)."""
    return zeitlin_euler(5, noise_degree=2)


def _primitives_and_step(algorithm, state):
    """The compiled step's primitives (as text) and its result from one trace of the step."""
    traced = liesample.jit(algorithm.step).trace(jax.random.key(1), state)
    new_state, info = traced.lower().compile()(jax.random.key(1), state)
    return str(traced.jaxpr), new_state, info


def test_adjusted_zeitlin_step_solves_no_eigenproblem():
    """The compiled adjusted step on Zeitlin's model calls no eigensolver, LU or triangular
    solve (the per-step Casimir drift is ‖W‖²'s), and that drift is what the Info reports."""
    system = _su5_system()
    algorithm = liesample.adjusted_lie_poisson(system, beta=1.0, step_size=0.5)
    state = algorithm.init(jnp.asarray(system.default_position))
    primitives, new_state, info = _primitives_and_step(algorithm, state)
    for name in ("eigh", "lu", "triangular_solve", "svd"):
        assert f"{name}[" not in primitives, name
    norm_sq = float(jnp.sum(new_state.position**2))
    reference = float(state.reference_casimirs[-1])
    drift = abs(norm_sq - reference) / max(reference, norm_sq)
    assert float(info.casimir_error) == pytest.approx(drift, abs=1e-15)  # sums' round-off
    assert float(system.casimir_error(new_state.position, state.reference_casimirs)) < 1e-13


def test_unadjusted_zeitlin_step_on_the_orbit_solves_no_eigenproblem():
    """``lie_poisson_langevin`` with an orbit integrator reports the cheap ‖W‖² drift and calls
    no eigensolver; an integrator that leaves the orbit still reports the whole spectrum's."""
    system = _su5_system()
    state = None
    for integrator, eigensolver in (("rkmk_heun", False), ("euler_heun", True)):
        # stability="off": the step is the same; the start's step-size check (a compiled
        # curvature scan of its own) is not what this test is about
        algorithm = liesample.lie_poisson_langevin(
            system, beta=1.0, step_size=0.01, integrator=integrator, stability="off"
        )
        state = algorithm.init(jnp.asarray(system.default_position))
        primitives, new_state, info = _primitives_and_step(algorithm, state)
        assert ("eigh[" in primitives) == eigensolver, integrator
        expected = (system.casimir_error if eigensolver else system.step_casimir_error)(
            new_state.position, state.reference_casimirs
        )
        assert float(info.casimir_error) == pytest.approx(float(expected), abs=1e-15)


def test_noise_by_the_harmonic_transform_equals_the_dense_streams():
    """With many noise directions ĥ goes through the O(N³) transform; same values as the dense
    streams ψ_i (to round-off)."""
    system = zeitlin_euler(8, noise_degree=7, noise_smoothness=2)
    x = jnp.asarray(random_vorticity(8, seed=3))
    dense = jnp.einsum("knm,nm->k", jnp.asarray(system.params["noise_streams"]), x)
    np.testing.assert_allclose(system.noise_hamiltonians(x), dense, atol=1e-15)


def test_repeated_moves_along_one_noise_field_keep_the_spectrum():
    """The splitting moves along the same noise field every step, so a unitarity error of the
    exponential that is systematic for that direction would make the Casimirs drift linearly
    in the number of moves; the structured exponential's is random round-off, so the drift
    grows like √moves (a systematic error of a tenth of the unit round-off per move fails).
    """
    system = _euler_system()
    start = jnp.asarray(EULER_START)
    c0 = system.casimirs(start)
    directions = jax.jacrev(system.noise_hamiltonians)(start)  # (m, N, N), constant (linear)
    sizes = 0.1 * jax.random.normal(jax.random.key(5), (20_000, 2))

    def move(w, size):
        for i, c in zip((0, 5), size):
            w = system.algebra.coadjoint_exp(c * directions[i], w)
        return w, None

    final, _ = liesample.jit(lambda w: jax.lax.scan(move, w, sizes))(start)
    moves = sizes.size
    random_walk = 10 * np.finfo(float).eps / 2 * math.sqrt(moves)  # 10 unit round-offs × √n
    assert float(system.casimir_error(final, c0)) < random_walk
