"""Zeitlin physics tools: grid transforms, initial vorticities, spectra, the time unit, the exact
laws that scale with N, and the adjusted sampler against them at N = 16.

Exact references: round trips of band-limited fields (round-off), 1-D adaptive quadrature, the
continuum Rossby–Haurwitz rotation rate, the Harish-Chandra–Itzykson–Zuber determinant, Haar
importance sampling (``liesample.targets.zeitlin.UnitaryOrbitLaw``) at small N and Schur's lemma
for the uniform orbit law. Statistical checks compare with MCSE-based tolerances.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import eval_legendre

import liesample
from liesample.dynamics import Scene
from liesample.dynamics.sde import PoissonLangevinSDE
from liesample.geometry.algebras import Unitary
from liesample.geometry.poisson import LiePoissonStructure
from liesample.geometry.spherical_harmonics import gauss_legendre_grid
from liesample.systems.custom import lie_poisson_system
from liesample.systems.zeitlin import quantised_harmonics, random_vorticity, zeitlin_euler
from liesample.systems.zeitlin_states import (
    energy_spectrum,
    enstrophy_spectrum,
    physical_time_unit,
    rossby_haurwitz,
    rossby_haurwitz_angular_velocity,
    spectral_vorticity,
    vortex_blobs,
    vorticity_from_grid,
    vorticity_on_grid,
)
from liesample.targets.zeitlin import (
    UnitaryOrbitLaw,
    dipole_gibbs_moments,
    uniform_orbit_energy_spectrum,
)


def _coefficient(harmonics, coefficients, degree, order):
    return coefficients[
        ..., np.flatnonzero((harmonics.degrees == degree) & (harmonics.orders == order))[0]
    ]


def _squared_integral(x, size):
    """``∫ω² dΩ`` by Gauss–Legendre quadrature of the gridded field (exact for ``ℓ ≤ N − 1``)."""
    theta, phi, weights = gauss_legendre_grid(2 * (size - 1))
    values = vorticity_on_grid(x, theta, phi.size)
    return float(np.sum(weights[:, None] * values**2) * 2 * np.pi / phi.size)


# ---------------------------------------------------------------------------------------------
# Grid ↔ W
# ---------------------------------------------------------------------------------------------


def test_grid_round_trips_to_round_off():
    size = 6
    x = random_vorticity(size, seed=3)
    # Gauss–Legendre quadrature, the smallest exact grid
    theta, phi, weights = gauss_legendre_grid(size - 1)
    values = vorticity_on_grid(x, theta, phi.size)
    np.testing.assert_allclose(vorticity_from_grid(values, theta, size, weights), x, atol=1e-13)
    # least squares on the cell-centred grid of QuantisedHarmonics.grid
    theta, phi, values = quantised_harmonics(size).grid(x, num_theta=12, num_phi=16)
    np.testing.assert_allclose(vorticity_from_grid(np.asarray(values), theta, size), x, atol=1e-12)
    np.testing.assert_allclose(vorticity_on_grid(x, theta, phi.size), values, atol=1e-12)
    # batches, and the mean (ℓ = 0) is dropped: the state stays in su(N)
    batch = np.stack([values, np.asarray(values) + 3.0])
    recovered = vorticity_from_grid(batch, theta, size)
    np.testing.assert_allclose(recovered, np.stack([x, x]), atol=1e-12)
    assert abs(np.trace(recovered[1])) < 1e-12


def test_random_vorticity_enstrophy_is_half_the_squared_vorticity():
    """``‖W‖² = ∫ω²`` (the transform is an isometry), so ``enstrophy = ½∫ω²`` — what the
    module docstring says and, since the fix, what ``random_vorticity(enstrophy=…)`` gives."""
    for size, enstrophy in ((3, 8.0), (7, 0.5)):
        x = random_vorticity(size, seed=2, enstrophy=enstrophy)
        integral = _squared_integral(x, size)
        assert abs(integral - float(np.sum(x**2))) < 1e-12 * integral
        assert abs(0.5 * integral - enstrophy) < 1e-12 * enstrophy
        assert abs(float(np.sum(enstrophy_spectrum(x))) - enstrophy) < 1e-12 * enstrophy
    # the default start of zeitlin_euler is unchanged: ‖W‖² = 1
    assert abs(float(np.sum(zeitlin_euler(3).default_position ** 2)) - 1.0) < 1e-12


# ---------------------------------------------------------------------------------------------
# Initial vorticities and spectra
# ---------------------------------------------------------------------------------------------


def test_vortex_blob_at_the_pole_has_its_legendre_coefficients():
    """A blob at the north pole is axisymmetric: its coefficients are 1-D integrals
    ``2π ∫ Γ e^{(z−1)/w²} Y_ℓ0(z) dz`` (adaptive quadrature)."""
    size, strength, width = 8, 2.0, 0.5
    x = vortex_blobs(size, [[0.0, 0.0, 3.0]], strength, width)
    harmonics = quantised_harmonics(size)
    coefficients = np.asarray(harmonics.coefficients(jnp.asarray(x)))
    for degree in range(1, size):
        norm = math.sqrt((2 * degree + 1) / (4 * math.pi))
        exact = quad(
            lambda z, d=degree, c=norm: (
                2 * math.pi * strength * math.exp((z - 1) / width**2) * c * eval_legendre(d, z)
            ),
            -1,
            1,
            epsabs=1e-14,
        )[0]
        assert abs(_coefficient(harmonics, coefficients, degree, 0) - exact) < 1e-11
    assert np.max(np.abs(coefficients[harmonics.orders != 0])) < 1e-12
    assert abs(coefficients[0]) < 1e-14 and abs(np.trace(x)) < 1e-12
    # a ± pair at antipodes is odd under the reflection u ↦ −u: only odd degrees
    pair = vortex_blobs(size, [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]], [1.0, -1.0], 0.4)
    even = np.asarray(harmonics.coefficients(jnp.asarray(pair)))[harmonics.degrees % 2 == 0]
    assert np.max(np.abs(even)) < 1e-12 < np.max(np.abs(pair))


@pytest.mark.parametrize("size", [3, 24])
def test_rossby_haurwitz_turns_at_the_continuum_rate_in_physical_time(size):
    """The model's ``Ẇ = [P, W]`` of a Rossby–Haurwitz wave is a rigid rotation about the pole
    at ``Ω(1 − 2/(ℓ(ℓ+1))) · physical_time_unit(N)`` per unit of model time: this fixes the unit
    ``t_phys = √(16π/(N(N²−1))) t_model`` (exactly, at every N)."""
    degree, order, omega = 2, 2, 0.7
    harmonics = quantised_harmonics(size)
    algebra = Unitary(size)
    x = rossby_haurwitz(size, degree, order, amplitude=0.3, angular_velocity=omega)
    x = x + rossby_haurwitz(size, degree, -1, amplitude=0.2, angular_velocity=0.0)

    @liesample.jit
    def coefficients_and_rate(x):
        w, p = algebra.to_matrix(x), algebra.to_matrix(harmonics.inverse_laplacian(x))
        return harmonics.coefficients(x), harmonics.coefficients(algebra.from_matrix(p @ w - w @ p))

    c, rate = (np.asarray(v) for v in coefficients_and_rate(jnp.asarray(x)))
    # d/dα of ω(θ, φ − α): (c_ℓm, c_ℓ,−m) ↦ (−m c_ℓ,−m, m c_ℓm), for m > 0
    turn = np.zeros_like(c)
    for index in np.flatnonzero(harmonics.orders > 0):
        ell, m = harmonics.degrees[index], harmonics.orders[index]
        mirror = np.flatnonzero((harmonics.degrees == ell) & (harmonics.orders == -m))[0]
        turn[index], turn[mirror] = -m * c[mirror], m * c[index]
    expected = rossby_haurwitz_angular_velocity(degree, omega) * physical_time_unit(size)
    np.testing.assert_allclose(rate, expected * turn, atol=1e-13 * np.abs(turn).max())
    assert np.abs(turn).max() > 0.1
    if size == 24:
        assert abs(physical_time_unit(24) - 0.0604) < 1e-4


def test_spectral_vorticity_has_its_spectrum_and_totals():
    size = 10
    harmonics = quantised_harmonics(size)
    target = np.arange(1, size, dtype=float) ** -3.0
    x = spectral_vorticity(size, target, seed=1)
    np.testing.assert_allclose(np.asarray(energy_spectrum(x)), target, rtol=1e-12)
    method_spectrum, energy = liesample.jit(
        lambda x: (harmonics.energy_spectrum(x), harmonics.energy(x))
    )(jnp.asarray(x))
    np.testing.assert_allclose(np.asarray(method_spectrum), target, rtol=1e-12)
    assert abs(float(energy) - target.sum()) < 1e-12
    ell = np.arange(1, size)
    np.testing.assert_allclose(
        np.asarray(enstrophy_spectrum(x)), ell * (ell + 1) * target, rtol=1e-12
    )
    by_energy = spectral_vorticity(size, lambda degrees: degrees**-3.0, seed=1, energy=2.0)
    assert abs(float(np.sum(energy_spectrum(by_energy))) - 2.0) < 1e-12
    by_enstrophy = spectral_vorticity(size, target, seed=1, enstrophy=5.0)
    assert abs(0.5 * float(np.sum(by_enstrophy**2)) - 5.0) < 1e-12
    # batches and jit
    stack = jnp.stack([jnp.asarray(x), jnp.asarray(by_energy)])
    assert liesample.jit(energy_spectrum)(stack).shape == (2, size - 1)
    with pytest.raises(ValueError, match="at most one"):
        spectral_vorticity(size, target, energy=1.0, enstrophy=1.0)
    with pytest.raises(ValueError, match="9 finite values"):
        spectral_vorticity(size, target[:-1])


def test_state_validation():
    with pytest.raises(ValueError, match="degree"):
        rossby_haurwitz(4, degree=4)
    with pytest.raises(ValueError, match="widths"):
        vortex_blobs(4, [[0, 0, 1]], 1.0, 0.0)
    with pytest.raises(ValueError, match="nonzero"):
        vortex_blobs(4, [[0, 0, 0]], 1.0)
    with pytest.raises(ValueError, match="num_phi"):
        vorticity_from_grid(np.zeros((4, 5)), np.linspace(0.1, 3, 4), 4)


def test_spectra_plots_write_pngs(tmp_path):
    import sys

    from liesample.analysis import plots

    x = np.stack([random_vorticity(6, seed=s) for s in range(3)])
    spectra = np.asarray(energy_spectrum(x))
    path = plots.plot_spectra(
        spectra,
        tmp_path / "e.png",
        labels=["a", "b", "c"],
        errors=0.1 * spectra,
        exact=uniform_orbit_energy_spectrum(6, 1.0),
    )
    assert path.exists() and path.stat().st_size > 1000
    path = plots.plot_spectra(
        np.asarray(enstrophy_spectrum(x[0])), tmp_path / "z.png", kind="enstrophy"
    )
    assert path.exists()
    theta, phi, _ = gauss_legendre_grid(5, 12, 24)
    path = plots.plot_vorticity(
        vorticity_on_grid(x[:2], theta, 24), theta, phi, tmp_path / "w.png", labels=["0", "1"]
    )
    assert path.exists()
    assert "matplotlib" in sys.modules  # imported by the plot functions themselves
    with pytest.raises(ValueError, match="kind"):
        plots.plot_spectra(spectra, tmp_path / "bad.png", kind="power")


# ---------------------------------------------------------------------------------------------
# noise_fields of a matrix state
# ---------------------------------------------------------------------------------------------


def test_noise_fields_keep_the_axes_of_matrix_states():
    """``σ X_{ĥ_i}`` is ``fields[..., i]`` with the state's own axes: ``ad*_{ξ_i} W``. Fails
    on the transposed ``fields.T`` (whose first two axes are swapped)."""
    size = 3
    system = zeitlin_euler(size, noise_degree=2)
    algebra = Unitary(size)
    sde = PoissonLangevinSDE(
        LiePoissonStructure(algebra),
        system.hamiltonian,
        system.noise_hamiltonians,
        0.7,
        0.0,
        Scene(),
    )
    z = jnp.asarray(random_vorticity(size, seed=4))
    fields = np.asarray(liesample.jit(sde.noise_fields)(z))
    assert fields.shape == (size, size, system.num_noises)
    streams = system.params["noise_streams"]
    for i in range(system.num_noises):
        expected = 0.7 * np.asarray(algebra.ad_star(jnp.asarray(streams[i]), z))
        np.testing.assert_allclose(fields[..., i], expected, atol=1e-14)
        assert np.max(np.abs(expected - expected.T)) > 1e-3  # the transpose would differ


# ---------------------------------------------------------------------------------------------
# Exact laws at any N
# ---------------------------------------------------------------------------------------------


def _dipole(size):
    """The real coordinates of ``E_10`` (``h = κ ⟨W, E_10⟩ = κ ω_10``)."""
    return quantised_harmonics(size).basis(1, 1)[1]


def _spectrum(x):
    return np.linalg.eigvalsh(1j * np.asarray(Unitary(x.shape[-1]).to_matrix(jnp.asarray(x))))


@pytest.mark.parametrize("size", [3, 4])
def test_dipole_moments_match_the_hciz_determinant(size):
    """The product formula against the HCIZ determinant ``det[e^{t a_i b_j}] / t^{N(N−1)/2}``
    (``a`` the spectrum of ``−κ S₃/‖S₃‖``), differentiated analytically."""
    rng = np.random.default_rng(size)
    b = np.sort(rng.normal(size=size))
    b -= b.mean()
    spin = 0.5 * (size - 1) - np.arange(size)
    kappa = 1.3
    a = -kappa * spin / math.sqrt(np.sum(spin**2))
    pairs = size * (size - 1) / 2
    for beta in (-2.0, 0.4, 3.0):
        t = -beta
        m = np.exp(t * np.outer(a, b))
        m1, m2 = np.outer(a, b) * m, np.outer(a, b) ** 2 * m
        inverse = np.linalg.inv(m)
        first = np.trace(inverse @ m1) - pairs / t
        second = np.trace(inverse @ m2) - np.trace(inverse @ m1 @ inverse @ m1) + pairs / t**2
        mean, variance = dipole_gibbs_moments(b, beta, coupling=kappa)
        assert abs(mean - first) < 1e-10 * max(1.0, abs(first))
        assert abs(variance - second) < 1e-8 * max(1.0, abs(second))


@pytest.mark.parametrize("size, beta", [(2, 1.5), (3, 2.0), (4, -1.5)])
def test_dipole_moments_match_haar_importance_sampling(size, beta):
    x0 = random_vorticity(size, seed=5, enstrophy=1.0 + size)
    dipole = _dipole(size)

    def h(x):
        return np.sum(x * dipole, axis=(-2, -1))

    law = UnitaryOrbitLaw(h, x0, beta)
    estimate, error, _ = law.expectations(
        lambda x: np.stack([h(x), h(x) ** 2], -1), num_samples=100_000, seed=3
    )
    mean, variance = dipole_gibbs_moments(_spectrum(x0), beta)
    exact = np.array([mean, variance + mean**2])
    assert np.all(np.abs(estimate - exact) < 4.5 * error), (estimate, exact, error)
    assert abs(mean) > 20 * error[0]  # not vacuous: the uniform law has E[h] = 0


def test_dipole_moments_limits():
    b = np.array([-1.0, 1.0])  # N = 2: h = √2 λ cos θ, Langevin's paramagnet
    for beta in (-3.0, 1e-9, 0.7):
        x = math.sqrt(2.0) * beta
        langevin = 1 / math.tanh(x) - 1 / x if abs(x) > 1e-6 else x / 3
        mean, variance = dipole_gibbs_moments(b, beta)
        assert abs(mean + math.sqrt(2.0) * langevin) < 1e-12
    mean, variance = dipole_gibbs_moments(np.linspace(-1, 1, 16), 0.0)
    assert mean == 0.0 and variance > 0
    assert np.isfinite(dipole_gibbs_moments(np.linspace(-1, 1, 64), 1e4)).all()
    with pytest.raises(ValueError, match="spectrum"):
        dipole_gibbs_moments([1.0], 1.0)


def test_uniform_orbit_energy_spectrum_matches_haar_monte_carlo():
    size = 4
    x0 = random_vorticity(size, seed=6)
    harmonics = quantised_harmonics(size)
    spectrum = jax.jit(harmonics.energy_spectrum)
    law = UnitaryOrbitLaw(lambda x: np.zeros(len(x)), x0, 0.0)
    samples = np.asarray(spectrum(jnp.asarray(law.orbit_samples(np.random.default_rng(0), 20_000))))
    exact = uniform_orbit_energy_spectrum(size, float(np.sum(x0**2)))
    error = samples.std(0, ddof=1) / math.sqrt(len(samples))
    assert np.all(np.abs(samples.mean(0) - exact) < 4.5 * error)
    start = np.asarray(spectrum(jnp.asarray(x0)))
    assert np.max(np.abs(start - exact) / error) > 20  # the start's own spectrum is far off


# ---------------------------------------------------------------------------------------------
# The adjusted sampler against the exact dipole law
# ---------------------------------------------------------------------------------------------


def _dipole_system(size, enstrophy, noise_degree):
    """Zeitlin's orbit and noise with the Hamiltonian ``h = ω_10`` (linear)."""
    zeitlin = zeitlin_euler(size, noise_degree=noise_degree)
    dipole = jnp.asarray(_dipole(size))
    start = random_vorticity(size, seed=5, enstrophy=enstrophy)
    return lie_poisson_system(
        Unitary(size),
        lambda x: jnp.sum(x * dipole, axis=(-2, -1)),
        zeitlin.noise_hamiltonians,
        start,
        name=f"su({size}) dipole",
        positive_casimirs=(size,),
        casimir_scale=zeitlin.casimir_scale,
    )


