"""The exact restricted-Gaussian (Bingham) reference against independent quadrature and sampling."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats
from scipy.special import dawsn, roots_legendre

import liesample
from liesample.targets.orbits import (
    RestrictedGaussian,
    _acg_envelope,
    _log_acceptance_ratio,
    bingham_log_normalizer,
    bingham_marginal_density,
    bingham_second_moments,
    isotropic_autocorrelation,
    sample_bingham,
)

# Concentrations λ: anisotropic, ties, negative (β < 0), uniform, and concentrated (|λ| ~ 1e3).
LAMS = [
    (0.3, 1.2, 2.5),
    (1.0, 1.0, 3.0),
    (2.0, -0.5, 2.0),
    (-3.375, -1.6875, -0.84375),
    (0.0, 0.0, 0.0),
    (0.0, 500.0, 1000.0),
    (1000.0, 1000.0, 0.0),
    (1000.0, 0.0, 0.0),
    (-1000.0, 0.0, 500.0),
]


def sphere_rule(lam, n=600):
    """Tensor rule on S² in (u = cos θ, φ): Gauss–Legendre in u, midpoint (periodic) in φ.

    The polar axis is put on the coordinate of largest λ, so the mass never sits at the poles.
    Returns points ``x`` (N, 3) and area weights ``w`` (N,), ``Σ w = 4π``.
    """
    u, wu = roots_legendre(n)
    phi = 2.0 * np.pi * (np.arange(n) + 0.5) / n
    U, P = np.meshgrid(u, phi, indexing="ij")
    S = np.sqrt((1.0 - U) * (1.0 + U))
    x = np.stack([S * np.cos(P), S * np.sin(P), U], axis=-1).reshape(-1, 3)
    x = np.roll(x, int(np.argmax(lam)) - 2, axis=-1)
    w = np.repeat(wu, n) * (2.0 * np.pi / n)
    return x, w


def quadrature_reference(lam):
    """``log Z`` and ``E[x_i²]`` by brute-force 2-D quadrature of ``exp(−Σ λ_i x_i²)``."""
    lam = np.asarray(lam, dtype=float)
    x, w = sphere_rule(lam)
    c = lam.min()
    dens = w * np.exp(-(x * x) @ (lam - c))
    total = dens.sum()
    return np.log(total) - c, (dens @ (x * x)) / total


def line_rule(r=1.0):
    """Composite 20-point Gauss–Legendre rule on [−r, r], panels graded toward both ends
    (boundary layers of width ~1/λ) and of width 0.05 r in the middle (peaks of width ~λ^{−1/2})."""
    inner = np.linspace(-0.9, 0.9, 37)
    graded = 1.0 - 10.0 ** -np.arange(1.0, 11.0)
    edges = r * np.unique(np.concatenate([[-1.0, 1.0], inner, graded, -graded]))
    t, w = np.polynomial.legendre.leggauss(20)
    half = 0.5 * np.diff(edges)[:, None]
    mid = 0.5 * (edges[1:] + edges[:-1])[:, None]
    return (mid + half * t).ravel(), (half * w).ravel()


@pytest.mark.parametrize("lam", LAMS)
def test_log_normalizer_and_moments_match_2d_quadrature(lam):
    log_z_ref, m2_ref = quadrature_reference(lam)
    log_z = float(bingham_log_normalizer(jnp.asarray(lam)))
    assert abs(log_z - log_z_ref) < 1e-10  # relative error of Z
    m2 = np.asarray(bingham_second_moments(jnp.asarray(lam)))
    np.testing.assert_allclose(m2, m2_ref, rtol=1e-9, atol=1e-13)
    assert abs(m2.sum() - 1.0) < 1e-12


def test_closed_forms():
    assert abs(float(bingham_log_normalizer(jnp.zeros(3))) - np.log(4 * np.pi)) < 1e-14
    np.testing.assert_allclose(bingham_second_moments(jnp.zeros(3)), 1 / 3, atol=1e-14)
    np.testing.assert_allclose(bingham_second_moments(jnp.full(3, -7.0)), 1 / 3, atol=1e-14)
    # λ = (L, L, 0): Z = 2π ∫ exp(−L(1−u²)) du = 4π D(√L)/√L (Dawson's integral); shifting by c.
    for L in (0.5, 30.0, 1e3, 1e4):
        exact = np.log(4 * np.pi * dawsn(np.sqrt(L)) / np.sqrt(L)) - 2.5
        assert (
            abs(float(bingham_log_normalizer(jnp.array([L + 2.5, L + 2.5, 2.5]))) - exact) < 1e-10
        )


def test_project_notes_rigid_body_moments():
    target = RestrictedGaussian(inertia=(1.0, 2.0, 4.0), beta=3.0, radius=1.5)
    m2 = np.diag(np.asarray(target.second_moments()))
    np.testing.assert_allclose(m2, [0.417, 0.751, 1.083], atol=2e-3)
    _, m2_ref = quadrature_reference(np.asarray(target.lam))
    np.testing.assert_allclose(m2, 1.5**2 * m2_ref, rtol=1e-9)
    off = np.asarray(target.second_moments()) - np.diag(m2)
    assert np.all(off == 0.0)
    expected_energy = 0.5 * np.sum(m2 / np.array([1.0, 2.0, 4.0]))
    assert abs(float(target.mean_energy()) - expected_energy) < 1e-14


def test_jit_and_vmap_agree():
    lams = jnp.array([LAMS[0], LAMS[2], LAMS[5]])
    direct = np.array([bingham_second_moments(lam) for lam in lams])
    np.testing.assert_allclose(
        liesample.jit(jax.vmap(bingham_second_moments))(lams), direct, rtol=1e-13
    )


@pytest.mark.parametrize("lam", [LAMS[0], LAMS[2], LAMS[3], LAMS[5], LAMS[8]])
@pytest.mark.parametrize("axis", [0, 1, 2])
def test_marginal_density_normalised_with_exact_second_moment(lam, axis):
    t, w = line_rule()
    f = np.asarray(bingham_marginal_density(t, jnp.asarray(lam), axis))
    assert abs(np.sum(w * f) - 1.0) < 1e-10
    m2 = float(bingham_second_moments(jnp.asarray(lam))[axis])
    assert abs(np.sum(w * t * t * f) - m2) < 1e-10 * max(m2, 1e-3)
    assert float(bingham_marginal_density(1.5, jnp.asarray(lam), axis)) == 0.0


@pytest.fixture(scope="module")
def sphere_points():
    """200 000 uniform points on S² and the three axes: the same points for every λ (they were
    drawn with the same key in each case; drawn once, they cost ~0.15 s of CPU less a case)."""
    y = jax.random.normal(jax.random.key(11), (200_000, 3))
    x = y / jnp.linalg.norm(y, axis=-1, keepdims=True)
    return jnp.concatenate([x, jnp.eye(3)])


@pytest.mark.parametrize("lam", LAMS + [(1e4, 0.0, 3.0), (-5e3, 2e3, 0.0), (0.0, 0.2, 0.1)])
def test_acg_envelope_bounds_bingham(lam, sphere_points):
    lam = jnp.asarray(lam)
    A, b, omega, log_M = _acg_envelope(lam)
    assert 0.0 < float(b) <= 3.0
    assert abs(float(jnp.sum(1.0 / (b + 2.0 * A))) - 1.0) < 1e-12
    x = sphere_points
    assert float(jnp.max(_log_acceptance_ratio(x, A, omega, log_M))) <= 1e-12
    # On S² the bound is attained where xᵀAx = (3−b)/2, when that level set is reachable.
    if 0.0 <= (3.0 - float(b)) / 2.0 <= float(jnp.max(A)):
        assert float(jnp.max(_log_acceptance_ratio(x, A, omega, log_M))) > -1e-2


def _marginal_cdf(lam, axis, cells=4000):
    """CDF of ``x_axis`` from the exact marginal density, on a grid, by cellwise Gauss–Legendre."""
    edges = np.linspace(-1.0, 1.0, cells + 1)
    t, w = np.polynomial.legendre.leggauss(10)
    h = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[1:] + edges[:-1])
    nodes = mid[:, None] + h[:, None] * t[None, :]
    f = np.asarray(bingham_marginal_density(nodes, jnp.asarray(lam), axis))
    cdf = np.concatenate([[0.0], np.cumsum(np.sum(f * w, axis=1) * h)])
    assert abs(cdf[-1] - 1.0) < 1e-10
    return lambda s: np.interp(s, edges, cdf)


@pytest.mark.parametrize(
    "lam",
    [(3.375, 1.6875, 0.84375), (-3.375, -1.6875, -0.84375), (0.0, 60.0, 15.0), (0.0, 0.0, 0.0)],
    ids=["rigid-body", "negative-beta", "concentrated", "uniform"],
)
def test_iid_sampler_matches_exact_law(lam):
    n = 200_000
    x, acc = sample_bingham(jax.random.key(2024), jnp.asarray(lam), n)
    x = np.asarray(x)
    assert x.shape == (n, 3)
    assert np.max(np.abs(np.linalg.norm(x, axis=1) - 1.0)) < 1e-12
    assert float(acc) >= 0.5
    m2 = np.asarray(bingham_second_moments(jnp.asarray(lam)))
    sq = x * x
    z = (sq.mean(axis=0) - m2) / (sq.std(axis=0) / np.sqrt(n))
    assert np.all(np.abs(z) < 4.0), z
    for axis in range(3):
        p = stats.kstest(x[:, axis], _marginal_cdf(lam, axis)).pvalue
        assert p > 1e-3, (axis, p)


def test_sampler_deterministic_exact_count_and_concentrated_acceptance():
    lam = jnp.array([0.0, 500.0, 1000.0])
    a, acc = sample_bingham(jax.random.key(5), lam, 1001)
    b, _ = sample_bingham(jax.random.key(5), lam, 1001)
    assert a.shape == (1001, 3)
    np.testing.assert_array_equal(a, b)
    assert 0.5 <= float(acc) <= 1.0
    with pytest.raises(ValueError, match="num_samples"):
        sample_bingham(jax.random.key(5), lam, 0)


def test_isotropic_autocorrelation():
    t = jnp.array([0.0, 0.5, 2.0])
    np.testing.assert_allclose(
        isotropic_autocorrelation(t, 1.5, 0.7), 2.25 * np.exp(-0.49 * np.asarray(t)), rtol=1e-15
    )


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"inertia": (1.0, 0.0, 4.0), "beta": 1.0, "radius": 1.0}, r"inertia\[1\]"),
        ({"inertia": (1.0, 2.0, -4.0), "beta": 1.0, "radius": 1.0}, r"inertia\[2\]"),
        ({"inertia": (1.0, np.inf, 4.0), "beta": 1.0, "radius": 1.0}, r"inertia\[1\]"),
        ({"inertia": (1.0, 2.0), "beta": 1.0, "radius": 1.0}, "inertia"),
        ({"inertia": (1.0, 2.0, 3.0, 4.0), "beta": 1.0, "radius": 1.0}, "inertia"),
        ({"inertia": (1.0, 2.0, 4.0), "beta": np.nan, "radius": 1.0}, "beta"),
        ({"inertia": (1.0, 2.0, 4.0), "beta": np.inf, "radius": 1.0}, "beta"),
        ({"inertia": (1.0, 2.0, 4.0), "beta": -np.inf, "radius": 1.0}, "beta"),
        ({"inertia": (1.0, 2.0, 4.0), "beta": 1.0, "radius": 0.0}, "radius"),
        ({"inertia": (1.0, 2.0, 4.0), "beta": 1.0, "radius": -2.0}, "radius"),
        ({"inertia": (1.0, 2.0, 4.0), "beta": 1.0, "radius": np.nan}, "radius"),
    ],
)
def test_restricted_gaussian_rejects_bad_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RestrictedGaussian(**kwargs)


@pytest.mark.parametrize("beta", [3.0, -2.0, 0.0])
def test_restricted_gaussian_density_normalised_on_sphere(beta):
    r = 1.7
    target = RestrictedGaussian(inertia=(1.0, 2.0, 4.0), beta=beta, radius=r)
    x, w = sphere_rule(np.asarray(target.lam), n=300)
    p = np.exp(np.asarray(target.logdensity(r * x)))
    assert abs(r**2 * np.sum(w * p) - 1.0) < 1e-10  # dA on the radius-r sphere is r² dA(x)
    assert target.logdensity(r * x.reshape(300, 300, 3)).shape == (300, 300)
    # Marginal of μ_0 on [−r, r] integrates to 1.
    m, wm = line_rule(r)
    assert abs(np.sum(wm * np.asarray(target.marginal_density(m, 0))) - 1.0) < 1e-10
    draws = target.sample(jax.random.key(3), 1000)
    assert draws.shape == (1000, 3)
    assert np.max(np.abs(np.linalg.norm(np.asarray(draws), axis=1) - r)) < 1e-12


def test_the_heisenberg_bond_variance_is_continuous_where_its_series_takes_over():
    """Below ``|βJ| = 1e-3`` the bond variance is the series ``1/3 − K²/15`` of ``1/K² −
    1/sinh²K``: the two agree to the series' next term on either side of the switch."""
    from liesample.targets.spins import HeisenbergChainReference

    def variance(k):
        return HeisenbergChainReference(length=4, beta=k, coupling=1.0).bond_variance()

    for k in (0.999e-3, 1.001e-3):
        exact = 1 / k**2 - 1 / np.sinh(k) ** 2  # numpy float64: fine at this K (error ~1e-10)
        assert abs(variance(k) - exact) < 1e-9
    assert abs(variance(0.999e-3) - variance(1.001e-3)) < 1e-9
