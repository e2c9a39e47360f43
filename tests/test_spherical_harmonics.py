"""Real spherical harmonics: values, orthonormality by quadrature, addition theorems, poles,
and the grid transforms (round trips to round-off for band-limited fields)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import eval_legendre, sph_harm_y

from liesample.geometry.spherical_harmonics import (
    degrees_and_orders,
    gauss_legendre_grid,
    harmonic_analysis,
    harmonic_synthesis,
    num_harmonics,
    real_spherical_harmonics,
    transport_modes,
)

MAX_DEGREE = 8


def scipy_real_harmonics(theta, phi, max_degree, min_degree=0):
    """Real harmonics from scipy's complex ``sph_harm_y`` (Condon–Shortley phase removed)."""
    columns = []
    for ell, m in zip(*degrees_and_orders(max_degree, min_degree), strict=True):
        y = sph_harm_y(ell, abs(m), theta, phi)
        if m == 0:
            columns.append(y.real)
        else:
            sign = (-1.0) ** abs(m)
            columns.append(math.sqrt(2.0) * sign * (y.real if m > 0 else y.imag))
    return np.stack(columns, axis=-1)


def quadrature_grid(num_z=24, num_phi=48):
    """Gauss–Legendre in ``z`` × uniform in ``φ``: exact for polynomials of degree < 2·24 on S²."""
    z, wz = np.polynomial.legendre.leggauss(num_z)
    phi = 2.0 * np.pi * np.arange(num_phi) / num_phi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1.0 - zz**2)
    points = np.stack([s * np.cos(pp), s * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    weights = (wz[:, None] * np.full(num_phi, 2.0 * np.pi / num_phi)[None, :]).reshape(-1)
    return points, weights, np.arccos(zz).reshape(-1), pp.reshape(-1)


def test_values_match_scipy_including_poles():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(50, 3)) * rng.uniform(0.5, 3.0, size=(50, 1))  # any radius
    x = np.concatenate([x, [[0.0, 0.0, 2.0], [0.0, 0.0, -1.0]]])  # the poles
    u = x / np.linalg.norm(x, axis=-1, keepdims=True)
    theta, phi = np.arccos(np.clip(u[:, 2], -1, 1)), np.arctan2(u[:, 1], u[:, 0])
    ours = np.asarray(real_spherical_harmonics(x, MAX_DEGREE))
    assert ours.shape == (52, num_harmonics(MAX_DEGREE))
    np.testing.assert_allclose(ours, scipy_real_harmonics(theta, phi, MAX_DEGREE), atol=1e-13)


def test_orthonormal_by_quadrature_against_scipy():
    points, weights, theta, phi = quadrature_grid()
    ours = np.asarray(real_spherical_harmonics(points, MAX_DEGREE))
    gram = ours.T @ (weights[:, None] * ours)
    np.testing.assert_allclose(gram, np.eye(gram.shape[0]), atol=1e-12)
    cross = ours.T @ (weights[:, None] * scipy_real_harmonics(theta, phi, MAX_DEGREE))
    np.testing.assert_allclose(cross, np.eye(gram.shape[0]), atol=1e-12)


def test_addition_theorem_and_gradient_sum():
    """``Σ_m Y_ℓm(a)Y_ℓm(b) = (2ℓ+1)/(4π) P_ℓ(a·b)`` and ``Σ_m ∇Y ∇Yᵀ = ℓ(ℓ+1)(2ℓ+1)/(8π) P_a``:
    what makes complete ℓ-shells of noise isotropic."""
    rng = np.random.default_rng(1)
    a, b = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 3)))
    ell, _ = degrees_and_orders(MAX_DEGREE)
    products = np.asarray(real_spherical_harmonics(a, MAX_DEGREE)) * np.asarray(
        real_spherical_harmonics(b, MAX_DEGREE)
    )
    for degree in range(MAX_DEGREE + 1):
        expected = (2 * degree + 1) / (4 * np.pi) * eval_legendre(degree, a @ b)
        assert abs(products[ell == degree].sum() - expected) < 1e-13
    jacobian = np.asarray(jax.jacfwd(lambda x: real_spherical_harmonics(x, MAX_DEGREE))(a))
    tangent_projector = np.eye(3) - np.outer(a, a)
    for degree in range(1, MAX_DEGREE + 1):
        rows = jacobian[ell == degree]
        expected = degree * (degree + 1) * (2 * degree + 1) / (8 * np.pi) * tangent_projector
        np.testing.assert_allclose(rows.T @ rows, expected, atol=1e-11)
    np.testing.assert_allclose(jacobian @ a, 0.0, atol=1e-12)  # 0-homogeneous: tangent gradient


def test_gradients_finite_at_the_poles():
    for pole in ([0.0, 0.0, 1.0], [0.0, 0.0, -1.0]):
        jacobian = jax.jacfwd(lambda x: transport_modes(x, 6))(jnp.asarray(pole))
        assert np.all(np.isfinite(np.asarray(jacobian)))