def _check_dipole_law(size, beta, enstrophy, step_size, num_chains, num_steps, burn_in):
    system = _dipole_system(size, enstrophy, noise_degree=size - 1)
    algorithm = liesample.adjusted_lie_poisson(system, beta=beta, sigma=1.0, step_size=step_size)
    start = system.default_position
    starts = UnitaryOrbitLaw(lambda x: np.zeros(len(x)), start, 0.0).orbit_samples(
        np.random.default_rng(size), num_chains
    )  # uniform on the orbit, not the Gibbs law

    def chain(position, key):
        def body(state, k):
            state, info = algorithm.step(k, state)
            return state, (info.energy, info.casimir_error)

        _, (h, drift) = jax.lax.scan(
            body, algorithm.init(position), jax.random.split(key, num_steps)
        )
        h = h[burn_in:]
        return jnp.stack([jnp.mean(h), jnp.mean(h**2)]), jnp.max(drift)

    keys = jax.random.split(jax.random.key(size), num_chains)
    means, drift = liesample.jit(jax.vmap(chain))(jnp.asarray(starts), keys)
    means = np.asarray(means)
    assert float(jnp.max(drift)) < 1e-11
    mean, variance = dipole_gibbs_moments(_spectrum(start), beta)
    exact = np.array([mean, variance + mean**2])
    estimate = means.mean(0)
    mcse = means.std(0, ddof=1) / math.sqrt(num_chains)
    z = (estimate - exact) / mcse
    assert np.all(np.abs(z) < 4.5), (estimate, exact, mcse, z)
    # not vacuous: the uniform law (β = 0) and half the β are both far outside the tolerance
    for wrong in (0.0, 0.5 * beta):
        other, _ = dipole_gibbs_moments(_spectrum(start), wrong)
        assert abs(other - exact[0]) > 2 * 4.5 * mcse[0]


