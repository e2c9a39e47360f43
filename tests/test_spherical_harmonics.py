"""Real spherical harmonics: values, orthonormality by quadrature, addition theorems, poles."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import eval_legendre, sph_harm_y

from liesample.geometry.spherical_harmonics import (
    degrees_and_orders,
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