def test_transport_modes_scaling_and_validation():
    x = jnp.asarray([[0.3, -0.4, 0.866], [1.0, 0.0, 0.0]])
    ell, _ = degrees_and_orders(3, 1)
    np.testing.assert_allclose(
        np.asarray(transport_modes(x, 3)) * np.sqrt(ell * (ell + 1.0)),
        np.asarray(real_spherical_harmonics(x, 3, 1)),
        atol=1e-15,
    )
    with pytest.raises(ValueError, match="max_degree must be >= 1"):
        transport_modes(x, 0)
    with pytest.raises(TypeError, match="max_degree must be an int"):
        transport_modes(x, 2.0)
    with pytest.raises(ValueError, match="max_degree must be >= min_degree"):
        real_spherical_harmonics(x, 1, 2)
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
        real_spherical_harmonics(jnp.ones((2, 2)), 2)


def _grid_points(theta, phi):
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], axis=-1)


def test_synthesis_is_the_sum_of_the_harmonics():
    rng = np.random.default_rng(3)
    coefficients = rng.normal(size=(2, num_harmonics(MAX_DEGREE)))
    theta = rng.uniform(0.0, np.pi, size=7)
    values = harmonic_synthesis(coefficients, theta, 19)
    harmonics = np.asarray(
        real_spherical_harmonics(_grid_points(theta, 2 * np.pi * np.arange(19) / 19), MAX_DEGREE)
    )
    np.testing.assert_allclose(
        values, np.einsum("tpk,bk->btp", harmonics, coefficients), atol=1e-13
    )


@pytest.mark.parametrize("grid", ["gauss_legendre", "equiangular"])
def test_analysis_inverts_synthesis_for_band_limited_fields(grid):
    """Round trip to round-off: by quadrature on the smallest exact Gauss–Legendre grid, and by
    least squares on an equiangular (cell-centred) grid."""
    rng = np.random.default_rng(4)
    coefficients = rng.normal(size=(3, num_harmonics(MAX_DEGREE)))
    if grid == "gauss_legendre":
        theta, phi, weights = gauss_legendre_grid(MAX_DEGREE)
        assert (theta.size, phi.size) == (MAX_DEGREE + 1, 2 * MAX_DEGREE + 1)
        assert abs(weights.sum() - 2.0) < 1e-14
        values = harmonic_synthesis(coefficients, theta, phi.size)
        recovered = harmonic_analysis(values, theta, MAX_DEGREE, weights)
        np.testing.assert_allclose(recovered, coefficients, atol=1e-13)
        # without the weights, least squares on the same grid gives the same answer
        np.testing.assert_allclose(
            harmonic_analysis(values, theta, MAX_DEGREE), coefficients, atol=1e-13
        )
    else:
        theta = (np.arange(24) + 0.5) * np.pi / 24
        values = harmonic_synthesis(coefficients, theta, 48)
        np.testing.assert_allclose(
            harmonic_analysis(values, theta, MAX_DEGREE), coefficients, atol=1e-12
        )
    # back again: the grid values are recovered too
    np.testing.assert_allclose(
        harmonic_synthesis(coefficients, theta, values.shape[-1]), values, atol=1e-13
    )


def test_quadrature_analysis_is_the_l2_projection():
    """On a finer Gauss–Legendre grid, quadrature of a field that is not band-limited gives its
    ``L²`` coefficients: checked against 1-D adaptive quadrature of an axisymmetric field."""
    from scipy.integrate import quad

    theta, phi, weights = gauss_legendre_grid(MAX_DEGREE, 40, 41)
    field = np.exp(2.0 * np.cos(theta))[:, None] * np.ones(phi.size)
    coefficients = harmonic_analysis(field, theta, MAX_DEGREE, weights)
    ell, m = degrees_and_orders(MAX_DEGREE)
    for degree in range(MAX_DEGREE + 1):
        norm = math.sqrt((2 * degree + 1) / (4 * math.pi))
        exact = quad(
            lambda z, d=degree, c=norm: 2 * math.pi * c * math.exp(2 * z) * eval_legendre(d, z),
            -1,
            1,
            epsabs=1e-14,
        )[0]
        assert abs(coefficients[(ell == degree) & (m == 0)][0] - exact) < 1e-12
    assert np.max(np.abs(coefficients[m != 0])) < 1e-13


def test_grid_transform_validation():
    theta, _, weights = gauss_legendre_grid(3)
    with pytest.raises(ValueError, match="num_phi >= 7"):
        harmonic_analysis(np.zeros((theta.size, 5)), theta, 3)
    with pytest.raises(ValueError, match="num_theta = 4"):
        harmonic_analysis(np.zeros((3, 7)), theta, 3)
    with pytest.raises(ValueError, match="distinct colatitudes"):
        harmonic_analysis(np.zeros((2, 7)), theta[:2], 3)
    with pytest.raises(ValueError, match="weights must have shape"):
        harmonic_analysis(np.zeros((4, 7)), theta, 3, weights[:2])
    with pytest.raises(ValueError, match="exact grid"):
        gauss_legendre_grid(3, num_theta=3)
    with pytest.raises(ValueError, match=r"\(L \+ 1\)²"):
        harmonic_synthesis(np.zeros(5), theta, 7)