# The N = 3 orbit law runs by default (test_zeitlin); the exact laws themselves are tested here.
@pytest.mark.slow
def test_adjusted_sampler_matches_the_exact_dipole_law_n8():
    _check_dipole_law(
        8, beta=-6.0, enstrophy=12.0, step_size=1.0, num_chains=16, num_steps=1000, burn_in=200
    )


@pytest.mark.slow  # ~20 s at N = 16; the N = 8 sibling above runs by default
def test_adjusted_sampler_matches_the_exact_dipole_law_n16():
    _check_dipole_law(
        16, beta=12.0, enstrophy=50.0, step_size=1.0, num_chains=16, num_steps=2000, burn_in=300
    )


@pytest.mark.slow  # ~20 s at N = 16; default siblings: the Haar check of the exact spectrum
# above and the N = 8 dipole test of the sampler
def test_adjusted_sampler_forgets_its_start_to_the_uniform_spectrum_n16():
    """Zeitlin's own system at ``β = 0``: from one fixed start, the mean energy spectrum of every
    degree reaches the exact uniform-orbit value (Schur's lemma)."""
    size, num_chains, num_steps, burn_in = 16, 16, 1000, 200
    system = zeitlin_euler(size, noise_degree=size - 1)
    algorithm = liesample.adjusted_lie_poisson(system, beta=0.0, sigma=1.0, step_size=1.0)
    start = jnp.asarray(system.default_position)

    def chain(key):
        def body(state, k):
            state, _ = algorithm.step(k, state)
            return state, energy_spectrum(state.position)

        _, spectra = jax.lax.scan(body, algorithm.init(start), jax.random.split(key, num_steps))
        return jnp.mean(spectra[burn_in:], axis=0)

    keys = jax.random.split(jax.random.key(16), num_chains)
    means = np.asarray(liesample.jit(jax.vmap(chain))(keys))
    exact = uniform_orbit_energy_spectrum(size, float(jnp.sum(start**2)))
    mcse = means.std(0, ddof=1) / math.sqrt(num_chains)
    z = (means.mean(0) - exact) / mcse
    assert np.all(np.abs(z) < 4.5), z
    # not vacuous: the start's own spectrum is far from the uniform one in most degrees
    far = np.abs(np.asarray(energy_spectrum(start)) - exact) > 2 * 4.5 * mcse
    assert far.sum() >= size // 2
